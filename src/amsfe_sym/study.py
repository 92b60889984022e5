"""Monte Carlo study: seeds x estimators (x scenario variants), in parallel.

``amsfe study paper-sim --seeds 20`` runs every estimator on seeds ``0 .. 19`` of one
scenario and writes to a folder:

- ``study.md``: one table per variant, mean +- std over seeds of the estimation RMSE of q, qd
  (per joint) and theta, tracking RMSE, the median cost per tick, the time-averaged NEES and
  the fraction of time steps where the across-seed average NEES lies inside its two-sided
  95 % chi-square band (see :func:`nees_band`), plus the exact command that produced it;
- ``study.json``: the same aggregates and every run's ``summary.json`` (``simulate.summarize``)
  with the study's extra per-run metrics (theta settling time);
- figures (per variant): ``errors.png`` (paper Fig. 4 analog: q and qd estimation errors per
  joint vs time, one seed, every estimator), ``theta.png`` (Fig. 5 analog: theta estimate vs
  time), ``nees.png`` (average NEES vs time with the 95 % band, every estimator).

Metrics use the window of :func:`amsfe_sym.simulate.summarize`: the last 80 % of the run.

The model library of each variant is generated once in the parent process before the pool
starts; the workers only load it by path (a :class:`ModelLibrary` holds ctypes handles and
is not sent between processes).  Workers are started with ``spawn`` (no fork of a process
holding loaded libraries and BLAS threads), with one BLAS thread each (``OMP_NUM_THREADS``,
``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1 unless already set).  ``workers = 1`` runs
everything in-process, with the parent's BLAS threading.

``--set section.field=value`` overrides scenario fields (``integrator=paper``,
``filter.link_torque_std=2``, ``encoders.q_std=0.01``, ...), validated with the scenario's
own checks: an unknown key or a bad value raises :class:`~amsfe_sym.errors.ConfigError`.
"""

from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
import os
import shlex
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import AmsfeError, ConfigError, describe
from amsfe_sym.estimation import ESTIMATORS
from amsfe_sym.plots import plot_study
from amsfe_sym.provenance import provenance
from amsfe_sym.scenario import Scenario, apply_sets, load_scenario
from amsfe_sym.sim.record import nees_band, window

__all__ = [
    "StudyResult",
    "aggregate",
    "apply_sets",
    "format_block_table",
    "format_table",
    "nees_band",
    "parse_estimators",
    "run_study",
]

log = logging.getLogger(__name__)
FloatArray = NDArray[np.float64]

#: A theta estimate has "settled" once it stays within this fraction of the true value.
THETA_SETTLE_REL = 0.10


def parse_estimators(text: str | Sequence[str] | None) -> tuple[str, ...]:
    """``"all"``/``None`` -> every registered estimator; else validated names, in order."""
    if text is None or text == "all":
        return tuple(ESTIMATORS)
    names = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    names = [s for s in names if s]
    bad = [s for s in names if s not in ESTIMATORS]
    if bad or not names:
        raise ConfigError(
            describe(
                "--estimators",
                "all or a comma-separated list of " + ", ".join(ESTIMATORS),
                repr(bad) if bad else "an empty list",
                "fix the names",
            )
        )
    return tuple(dict.fromkeys(names))


# --------------------------------------------------------------------------- statistics
def settle_time(
    t: FloatArray, est: FloatArray, true: float, rel: float = THETA_SETTLE_REL
) -> float:
    """First time after which ``|est - true| <= rel |true|`` for the rest of the run (NaN if
    the last sample is outside).  ``true == 0`` uses an absolute tolerance ``rel``."""
    tol = rel * abs(true) if true != 0 else rel
    outside = np.abs(est - true) > tol
    if outside[-1]:
        return math.nan
    idx = np.flatnonzero(outside)
    return float(t[0]) if idx.size == 0 else float(t[idx[-1] + 1])


# --------------------------------------------------------------------------- workers
@dataclass(frozen=True)
class _Task:
    variant: str
    scenario: Scenario
    lib_dir: str
    keep_series: bool


