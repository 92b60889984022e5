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

import dataclasses
import json
import logging
import math
import multiprocessing as mp
import os
import platform
import shlex
import sys
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
from amsfe_sym.scenario import Scenario, load_scenario, validate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "StudyResult",
    "aggregate",
    "apply_sets",
    "format_block_table",
    "format_table",
    "nees_band",
    "parse_estimators",
    "run_study",
    "study_from_cli",
]

log = logging.getLogger(__name__)
FloatArray = NDArray[np.float64]

#: Top-level scenario keys ``--set`` may change (``seed`` and ``estimator`` are the study's).
_TOP_SETTABLE = ("integrator", "duration", "controller")
#: Dataclass sections of :class:`Scenario`.
_SECTIONS = ("plant", "encoders", "camera", "filter", "estimate0")
#: Mapping-valued entries whose existing keys ``--set`` may change.
_MAPPINGS = ("trajectory", "controller_gains", "estimate0.std")
#: A theta estimate has "settled" once it stays within this fraction of the true value.
THETA_SETTLE_REL = 0.10


# --------------------------------------------------------------------------- overrides
def _parse_value(text: str) -> Any:
    """A TOML value (number, bool, quoted string, list) or, failing that, the bare text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def _coerce(key: str, current: Any, raw: str) -> Any:
    """``raw`` converted to the type of ``current`` (the field's present value)."""
    value = _parse_value(raw)

    def bad(expected: str) -> ConfigError:
        return ConfigError(
            describe(f"--set {key}={raw}", expected, repr(value), f"give {key} a valid value")
        )

    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(current, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("an integer")
        return value
    if isinstance(current, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad("a number")
        return float(value)
    if isinstance(current, tuple):
        items: Any = value
        if isinstance(value, str):
            items = [s for s in value.strip("[]() ").split(",") if s.strip()]
        elif not isinstance(value, list):
            items = [value]
        try:
            return tuple(float(v) for v in items)
        except (TypeError, ValueError):
            raise bad("numbers separated by commas, e.g. 0.5,0.5") from None
    if isinstance(current, str):
        if isinstance(value, list | dict):
            raise bad("a string")
        return str(value).lower() if isinstance(value, bool) else str(value)
    raise bad(f"a value like {current!r}")


def _split_set(text: str) -> tuple[str, str]:
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or not raw.strip():
        raise ConfigError(
            describe(
                f"--set {text!r}",
                "KEY=VALUE, e.g. integrator=paper or filter.link_torque_std=2",
                "no '=' or an empty side",
                "write section.field=value",
            )
        )
    return key, raw


def _settable_keys(sc: Scenario) -> list[str]:
    keys = list(_TOP_SETTABLE)
    for sec in _SECTIONS:
        keys += [f"{sec}.{f.name}" for f in dataclasses.fields(getattr(sc, sec))]
    keys += [f"trajectory.{k}" for k in sc.trajectory]
    keys += [f"controller_gains.{k}" for k in sc.controller_gains]
    keys += [f"estimate0.std.{k}" for k in sc.estimate0.std]
    return [k for k in keys if k != "estimate0.std"]


def apply_sets(sc: Scenario, sets: Sequence[str]) -> Scenario:
    """Scenario ``sc`` with ``KEY=VALUE`` overrides applied, then re-validated.

    Keys: ``integrator``, ``duration``, ``controller``; ``section.field`` for the sections
    plant, encoders, camera, filter, estimate0; ``trajectory.K``, ``controller_gains.K`` and
    ``estimate0.std.K`` for keys the scenario already has.  Values are TOML literals
    (``2``, ``0.01``, ``true``, ``"rk4"``) or bare words (``paper``); tuples are written
    ``0.5,0.5``.

    Raises:
        ConfigError: unknown key, value of the wrong type, or a value the scenario's own
            validation refuses (e.g. a negative noise standard deviation).
    """
    for text in sets:
        key, raw = _split_set(text)
        parts = key.split(".")
        if len(parts) == 1 and key in _TOP_SETTABLE:
            sc = dataclasses.replace(sc, **{key: _coerce(key, getattr(sc, key), raw)})
        elif len(parts) == 2 and parts[0] in _SECTIONS:
            sec = getattr(sc, parts[0])
            names = {f.name for f in dataclasses.fields(sec)}
            if parts[1] not in names or parts[1] == "std":
                raise _unknown_key(key, sc)
            new = _coerce(key, getattr(sec, parts[1]), raw)
            sc = dataclasses.replace(sc, **{parts[0]: dataclasses.replace(sec, **{parts[1]: new})})
        elif ".".join(parts[:-1]) in _MAPPINGS:
            where, name = ".".join(parts[:-1]), parts[-1]
            mapping: Mapping[str, Any] = (
                sc.estimate0.std if where == "estimate0.std" else getattr(sc, where)
            )
            if name not in mapping:
                raise _unknown_key(key, sc)
            d = dict(mapping)
            d[name] = _coerce(key, d[name], raw)
            if where == "estimate0.std":
                sc = dataclasses.replace(sc, estimate0=dataclasses.replace(sc.estimate0, std=d))
            else:
                changes: dict[str, Any] = {where: d}
                sc = dataclasses.replace(sc, **changes)
        else:
            raise _unknown_key(key, sc)
    validate(sc, f"{sc.name} with --set")
    return sc


def _unknown_key(key: str, sc: Scenario) -> ConfigError:
    return ConfigError(
        describe(
            f"--set key {key!r}",
            "integrator, duration, controller or section.field with section in "
            + ", ".join(_SECTIONS)
            + " (also trajectory.K, controller_gains.K, estimate0.std.K)",
            "no such field",
            "one of: " + ", ".join(_settable_keys(sc)),
        )
    )


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
                "use names from that list, e.g. --estimators oosm,replay",
            )
        )
    return tuple(dict.fromkeys(names))


# --------------------------------------------------------------------------- statistics
def nees_band(dof: int, seeds: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the across-seed average NEES.

    With M independent seeds and an N-dimensional Gaussian error that the filter's P
    describes, ``M * mean_m NEES_m(k)`` is chi-square with ``N M`` degrees of freedom, so
    the average lies in ``[chi2.ppf(a/2, N M) / M, chi2.ppf(1 - a/2, N M) / M]`` with
    probability ``1 - a``.
    """
    from scipy.stats import chi2

    if dof < 1 or seeds < 1 or not (0.0 < probability < 1.0):
        raise ConfigError(
            describe("nees_band", "dof >= 1, seeds >= 1, 0 < p < 1", f"{dof}, {seeds}", "fix")
        )
    a = 1.0 - probability
    return (
        float(chi2.ppf(a / 2, dof * seeds) / seeds),
        float(chi2.ppf(1 - a / 2, dof * seeds) / seeds),
    )


def _window(K: int) -> slice:
    return slice(int(0.2 * K), K)


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
    from amsfe_sym.simulate import run, summarize

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
    w = _window(res.t.size)
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
    w = _window(K)
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
        ConfigError: Bad names, keys or values, or a scenario ``simulate.run`` refuses (found
            before the pool starts by a 2-step run of each variant and estimator).
    """
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.simulate import library_for, run

    if seeds < 1 or workers < 1:
        raise ConfigError(
            describe(
                "--seeds / --workers",
                "integers >= 1",
                f"{seeds} / {workers}",
                "pass e.g. --seeds 20 --workers 2",
            )
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

    # Libraries: generated (if needed) here, once; workers load them by path.  A 2-step run
    # of every (variant, estimator) surfaces configuration errors before the pool starts.
    libs: dict[str, ModelLibrary] = {}
    quiet = logging.getLogger("amsfe_sym")
    old_level = quiet.level
    try:
        quiet.setLevel(logging.ERROR)
        for v, sc in scen.items():
            libs[v] = library_for(sc)
            for name in names:
                run(sc.with_overrides(estimator=name, duration=2 * libs[v].T), lib=libs[v])
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
        "machine": _machine(),
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


def _git_revision() -> str:
    """``<commit>[+dirty]`` of the source tree this module runs from, or ``"unknown"``."""
    import subprocess

    here = Path(__file__).resolve().parent

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=here, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()

    try:
        rev = git("rev-parse", "--short=12", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return rev + ("+dirty" if dirty else "") if rev else "unknown"


def _machine() -> dict[str, Any]:
    return {
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "processor": platform.processor() or platform.machine(),
        "git": _git_revision(),
    }


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
    m = _machine()
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
        f"estimator, controller), on {m['cpus']} cores shared with other jobs, {workers} "
        f"worker(s) in parallel; wall time of the study {wall:.0f} s; source {m['git']}. "
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
        unit = lib.manifest["theta"][0].get("unit", "") if lib.p else ""
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


# --------------------------------------------------------------------------- figures
def _decimate(n: int, max_points: int = 2500) -> slice:
    return slice(None, None, max(1, n // max_points))


def plot_study(
    series: Mapping[str, Mapping[str, Any]],
    lib: Any,
    sc: Scenario,
    fig_seed: int,
    out: Path,
    suffix: str = "",
    seeds: int = 1,
) -> list[Path]:
    """The study's three figures for one variant; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n, names = lib.n, list(series)
    dpi = 90
    paths: list[Path] = []
    first = series[names[0]]
    t = first["t"]
    dec = _decimate(t.size)
    w = _window(t.size)
    title = f"{sc.name}"

    # (a) estimation errors, paper Fig. 4 analog
    labels = [f"q{j + 1} [rad]" for j in range(n)] + [f"qd{j + 1} [rad/s]" for j in range(n)]
    fig, axes = plt.subplots(
        2 * n,
        len(names),
        figsize=(2.9 * len(names) + 0.6, 1.9 * 2 * n + 0.6),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    have = [s for s in series.values() if np.isfinite(s["err"]).all()] or [
        {"err": np.ones((t.size, 2 * n))}
    ]  # the figure seed's runs that did not fail
    for r in range(2 * n):
        late = max(float(np.percentile(np.abs(s["err"][w, r]), 99)) for s in have)
        top = 1.15 * max(float(np.max(np.abs(s["err"][:, r]))) for s in have)
        lin = max(2 * late, 1e-9)
        for c, name in enumerate(names):
            s = series[name]
            ax = axes[r][c]
            ax.fill_between(t[dec], -2 * s["sd"][dec, r], 2 * s["sd"][dec, r], color="0.85", lw=0)
            ax.plot(t[dec], s["err"][dec, r], lw=0.6)
            if top > 10 * lin:  # a large start transient: symlog shows it and the late error
                ax.set_yscale("symlog", linthresh=lin)
            ax.set_ylim(-max(top, lin), max(top, lin))
            ax.grid(alpha=0.3)
            if r == 0:
                ax.set_title(name, fontsize=10)
            if c == 0:
                ax.set_ylabel(labels[r], fontsize=9)
            if r == 2 * n - 1:
                ax.set_xlabel("t [s]")
            ax.tick_params(labelsize=7)
    fig.suptitle(
        f"{title}: true − estimate (grey ±2σ of the filter), seed {fig_seed}; symlog axes "
        "are linear within 2x the 99th percentile of the last 80 %",
        fontsize=10,
    )
    fig.tight_layout()
    paths.append(out / f"errors{suffix}.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)

    # (b) theta, paper Fig. 5 analog
    if lib.p:
        theta_true = lib.theta_true
        fig, axes = plt.subplots(lib.p, 2, figsize=(11, 3.4 * lib.p), squeeze=False, sharey="row")
        for i, th in enumerate(lib.manifest["theta"]):
            a0, a1 = axes[i]
            for name in names:
                s = series[name]
                (ln,) = a0.plot(t[dec], s["theta_hat"][dec, i], lw=0.9, label=name)
                allm = s["theta_all"][:, :, i]
                mu, sd = allm.mean(axis=0), allm.std(axis=0)
                a1.plot(t[dec], mu[dec], lw=0.9, color=ln.get_color(), label=name)
                a1.fill_between(
                    t[dec], (mu - sd)[dec], (mu + sd)[dec], color=ln.get_color(), alpha=0.15, lw=0
                )
            for ax in (a0, a1):
                ax.axhline(theta_true[i], color="k", ls="--", lw=0.8, label="true")
                ax.grid(alpha=0.3, which="both")
                ax.set_xscale("log")
                ax.set_xlim(t[1], t[-1])
                ax.set_xlabel("t [s] (log scale)")
            unit = th.get("unit", "")
            a0.set_ylabel(f"{th['name']} ({th['kind']}) [{unit}]")
            a0.set_title(f"seed {fig_seed}", fontsize=10)
            a1.set_title(f"mean ± std over {seeds} seeds", fontsize=10)
            a0.legend(fontsize=7)
        fig.suptitle(f"{title}: theta estimate (paper Fig. 5 analog)", fontsize=10)
        fig.tight_layout()
        paths.append(out / f"theta{suffix}.png")
        fig.savefig(paths[-1], dpi=dpi)
        plt.close(fig)

    # (c) average NEES with the 95 % band
    dof = lib.N
    fig, axes = plt.subplots(
        len(names), 1, figsize=(8, 1.7 * len(names) + 0.8), sharex=True, squeeze=False
    )
    for c, name in enumerate(names):
        ax = axes[c][0]
        avg = series[name]["avg_nees"]
        m = int(series[name].get("M", seeds))
        lo, hi = nees_band(dof, m)
        ax.plot(t[dec], avg[dec], lw=0.6, label=f"average NEES over {m} seeds")
        ax.axhspan(lo, hi, color="tab:green", alpha=0.2, lw=0, label="95 % band")
        ax.axhline(dof, color="k", lw=0.6, ls=":", label=f"N = {dof}")
        ax.axvline(t[w.start], color="0.5", lw=0.6, ls="--")
        inside = float(np.mean((avg[w] >= lo) & (avg[w] <= hi)))
        ax.set_title(f"{name}: {100 * inside:.0f} % of the last 80 % inside", fontsize=9)
        if np.nanmax(avg) > 10 * hi or np.nanmin(avg[w]) < 0.1 * lo:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7, loc="upper right")
    axes[-1][0].set_xlabel("t [s]")
    fig.suptitle(
        f"{title}: NEES averaged over seeds with its 95 % chi-square band "
        f"[{nees_band(dof, seeds)[0]:.2f}, {nees_band(dof, seeds)[1]:.2f}] (M = {seeds})",
        fontsize=10,
    )
    fig.tight_layout()
    paths.append(out / f"nees{suffix}.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)
    return paths


# --------------------------------------------------------------------------- CLI
def _parse_variant(items: Sequence[str]) -> tuple[str, list[str]]:
    label, *sets = items
    if "=" in label or not label:
        raise ConfigError(
            describe(
                "--variant",
                "LABEL KEY=VALUE [KEY=VALUE ...]",
                repr(" ".join(items)),
                "start with a label, e.g. --variant paper integrator=paper",
            )
        )
    return label, list(sets)


def study_from_cli(args: Any) -> int:
    """``amsfe study`` (see :mod:`amsfe_sym.cli`)."""
    variants = dict(_parse_variant(v) for v in (args.variant or [])) or None
    res = run_study(
        args.scenario,
        seeds=args.seeds,
        estimators=args.estimators,
        duration=args.duration,
        workers=args.workers,
        out=args.out,
        sets=list(args.set or []),
        variants=variants,
        first_seed=args.first_seed,
        progress=not args.no_progress,
    )
    print(res.table)
    print(f"study folder: {res.out} (study.md, study.json, {len(res.figures)} figures)")
    return 0
