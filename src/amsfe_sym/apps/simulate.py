"""``amsfe simulate``: one run or the paper's comparison, written to a run folder with its
figures, and the headline numbers printed.

The closed loop itself is :func:`amsfe_sym.sim.loop.run` (both runtimes); the run folder is
:func:`amsfe_sym.sim.record.write_run`; this module is the application that puts them
together and draws the figures (:mod:`amsfe_sym.apps.plots`) into the folder.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import check_out, summarize, write_run
from amsfe_sym.sim.result import RunResult

__all__ = ["RunResult", "SimulateOptions", "print_run", "simulate_comparison", "simulate_one"]


@dataclass(frozen=True)
class SimulateOptions:
    """How ``amsfe simulate`` runs and writes.

    Attributes:
        plots: Draw the figures into the run folder.
        force: Replace an existing run folder.
        progress: Show a progress bar.
        runtime: ``"compiled"`` (the C loop) or ``"python"`` (the reference loop).
        bag: Also write the run as a rosbag2 in MCAP (:mod:`amsfe_sym.logs.write`) at this
            folder; ``Path()`` (empty): ``<run folder>/bag``; None: no bag.
    """

    plots: bool = True
    force: bool = False
    progress: bool = False
    runtime: str = "compiled"
    bag: Path | None = None


def simulate_one(
    sc: Scenario, lib: ModelLibrary, out: Path, options: SimulateOptions = SimulateOptions()
) -> RunResult:
    """Run ``sc`` on ``lib``, write the run folder ``out`` (with figures if
    ``options.plots``) and print its headline numbers.

    Raises:
        RunFolderError: ``out`` exists and ``options.force`` is off (checked before the run).
    """
    check_out(out, options.force)  # before the run: nothing is computed for nothing
    res = run(sc, lib, progress=options.progress, runtime=options.runtime)
    figures = None
    if options.plots:
        from amsfe_sym.apps.plots.run import plot_run

        figures = plot_run
    write_run(res, out, figures=figures, force=options.force)
    if options.bag is not None:
        bag = write_bag(res, out / "bag" if options.bag == Path() else options.bag)
        print(f"bag: {bag} (open its .mcap in Foxglove; amsfe estimate {bag})")
    print_run(res, out)
    return res


def write_bag(res: RunResult, path: Path) -> Path:
    """The run as a rosbag2 in MCAP with its URDF, ``/tf`` of the true and estimated arms,
    sensors, torque, truth and config (``amsfe estimate`` reads it back)."""
    from amsfe_sym.logs.write import write_run_bag

    urdf = Path(res.lib.manifest.urdf)
    return write_run_bag(res, path, urdf.read_text() if urdf.is_file() else None)


def simulate_comparison(
    sc: Scenario,
    lib: ModelLibrary,
    controllers: tuple[str, ...],
    out: Path,
    options: SimulateOptions = SimulateOptions(),
) -> None:
    """Run ``sc`` once per controller (same seed and noise), write ``out/<controller>/``,
    ``comparison.json`` and the paper's figures, and print the comparison."""
    from amsfe_sym.apps.reproduce import print_comparison, run_comparison, write_comparison

    check_out(out, options.force)  # before the runs
    cmp = run_comparison(sc, controllers, lib, progress=options.progress, runtime=options.runtime)
    figures = None
    if options.plots:
        from amsfe_sym.apps.plots.paper import plot_comparison

        figures = plot_comparison
    write_comparison(cmp, out, figures=figures, force=options.force)
    if options.bag is not None:
        for name, res in cmp.results.items():
            where = out / name / "bag" if options.bag == Path() else options.bag / name
            print(f"bag: {write_bag(res, where)}")
    print_comparison(cmp, out)


def print_run(res: RunResult, out: Path) -> None:
    """The headline numbers of one run: ticks and cost, estimation and tracking RMSE over
    the last 80 %, theta, mean NEES."""
    s = summarize(res)
    print(f"run folder: {out}")
    if res.diverged_at is not None:
        print(f"  diverged at t = {res.diverged_at:.3f} s (the run stops there)")
    print(
        f"  {s['ticks']} ticks ({s['sim_time_s']:.2f} s simulated) in {s['wall_time_s']:.2f} s "
        f"wall, {s['cost_per_tick_us']:.1f} us/tick"
    )
    er = s["estimation_rmse"]
    print(
        f"  estimation RMSE (last 80 %): q {np.round(er['q'], 5).tolist()} rad, "
        f"qd {np.round(er['qd'], 4).tolist()} rad/s, theta {np.round(er['theta'], 4).tolist()}"
    )
    print(
        f"  theta: true {s['theta_final']['true']}, final estimate "
        f"{np.round(s['theta_final']['estimate'], 4).tolist()}"
    )
    print(
        f"  tracking RMSE: {np.round(s['tracking_rmse']['q'], 4).tolist()} rad; "
        f"mean NEES {s['nees_mean']:.2f} (N = {s['nees_dof']})"
    )