_LIBS: dict[str, Any] = {}


#: BLAS thread pools of the workers: one thread each (set in the environment the workers
#: inherit, unless the caller set them).  Two processes with multithreaded BLAS on two cores
#: oversubscribe the machine; worse, scipy 1.17's ``scipy.linalg.solve`` on a 5x5 system took
#: ~0.9-1.9 ms with OpenBLAS threads against ~20 us with one thread on this machine.
_BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _worker_init() -> None:
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)


def _run_task(task: _Task) -> dict[str, Any]:
    """One run (in a worker): the summary, the NEES and theta series, and optionally the
    error series of the figure seed."""
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    lib = _LIBS.get(task.lib_dir)
    if lib is None:
        lib = _LIBS[task.lib_dir] = ModelLibrary(task.lib_dir)
    try:
        res = run(task.scenario, lib=lib)
    except AmsfeError as exc:  # one diverging run must not sink the study: record it
        sc = task.scenario
        failed = {
            "variant": task.variant,
            "scenario": sc.name,
            "estimator": sc.estimator,
            "seed": sc.seed,
            "error": f"{type(exc).__name__}: {exc}",
        }
        return {"summary": failed, "failed": True}
    summary = summarize(res)
    L = lib.layout
    th_hat = res.x_hat[:, L["theta"]]
    th_true = res.x_true[0, L["theta"]]
    summary["variant"] = task.variant
    w = window(res.t.size)
    z = (res.x_true - res.x_hat)[w] ** 2 / np.maximum(res.P_diag[w], 1e-300)
    summary["nes_block"] = {
        b: float(np.mean(z[:, sl])) for b, sl in L.items() if sl.stop > sl.start
    }
    summary["theta_settle_s"] = [
        settle_time(res.t, th_hat[:, i], float(th_true[i])) for i in range(lib.p)
    ]
    out: dict[str, Any] = {
        "summary": summary,
        "nees": res.nees.astype(np.float64),
        "theta_hat": th_hat.astype(np.float64),
    }
    if task.keep_series:
        cols = np.r_[np.arange(L["q"].start, L["q"].stop), np.arange(L["qd"].start, L["qd"].stop)]
        out["t"] = res.t
        out["err"] = (res.x_true - res.x_hat)[:, cols]
        out["sd"] = np.sqrt(np.maximum(res.P_diag[:, cols], 0.0))
    return out


# --------------------------------------------------------------------------- the study
@dataclass
class StudyResult:
    """What :func:`run_study` produced.

    Attributes:
        out: Output folder.
        table: The markdown report (``study.md``).
        aggregate: ``{variant: {estimator: metrics}}`` as written to ``study.json``.
        runs: Every run's summary.
        figures: Paths of the PNGs written.
    """

    out: Path
    table: str
    aggregate: dict[str, dict[str, Any]]
    runs: list[dict[str, Any]]
    figures: list[Path] = field(default_factory=list)


def _mean_std(values: Sequence[Sequence[float]] | FloatArray) -> dict[str, list[float]]:
    a = np.asarray(values, dtype=float)
    return {
        "mean": np.mean(a, axis=0).tolist(),
        "std": (np.std(a, axis=0, ddof=1) if a.shape[0] > 1 else np.zeros(a.shape[1])).tolist(),
    }


