"""``amsfe study``: variants x seeds x estimators, run and written to a folder."""

from __future__ import annotations

import json
import logging
import math
import os
import shlex
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.plots.run import plot_study
from amsfe_sym.apps.study.metrics import (
    THETA_SETTLE_REL,
    aggregate,
    format_block_table,
    format_table,
)
from amsfe_sym.apps.study.records import study_json_text
from amsfe_sym.apps.study.workers import Task, progress_bar, run_tasks
from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.provenance import provenance
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation import ESTIMATORS
from amsfe_sym.scenario import Scenario, apply_sets, load_scenario

__all__ = ["StudyResult", "is_study_folder", "parse_estimators", "run_study"]


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
    runtime: str = "compiled",
    force: bool = False,
    inputs: Sequence[str | os.PathLike[str]] = (),
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
        runtime: ``"compiled"`` (the C loop) or ``"python"`` (the reference loop).
        force: Replace an existing ``out`` that this tool wrote.
        inputs: Files the study reads (the scenario file): ``out`` may not be, hold or lie
            inside one.

    The folder is written whole at the end (complete or absent); ``out`` is checked before
    anything runs (:func:`amsfe_sym.core.outputs.check_output`).

    Raises:
        ConfigError: Bad names, keys or values, or a scenario the run builders refuse (found
            before the pool starts by building each variant and estimator's run).
        RunFolderError: ``out`` cannot be written as asked.
    """
    from amsfe_sym.codegen import library_for
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.sim.builders import build_run

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
        raise ConfigError(
            describe(
                "figure_seed",
                f"one of {seed_list}",
                str(fig_seed),
                "pass a seed of the study (first_seed .. first_seed + seeds - 1)",
            )
        )
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    folder = Path(out) if out else Path("runs") / f"study-{base.name}-{stamp}"
    # before the runs
    check_output(folder, option="--out", force=force, inputs=inputs, own=is_study_folder)

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
                build_run(sc.with_overrides(estimator=name), libs[v], runtime == "compiled")
        tasks = [
            Task(
                variant=v,
                scenario=sc.with_overrides(estimator=name, seed=seed),
                lib_dir=str(libs[v].dir),
                keep_series=seed == fig_seed,
                runtime=runtime,
            )
            for v, sc in scen.items()
            for seed in seed_list
            for name in names
        ]
        bar = progress_bar(len(tasks), progress)
        t0 = time.perf_counter()
        results: list[dict[str, Any] | None] = [None] * len(tasks)
        for i, r in run_tasks(tasks, workers):
            results[i] = r
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        wall = time.perf_counter() - t0
    finally:
        quiet.setLevel(old_level)

    done = [r for r in results if r is not None]
    written: dict[str, Any] = {}

    def fill(tmp: Path) -> None:
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
                figs += plot_study(series[v], libs[v], scen[v], fig_seed, tmp, suffix, seeds)

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
            runtime,
        )
        md = _report(
            cmd, base, scen, variant_sets, libs, agg, seeds, first_seed, wall, workers, sets
        )
        (tmp / "study.md").write_text(md)
        doc = {
            "command": cmd,
            "scenario": base.name,
            "provenance": provenance(),
            "workers": workers,
            "runtime": runtime,
            "wall_time_s": round(wall, 2),
            "seeds": seed_list,
            "estimators": list(names),
            "variants": {
                v: {"sets": [*sets, *variant_sets[v]], "scenario": _jsonable(scen[v].to_dict())}
                for v in scen
            },
            "window": "last 80 % of the run",
            "aggregate": agg,
        }
        runs = [r["summary"] for r in done]
        (tmp / "study.json").write_text(study_json_text(doc, runs))  # runs: records.py
        written.update(agg=agg, md=md, figs=[folder / f.relative_to(tmp) for f in figs])

    write_folder(folder, fill, replace=force, own=is_study_folder)
    agg, md, figs = written["agg"], written["md"], written["figs"]
    return StudyResult(
        out=folder, table=md, aggregate=agg, runs=[r["summary"] for r in done], figures=figs
    )


def is_study_folder(path: Path) -> bool:
    """Whether ``path`` is a study folder amsfe wrote: it holds the marker, or (written
    before the marker existed) a ``study.json`` with the study's keys, or a ``study.md``
    whose first line is the study report's title."""
    from amsfe_sym.core.folders import is_run_folder

    if is_run_folder(path):
        return True
    try:
        doc = json.loads((path / "study.json").read_text())
        return isinstance(doc, dict) and {"command", "aggregate"} <= set(doc)
    except (OSError, ValueError):
        pass
    try:
        with (path / "study.md").open() as f:
            return f.readline().startswith("# Study: ")
    except OSError:
        return False


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
    runtime: str = "compiled",
) -> str:
    parts = ["amsfe", "study", str(scenario), "--seeds", str(seeds)]
    if runtime != "compiled":
        parts += ["--runtime", runtime]
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
