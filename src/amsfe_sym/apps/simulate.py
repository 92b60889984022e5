"""``amsfe simulate``: one run or the paper's comparison, written to a run folder with its
figures, and the headline numbers printed.

The closed loop itself is :func:`amsfe_sym.sim.loop.run` (both runtimes); the run folder is
:func:`amsfe_sym.sim.record.write_run`; this module is the application that puts them
together and draws the figures (:mod:`amsfe_sym.apps.plots`) into the folder.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.core.folders import FolderJob, write_folders
from amsfe_sym.core.outputs import Output, check_output
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import run_filler, summarize
from amsfe_sym.sim.result import RunResult

__all__ = [
    "BAG_IN_RUN",
    "RunResult",
    "SimulateOptions",
    "SimulateOutputs",
    "check_outputs",
    "print_run",
    "simulate_comparison",
    "simulate_one",
    "write_bag",
]


#: ``SimulateOptions.bag`` for the bag inside the run folder (``--bag`` without a folder).
BAG_IN_RUN = "<run folder>/bag"


@dataclass(frozen=True)
class SimulateOptions:
    """How ``amsfe simulate`` runs and writes.

    Attributes:
        plots: Draw the figures into the run folder.
        all_plots: A comparison on an arm of more than two joints also draws the sliding
            variable and the torque (the paper's arms always do).
        force: Replace an existing run folder (and bag) that this tool wrote.
        progress: Show a progress bar.
        runtime: ``"compiled"`` (the C loop) or ``"python"`` (the reference loop).
        bag: Also write the run as a rosbag2 in MCAP (:mod:`amsfe_sym.logs.write`) at this
            folder; :data:`BAG_IN_RUN`: ``<run folder>/bag``; None: no bag.
        inputs: Files the command reads (the scenario file): never written.
        started_s: How long the command had run before this call [s] (the library's
            compile, start-up), for the ``--no-plots`` hint's share; None: 0.
        images: With the bag, the camera writes images of the marker in this format
            (``mono8``, ``jpeg``, ``png``) and its CameraInfo instead of its pixel topic
            (docs/camera.md); None: the pixel topic.
    """

    plots: bool = True
    all_plots: bool = False
    force: bool = False
    progress: bool = False
    runtime: str = "compiled"
    bag: Path | str | None = None
    inputs: tuple[Path, ...] = ()
    started_s: float | None = None
    images: str | None = None


@dataclass(frozen=True)
class SimulateOutputs:
    """The checked outputs of one ``amsfe simulate``: the run (or comparison) folder and,
    when ``--bag DIR`` names a folder elsewhere, that bag folder."""

    run: Output
    bag: Output | None


def check_outputs(out: Path, options: SimulateOptions) -> SimulateOutputs:
    """Check ``out`` and ``options.bag`` before the run (:func:`check_output`): an explicit
    ``--bag`` may not be, hold or lie inside ``--out`` (``--bag`` alone writes it there).

    Raises:
        RunFolderError: one line naming the path, what is there and what to do.
        ConfigError: ``--images`` without ``--bag``.
    """
    if options.images is not None and options.bag is None:
        raise ConfigError(
            describe("--images", "--bag too (the images go into the bag)", "no --bag", "add --bag")
        )
    run_out = check_output(out, option="--out", force=options.force, inputs=options.inputs)
    bag = None
    if options.bag is not None and options.bag != BAG_IN_RUN:
        bag = check_output(
            options.bag,
            option="--bag",
            force=options.force,
            inputs=options.inputs,
            others=[run_out],
        )
    return SimulateOutputs(run_out, bag)


def _urdf_text(res: RunResult) -> str | None:
    urdf = Path(res.lib.manifest.urdf)
    return urdf.read_text() if urdf.is_file() else None


def _images(options: SimulateOptions) -> Any:
    """The simulated camera's image options of ``--images`` (None: the pixel topic)."""
    if options.images is None:
        return None
    from amsfe_sym.vision.sim_images import ImageOptions

    return ImageOptions(format=options.images)  # type: ignore[arg-type]


def _write_bag_into(res: RunResult, folder: Path, options: SimulateOptions) -> None:
    """The run's bag as ``folder/bag``, inside the run folder being written."""
    from amsfe_sym.logs.write import run_bag_filler

    run_bag_filler(res, _urdf_text(res), _images(options))(folder / "bag")


def simulate_one(
    sc: Scenario, lib: ModelLibrary, out: Path, options: SimulateOptions = SimulateOptions()
) -> RunResult:
    """Run ``sc`` on ``lib``, write the run folder ``out`` (with figures if
    ``options.plots``, and its bag) and print its headline numbers.

    The run folder and the bag are one unit: a bag inside the run folder is written in the
    same temporary folder, a bag elsewhere is renamed into place together with it
    (:func:`~amsfe_sym.core.folders.write_folders`): both or neither.

    Raises:
        RunFolderError: ``out`` or the bag cannot be written as asked (checked before the
            run).
    """
    from amsfe_sym.apps.plots.cost import FigureClock
    from amsfe_sym.logs.write import bag_job, run_bag_filler

    clock = FigureClock(options.started_s)
    outs = check_outputs(out, options)  # before the run: nothing is computed for nothing
    res = run(sc, lib, progress=options.progress, runtime=options.runtime)
    figures = None
    if options.plots:
        from amsfe_sym.apps.plots.run import plot_run

        figures = clock.timed(plot_run)
    inside = options.bag == BAG_IN_RUN

    def extra(folder: Path) -> None:
        if inside:
            _write_bag_into(res, folder, options)

    jobs = [FolderJob(out, run_filler(res, out, figures, extra), options.force)]
    if outs.bag is not None:
        filler = run_bag_filler(res, _urdf_text(res), _images(options))
        jobs.append(bag_job(outs.bag.path, filler, options.force))
    write_folders(jobs)
    if options.bag is not None:
        bag = out / "bag" if inside else Path(options.bag)
        print(f"bag: {bag} (open its .mcap in Foxglove; amsfe estimate {bag})")
    print_run(res, out)
    if hint := clock.hint():
        print(f"  {hint}")
    return res


def write_bag(res: RunResult, path: Path, replace: bool = False) -> Path:
    """The run as a rosbag2 in MCAP with its URDF, ``/tf`` of the true and estimated arms,
    sensors, torque, truth and config (``amsfe estimate`` reads it back)."""
    from amsfe_sym.logs.write import write_run_bag

    return write_run_bag(res, path, _urdf_text(res), replace)


def simulate_comparison(
    sc: Scenario,
    lib: ModelLibrary,
    controllers: tuple[str, ...],
    out: Path,
    options: SimulateOptions = SimulateOptions(),
) -> None:
    """Run ``sc`` once per controller (same seed and noise), write ``out/<controller>/``,
    ``comparison.json`` and the paper's figures, and print the comparison.  The bags go to
    ``out/<controller>/bag``, or ``<--bag>/<controller>`` written together with ``out``."""
    from amsfe_sym.apps.plots.cost import FigureClock
    from amsfe_sym.apps.reproduce import comparison_filler, print_comparison, run_comparison
    from amsfe_sym.logs.write import bag_job, run_bag_filler

    clock = FigureClock(options.started_s)
    outs = check_outputs(out, options)  # before the runs
    cmp = run_comparison(sc, controllers, lib, progress=options.progress, runtime=options.runtime)
    figures = None
    if options.plots:
        from amsfe_sym.apps.plots.paper import plot_comparison

        every = options.all_plots
        figures = clock.timed(lambda cmp, out: plot_comparison(cmp, out, every=every))
    inside = options.bag == BAG_IN_RUN

    def extra(name: str, res: RunResult, folder: Path) -> None:
        if inside:
            _write_bag_into(res, folder, options)

    def bags(folder: Path) -> None:
        folder.mkdir()
        for name, res in cmp.results.items():
            run_bag_filler(res, _urdf_text(res), _images(options))(folder / name)

    jobs = [FolderJob(out, comparison_filler(cmp, figures, extra), options.force)]
    if outs.bag is not None:
        jobs.append(bag_job(outs.bag.path, bags, options.force))
        # (bag_job writes into a child named after the folder: one bag per controller below)
    write_folders(jobs)
    if options.bag is not None:
        for name in cmp.results:
            print(f"bag: {out / name / 'bag' if inside else Path(options.bag) / name}")
    print_comparison(cmp, out)
    if hint := clock.hint():
        print(f"  {hint}")


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