def aggregate(
    summaries: Sequence[Mapping[str, Any]],
    nees: FloatArray,
    theta_hat: FloatArray,
    t: FloatArray,
    theta_true: Sequence[float],
) -> dict[str, Any]:
    """Metrics of one (variant, estimator) over its seeds.

    Args:
        summaries: The runs' summaries (``simulate.summarize`` + ``theta_settle_s``).
        nees: NEES series, (M, K).
        theta_hat: theta estimates, (M, K, p).
        t: Times, (K,).
        theta_true: True theta, (p,).
    """
    M, K = nees.shape
    dof = int(summaries[0]["nees_dof"])
    lo, hi = nees_band(dof, M)
    w = window(K)
    avg = nees.mean(axis=0)
    er = [s["estimation_rmse"] for s in summaries]
    settle = np.array([s["theta_settle_s"] for s in summaries], dtype=float).reshape(M, -1)
    marks = [tm for tm in (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0) if tm < t[-1]]
    marks.append(float(t[-1]))
    idx = [min(int(np.searchsorted(t, tm)), K - 1) for tm in marks]
    counters = {
        key: float(np.mean([s["counters"].get(key, 0) for s in summaries]))
        for key in summaries[0]["counters"]
    }
    return {
        "seeds": [int(s["seed"]) for s in summaries],
        "M": M,
        "rmse_q": _mean_std([e["q"] for e in er]),
        "rmse_qd": _mean_std([e["qd"] for e in er]),
        "rmse_theta": _mean_std([e["theta"] for e in er]),
        "tracking_q": _mean_std([s["tracking_rmse"]["q"] for s in summaries]),
        "cost_per_tick_us_median": float(np.median([s["cost_per_tick_us"] for s in summaries])),
        "cost_per_tick_us_iqr": [
            float(v) for v in np.percentile([s["cost_per_tick_us"] for s in summaries], [25, 75])
        ],
        "nees_time_avg": _mean_std([[s["nees_mean"]] for s in summaries]),
        "nees_dof": dof,
        "nees_band95": [lo, hi],
        "avg_nees_window_mean": float(avg[w].mean()),
        "avg_nees_in_band_fraction": float(np.mean((avg[w] >= lo) & (avg[w] <= hi))),
        "avg_nees_below_band_fraction": float(np.mean(avg[w] < lo)),
        "avg_nees_above_band_fraction": float(np.mean(avg[w] > hi)),
        "theta_true": [float(v) for v in theta_true],
        "theta_final": _mean_std(theta_hat[:, -1, :]),
        "theta_mean_at": {
            f"{float(t[i]):g}": np.mean(theta_hat[:, i, :], axis=0).tolist() for i in idx
        },
        "theta_settle_rel": THETA_SETTLE_REL,
        "theta_settle_s_median": np.nanmedian(settle, axis=0).tolist()
        if np.any(np.isfinite(settle))
        else [math.nan] * settle.shape[1],
        "theta_settle_s_max": np.max(settle, axis=0).tolist(),
        "theta_not_settled": np.sum(~np.isfinite(settle), axis=0).astype(int).tolist(),
        "counters_mean": counters,
        "nes_block_mean": {
            b: float(np.mean([s["nes_block"][b] for s in summaries]))
            for b in summaries[0].get("nes_block", {})
        },
    }


def _pm(ms: Mapping[str, list[float]], scale: float, digits: int = 3) -> str:
    return " / ".join(
        f"{m * scale:.{digits}g} ± {s * scale:.2g}"
        for m, s in zip(ms["mean"], ms["std"], strict=True)
    )


def format_table(agg: Mapping[str, Mapping[str, Any]], theta_unit: str = "") -> str:
    """Markdown table of one variant: a row per estimator (see the module docstring)."""
    full = [a for a in agg.values() if a.get("M")]
    lo, hi = full[0]["nees_band95"] if full else (math.nan, math.nan)
    tu = f" [{theta_unit}]" if theta_unit else ""
    head = (
        "| estimator | q RMSE [mrad] | qd RMSE [mrad/s] | theta RMSE"
        + tu
        + " | tracking RMSE [mrad] | cost/tick [us] (median) | NEES (time avg) "
        + f"| avg NEES in 95% band [{lo:.2f}, {hi:.2f}] | theta settle [s] | frames used |"
    )
    rows = [head, "|" + "---|" * 10]
    for name, a in agg.items():
        if not a.get("M"):
            msg = (a.get("errors") or ["?"])[0].replace("|", "/")
            rows.append(f"| {name} | all runs failed: {msg} |" + " |" * 8)
            continue
        if a.get("failed_seeds"):
            name = f"{name} ({len(a['failed_seeds'])} runs failed, M = {a['M']})"
        c = a["counters_mean"]
        st = a["theta_settle_s_median"]
        ns = a["theta_not_settled"]
        settle = " / ".join(
            ("–" if not math.isfinite(v) else f"{v:.2f}") + (f" ({k} never)" if k else "")
            for v, k in zip(st, ns, strict=True)
        )
        rows.append(
            f"| {name} | {_pm(a['rmse_q'], 1e3)} | {_pm(a['rmse_qd'], 1e3)} "
            f"| {_pm(a['rmse_theta'], 1.0)} | {_pm(a['tracking_q'], 1e3)} "
            f"| {a['cost_per_tick_us_median']:.0f} | {_pm(a['nees_time_avg'], 1.0)} "
            f"| {100 * a['avg_nees_in_band_fraction']:.0f} % "
            f"(mean {a['avg_nees_window_mean']:.2f}) | {settle} "
            f"| {c.get('frames_applied', 0):.1f} / {c.get('frames_delivered', 0):.1f} |"
        )
    return "\n".join(rows) + "\n"


