"""The paper's comparison: several controllers on one scenario and one seed, and its figures.

``amsfe simulate`` on a scenario with a ``compare`` list (paper-sim, paper-exp) and no
``--controller`` runs every listed controller on the same seed (the same noise, the same
camera frames), writes each run's folder under ``<out>/<controller>/``, a
``comparison.json`` table, and the paper's figures:

- trajectories of the simulation study (paper-sim): ``fig04_estimation_errors.png`` (q1, qd1,
  q2, qd2 estimation errors of the fusion estimate), ``fig05_theta_error.png``, one
  ``fig06_joint1_tracking.png``, ``fig07_joint2_tracking.png`` (``tracking_joint3.png``, ... on
  longer arms) (proposed vs
  the baselines), ``sliding_surface.png`` (s(k)) and ``torque.png`` (u(k), with a zoom that
  shows the chattering);
- the experiment (paper-exp, one link on a circle): ``fig12_encoder_vision_fused.png``,
  ``fig13_estimation_error.png``, ``fig14_tip_tracking_error.png``, plus the same s(k) and
  u(k) figures.

A diverged run is drawn up to the time it diverged, and the figures say so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import run_filler, summarize
from amsfe_sym.sim.result import RunResult

__all__ = ["Comparison", "comparison_filler", "run_comparison", "write_comparison"]


@dataclass
class Comparison:
    """Runs of several controllers on one scenario and seed (``results`` in the given order)."""

    scenario: Scenario
    results: dict[str, RunResult]


def run_comparison(
    scenario: Scenario,
    controllers: tuple[str, ...],
    lib: ModelLibrary,
    progress: bool = False,
    runtime: str = "compiled",
) -> Comparison:
    """Run ``scenario`` once per controller on ``lib`` (same seed, estimator and noise), on
    the ``runtime`` of :func:`amsfe_sym.sim.loop.run`."""
    results: dict[str, RunResult] = {}
    for name in controllers:
        sc = replace(scenario, controller=name, compare=())
        results[name] = run(sc, lib, progress=progress, runtime=runtime)
    return Comparison(scenario, results)


def comparison_table(cmp: Comparison) -> dict[str, Any]:
    """Per controller: tracking RMSE and max error after the transient, RMS u, chattering,
    saturation, the Sarpturk fractions, and where it diverged."""
    rows = {}
    for name, res in cmp.results.items():
        s = summarize(res)
        rows[name] = {
            "diverged_at_s": s["diverged_at_s"],
            **s["control"],
            "sliding_conditions": s["sliding_conditions"],
            "estimation_rmse_q": s["estimation_rmse"]["q"],
        }
    return {
        "scenario": cmp.scenario.name,
        "estimator": cmp.scenario.estimator,
        "seed": cmp.scenario.seed,
        "window": "last 80 % of each run (after the transient)",
        "controllers": rows,
    }


def comparison_filler(
    cmp: Comparison,
    figures: Callable[[Comparison, Path], object] | None = None,
    extra: Callable[[str, RunResult, Path], object] | None = None,
) -> Callable[[Path], None]:
    """The ``fill(folder)`` of a comparison folder: each run in ``folder/<controller>/``
    (then ``extra(controller, result, run_folder)``, e.g. its bag), ``comparison.json`` and
    ``figures(cmp, folder)``."""

    def fill(tmp: Path) -> None:
        for name, res in cmp.results.items():
            run_dir = tmp / name

            def more(folder: Path, name: str = name, res: RunResult = res) -> None:
                if extra is not None:
                    extra(name, res, folder)

            write_folder(run_dir, run_filler(res, run_dir, extra=more), replace=False)
        write_json(tmp / "comparison.json", comparison_table(cmp))
        if figures is not None:
            figures(cmp, tmp)

    return fill


def write_comparison(
    cmp: Comparison,
    out: Path,
    figures: Callable[[Comparison, Path], object] | None = None,
    force: bool = False,
) -> Path:
    """Write each run to ``out/<controller>/``, ``comparison.json`` and the figures
    (``figures(cmp, folder)``, e.g. :func:`amsfe_sym.apps.plots.paper.plot_comparison`).

    The folder is built beside ``out`` under a hidden name and renamed at the end, so it is
    complete or absent; an existing ``out`` is refused unless ``force`` and this tool wrote
    it (:func:`amsfe_sym.core.outputs.check_output`).
    """
    check_output(out, option="out", force=force)
    return write_folder(out, comparison_filler(cmp, figures), replace=force) / "comparison.json"


def print_comparison(cmp: Comparison, out: Path) -> None:
    """The table a user reads after ``amsfe simulate``."""
    table = comparison_table(cmp)
    print(f"comparison folder: {out}  (scenario {cmp.scenario.name}, seed {cmp.scenario.seed})")
    print(
        f"  {'controller':<12} {'tracking RMSE [rad]':<24} {'max error [rad]':<22} "
        f"{'RMS u [N m]':<16} {'saturated':>9}  status"
    )
    for name, row in table["controllers"].items():
        status = (
            f"diverged at t = {row['diverged_at_s']:.3f} s"
            if row["diverged_at_s"] is not None
            else "ok"
        )
        print(
            f"  {name:<12} {_fmt(row['tracking_rmse']):<24} {_fmt(row['tracking_max_error']):<22} "
            f"{_fmt(row['u_rms'], 1):<16} {row['saturated_fraction']:>9.3f}  {status}"
        )


def _fmt(v: list[float], digits: int = 4) -> str:
    return " ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float))