def format_block_table(agg: Mapping[str, Mapping[str, Any]]) -> str:
    """Markdown table of the per-block normalised error squared ``e_i^2 / P_ii``."""
    full = {k: a for k, a in agg.items() if a.get("M")}
    if not full:
        return ""
    blocks = list(next(iter(full.values()))["nes_block_mean"])
    rows = [
        "| estimator | " + " | ".join(blocks) + " |",
        "|---|" + "---|" * len(blocks),
    ]
    for name, a in full.items():
        b = a["nes_block_mean"]
        rows.append(f"| {name} | " + " | ".join(f"{b[k]:.3g}" for k in blocks) + " |")
    return "\n".join(rows) + "\n"


def _progress(total: int, enabled: bool) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="study", unit="run", mininterval=1.0)


def _results(tasks: list[_Task], workers: int) -> Iterator[tuple[int, dict[str, Any]]]:
    if workers <= 1 or len(tasks) <= 1:
        for i, task in enumerate(tasks):
            yield i, _run_task(task)
        return
    saved = {k: os.environ.get(k) for k in _BLAS_ENV}
    try:
        for k in _BLAS_ENV:
            os.environ.setdefault(k, "1")
        ctx = mp.get_context("spawn")
        with ctx.Pool(min(workers, len(tasks)), initializer=_worker_init) as pool:
            yield from pool.imap_unordered(_indexed, list(enumerate(tasks)))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _indexed(item: tuple[int, _Task]) -> tuple[int, dict[str, Any]]:
    return item[0], _run_task(item[1])


def run_study(
    scenario: str | os.PathLike[str] | Scenario,
    seeds: int = 20,
    estimators: str | Sequence[str] | None = None,
    duration: float | None = None,
    workers: int = 2,
    out: str | os.PathLike[str] | None = None,
    sets: Sequence[str] = (),
    variants: Mapping[str, Sequence[str]] | None = None,
    first_seed: int = 0,
    figure_seed: int | None = None,
    progress: bool = False,
    command: str | None = None,
) -> StudyResult:
    """Run the Monte Carlo study and write its folder.

    Args:
        scenario: Scenario name, path or object.
        seeds: Number of seeds M (``first_seed .. first_seed + M - 1``).
        estimators: ``"all"``, a comma-separated string or a sequence of names.
        duration: Simulated time [s] (default: the scenario's).
        workers: Processes (1 = in-process).
        out: Output folder (default ``runs/study-<scenario>-<stamp>``).
        sets: ``KEY=VALUE`` overrides applied to every variant.
        variants: ``{label: [KEY=VALUE, ...]}``; default one variant ``"base"`` with none.
        first_seed: First seed.
        figure_seed: Seed shown in the error and theta figures (default ``first_seed``).
        progress: Show a progress bar.
        command: The command line recorded in ``study.md`` (default: rebuilt from arguments).

    Raises:
        ConfigError: Bad names, keys or values, or a scenario the run builders refuse (found
            before the pool starts by building each variant and estimator's run).
    """
    from amsfe_sym.codegen import library_for
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.sim.builders import build_run

    if seeds < 1 or workers < 1:
        raise ConfigError(
            describe("--seeds / --workers", "integers >= 1", f"{seeds} / {workers}", "fix them")
        )
    names = parse_estimators(estimators)
    base = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if duration is not None:
        base = base.with_overrides(duration=float(duration))
    base = apply_sets(base, sets)
    variant_sets = dict(variants) if variants else {"base": []}
    scen: dict[str, Scenario] = {v: apply_sets(base, s) for v, s in variant_sets.items()}
    fig_seed = first_seed if figure_seed is None else figure_seed
    seed_list = list(range(first_seed, first_seed + seeds))
    if fig_seed not in seed_list:
        raise ConfigError(describe("figure_seed", f"one of {seed_list}", str(fig_seed), "fix"))

    # Libraries: generated (if needed) here, once; workers load them by path.  Building every
    # (variant, estimator) run surfaces configuration errors before the pool starts.
    libs: dict[str, ModelLibrary] = {}
    quiet = logging.getLogger("amsfe_sym")
    old_level = quiet.level
    try:
        quiet.setLevel(logging.ERROR)
        for v, sc in scen.items():
            libs[v] = library_for(sc)
            for name in names:
                build_run(sc.with_overrides(estimator=name), libs[v])
        tasks = [
            _Task(
                variant=v,
                scenario=sc.with_overrides(estimator=name, seed=seed),
                lib_dir=str(libs[v].dir),
                keep_series=seed == fig_seed,
            )
            for v, sc in scen.items()
            for seed in seed_list
            for name in names
        ]
        bar = _progress(len(tasks), progress)
        t0 = time.perf_counter()
        results: list[dict[str, Any] | None] = [None] * len(tasks)
        for i, r in _results(tasks, workers):
            results[i] = r
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        wall = time.perf_counter() - t0
    finally:
        quiet.setLevel(old_level)

    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    folder = Path(out) if out else Path("runs") / f"study-{base.name}-{stamp}"
    folder.mkdir(parents=True, exist_ok=True)
    done = [r for r in results if r is not None]
    agg: dict[str, dict[str, Any]] = {}
    figs: list[Path] = []
    series: dict[str, dict[str, Any]] = {}
    for v in scen:
        lib = libs[v]
        agg[v] = {}
        series[v] = {}
        for name in names:
            rs = [
                r
                for r in done
                if r["summary"]["variant"] == v and r["summary"]["estimator"] == name
            ]
            rs.sort(key=lambda r: int(r["summary"]["seed"]))
            ok = [r for r in rs if not r.get("failed")]
            failed = [r["summary"] for r in rs if r.get("failed")]
            if not ok:
                agg[v][name] = {
                    "M": 0,
                    "failed_seeds": [int(f["seed"]) for f in failed],
                    "errors": [f["error"] for f in failed],
                }
                continue
            K = ok[0]["nees"].size
            t = np.arange(K) * lib.T
            nees = np.stack([r["nees"] for r in ok])
            th = np.stack([r["theta_hat"] for r in ok])
            agg[v][name] = aggregate(
                [r["summary"] for r in ok], nees, th, t, lib.theta_true.tolist()
            )
            agg[v][name]["failed_seeds"] = [int(f["seed"]) for f in failed]
            agg[v][name]["errors"] = [f["error"] for f in failed]
            fig_run = next((r for r in ok if "err" in r), None)
            nan = np.full((K, 2 * lib.n), np.nan)
            series[v][name] = {
                "t": t,
                "avg_nees": nees.mean(axis=0),
                "theta_all": th,
                "M": len(ok),
                "err": fig_run["err"] if fig_run else nan,
                "sd": fig_run["sd"] if fig_run else nan,
                "theta_hat": fig_run["theta_hat"] if fig_run else np.full_like(th[0], np.nan),
            }
        suffix = "" if len(scen) == 1 else f"-{v}"
        if series[v]:
            figs += plot_study(series[v], libs[v], scen[v], fig_seed, folder, suffix, seeds)

    cmd = command or _command_line(
        scenario if not isinstance(scenario, Scenario) else base.name,
        seeds,
        names,
        duration,
        workers,
        folder,
        sets,
        variants or {},
        first_seed,
    )
    md = _report(cmd, base, scen, variant_sets, libs, agg, seeds, first_seed, wall, workers, sets)
    (folder / "study.md").write_text(md)
    doc = {
        "command": cmd,
        "scenario": base.name,
        "provenance": provenance(),
        "workers": workers,
        "wall_time_s": round(wall, 2),
        "seeds": seed_list,
        "estimators": list(names),
        "variants": {
            v: {"sets": [*sets, *variant_sets[v]], "scenario": _jsonable(scen[v].to_dict())}
            for v in scen
        },
        "window": "last 80 % of the run",
        "aggregate": agg,
        "runs": [r["summary"] for r in done],
    }
    (folder / "study.json").write_text(json.dumps(_jsonable(doc), indent=1) + "\n")
    return StudyResult(
        out=folder, table=md, aggregate=agg, runs=[r["summary"] for r in done], figures=figs
    )


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    if isinstance(x, Path):
        return str(x)
    return x


def _command_line(
    scenario: str | os.PathLike[str],
    seeds: int,
    names: Sequence[str],
    duration: float | None,
    workers: int,
    out: Path,
    sets: Sequence[str],
    variants: Mapping[str, Sequence[str]],
    first_seed: int,
) -> str:
    parts = ["amsfe", "study", str(scenario), "--seeds", str(seeds)]
    if first_seed:
        parts += ["--first-seed", str(first_seed)]
    if tuple(names) != tuple(ESTIMATORS):
        parts += ["--estimators", ",".join(names)]
    if duration is not None:
        parts += ["--duration", f"{duration:g}"]
    parts += ["--workers", str(workers), "--out", str(out)]
    for s in sets:
        parts += ["--set", s]
    for label, vs in variants.items():
        parts += ["--variant", label, *vs]
    return shlex.join(parts)


def _report(
    cmd: str,
    base: Scenario,
    scen: Mapping[str, Scenario],
    variant_sets: Mapping[str, Sequence[str]],
    libs: Mapping[str, Any],
    agg: Mapping[str, Mapping[str, Any]],
    seeds: int,
    first_seed: int,
    wall: float,
    workers: int,
    sets: Sequence[str] = (),
) -> str:
    m = provenance()
    lines = [
        f"# Study: {base.name}",
        "",
        "```",
        cmd,
        "```",
        "",
        f"Seeds {first_seed}..{first_seed + seeds - 1} (M = {seeds}); metrics over the last "
        "80 % of each run; mean ± std over seeds (per joint: joint 1 / joint 2 ...). "
        "Cost per tick: median over seeds of the whole closed-loop tick (plant, sensors, "
        f"estimator, controller), on {m['cores']} cores shared with other jobs, {workers} "
        f"worker(s) in parallel; wall time of the study {wall:.0f} s; source {m['commit']}. "
        "'theta settle': median "
        f"over seeds of the time after which the estimate stays within "
        f"{100 * THETA_SETTLE_REL:.0f} % of the true value. 'frames used': applied / "
        "delivered per run (mean).",
        "",
    ]
    if sets:
        lines += ["Every variant: `" + " ".join(f"--set {x}" for x in sets) + "`.", ""]
    for v, sc in scen.items():
        lib = libs[v]
        unit = lib.manifest.theta[0].unit if lib.p else ""
        title = v if len(scen) > 1 else "results"
        extra = f" (`--set {' '.join(variant_sets[v])}`)" if variant_sets[v] else ""
        lines += [
            f"## {title}{extra}",
            "",
            f"Robot library `{lib.name}` (integrator {sc.integrator or 'robot default'}), "
            f"T = {lib.T:g} s, {sc.duration:g} s, N = {lib.N} states.",
            "",
            format_table(agg[v], unit),
            "Per-state normalised error squared e_i^2 / P_ii (mean over the window and the "
            "seeds, each state alone, ignoring correlations; 1 for a consistent filter):",
            "",
            format_block_table(agg[v]),
        ]
    return "\n".join(lines)
