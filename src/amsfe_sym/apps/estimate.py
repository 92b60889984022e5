"""``amsfe estimate LOG``: an estimator of a generated robot over a recorded log (a ROS 1
``.bag``, a rosbag2 folder, an ``.mcap``), into a run folder (docs/how-to/logs.md).

A log written by ``amsfe simulate --bag`` carries its robot, scenario and estimator
(``/amsfe/config``), so ``amsfe estimate LOG`` alone reproduces the run's estimates; any
other log needs ``--robot ROBOT`` (the estimate starts from the log's first samples, the
filter from its defaults) or ``--scenario FILE`` (to tune the filter).  Topics are found by
message type and joint names (a driver's ``/joint_states``); a topic spec (``--log-spec``)
is for the unusual log.  The log's topics, types, joint names and rate are checked before
the robot's library is generated or loaded.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.estimate_build import (
    LogEstimator,
    default_scenario,
    effort_options,
    estimator_for_log,
    read_robot_log,
    robot_of,
)
from amsfe_sym.apps.estimate_filter import (
    HELD_THETA_STD,
    INPUT_UNKNOWN_ESTIMATOR,
    ROBOT_TORQUE_STD,
)
from amsfe_sym.apps.estimate_report import (
    CommandTiming,
    EstimateRun,
    figures,
    nis_report,
    print_summary,
    summary,
)
from amsfe_sym.apps.phases import Phases, command_startup_s
from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.toml import dump_toml, tomllib
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.read import read_config
from amsfe_sym.logs.source import log_topics
from amsfe_sym.logs.spec import read_log_spec
from amsfe_sym.scenario import Scenario, load_scenario, parse_scenario

__all__ = [
    "HELD_THETA_STD",
    "INPUT_UNKNOWN_ESTIMATOR",
    "ROBOT_TORQUE_STD",
    "EstimateOptions",
    "EstimateRun",
    "LogEstimator",
    "add_arguments",
    "default_out",
    "default_scenario",
    "effort_options",
    "estimate_command",
    "estimator_for_log",
    "from_args",
    "nis_report",
    "print_summary",
    "read_robot_log",
    "summary",
]


@dataclass(frozen=True)
class EstimateOptions:
    """How ``amsfe estimate`` runs.

    Attributes:
        scenario: Scenario file for a log without amsfe's config (or to override it).
        log_spec: Topic spec TOML (topics, joint names, effort kind, timing), or None.
        estimator: Estimator name overriding the scenario's.
        runtime: ``"compiled"`` (the library's C estimator) or ``"python"`` (the reference).
        plots: Draw the figures.
        force: Replace an existing run folder.
        robot: The robot (a shipped name or a ``robot.toml``) for a log without amsfe's
            config, when no scenario is given: filter defaults, start from the log.
        verbose: Print which topic plays which role, and the clock offset.
    """

    scenario: str | None = None
    log_spec: str | None = None
    estimator: str | None = None
    runtime: str = "compiled"
    plots: bool = True
    force: bool = False
    robot: str | None = None
    verbose: bool = False


def _config_scenario(path: Path, config: dict[str, Any]) -> Scenario:
    try:
        data = tomllib.loads(str(config["scenario_toml"]))
    except tomllib.TOMLDecodeError as exc:
        raise LogError(
            describe(
                f"log {path}: /amsfe/config scenario_toml",
                "the run's scenario as TOML (written by amsfe simulate --bag)",
                f"text that is not TOML ({exc})",
                "pass --scenario FILE (or --robot ROBOT) to give it yourself (docs/how-to/logs.md)",
            )
        ) from exc
    return parse_scenario(data, path)


def _scenario(path: Path, config: dict[str, Any] | None, options: EstimateOptions) -> Scenario:
    from_config = None
    if config is not None and "scenario_toml" in config:
        from_config = _config_scenario(path, config)
    if options.scenario is not None:
        sc = load_scenario(options.scenario)
    elif options.robot is not None:
        sc = default_scenario(options.robot)
    elif from_config is not None:
        sc = from_config
    else:
        raise LogError(
            describe(
                f"log {path}",
                "amsfe's run config (/amsfe/config, written by amsfe simulate --bag)",
                "none",
                "pass --robot ROBOT (a shipped robot or a robot.toml: the estimate starts "
                "from the log), or --scenario FILE to tune the filter (docs/how-to/logs.md)",
            )
        )
    if from_config is not None and sc is not from_config:
        mine, theirs = robot_of(sc.robot), robot_of(from_config.robot)
        if (mine[0], mine[1]) != (theirs[0], theirs[1]):
            raise LogError(
                describe(
                    f"log {path}",
                    f"a log of robot {mine[0]} ({len(mine[1])} joints: {mine[1]})",
                    f"its config says robot {theirs[0]} ({len(theirs[1])} joints)",
                    f"estimate it with --robot {theirs[0]}, or a scenario of that robot",
                )
            )
    return sc.with_overrides(estimator=options.estimator)


def estimate_command(
    log_path: Path, out: Path, options: EstimateOptions, startup_s: float | None = None
) -> EstimateRun:
    """Estimate over ``log_path`` and write the run folder ``out``: ``estimates.parquet``,
    ``summary.json``, ``config.toml``, figures and ``estimates/`` (a rosbag2 in MCAP).

    Everything about the log (container, topics, types, joint names, rate, stamps) is
    checked before the robot's library is generated or loaded.  ``startup_s``: the
    process's age [s] when the command started
    (:func:`~amsfe_sym.apps.phases.process_age_s`), for the summary's timing; None from
    Python.

    Raises:
        LogError: the log cannot be used (one line: what, found, fix).
        ConfigError, RunFolderError: bad settings, an existing ``out`` without ``force``, an
            ``out`` that is, holds or lies inside an input (the log), even with ``force``.
    """
    clock = Phases()
    inputs = [p for p in (log_path, options.scenario, options.log_spec) if p and Path(p).exists()]
    if log_path.is_file() and (log_path.parent / "metadata.yaml").is_file():
        inputs.append(log_path.parent)  # the .mcap of a bag folder: the folder is the log
    check_output(out, option="--out", force=options.force, inputs=inputs)
    spec = read_log_spec(options.log_spec)
    effort = effort_options(spec, options.log_spec)  # checked before anything is read
    clock.lap("setup")
    topics = log_topics(log_path)
    config = read_config(log_path, spec, topics)
    clock.lap("read")
    sc = _scenario(log_path, config, options)
    clock.lap("setup")
    log, derived = read_robot_log(
        log_path, spec, sc.robot, topics, verbose=options.verbose, clock=clock
    )
    log.config = config
    clock.lap("read")
    robot_defaults = options.scenario is None and (options.robot is not None or config is None)
    built = estimator_for_log(
        sc,
        log,
        spec,
        effort,
        robot_defaults=robot_defaults,
        estimator_given=options.estimator is not None,
        derived=derived,
        compiled=options.runtime == "compiled",
        verbose=options.verbose,
        clock=clock,
    )
    sc, lib, settled = built.scenario, built.lib, built.filter
    from amsfe_sym.logs.replay import estimate_log

    clock.lap("setup")
    result = estimate_log(built.feed, built.estimator, states=lib.N)
    clock.lap("estimate")
    run = EstimateRun(
        log, result, sc, out, clock.spent["read"], clock.spent["estimate"], noise=settled.noise
    )
    _write(run, lib.manifest.joints, options, clock, startup_s)
    return run


def add_arguments(e: argparse.ArgumentParser) -> None:
    """The options of ``amsfe estimate``."""
    e.add_argument("log", help="a ROS 1 .bag, a rosbag2 folder or an .mcap file")
    e.add_argument(
        "--robot",
        default=None,
        help="the robot (name or robot.toml) for a log not written by amsfe",
    )
    e.add_argument("--scenario", default=None, help="robot + filter settings, to tune the filter")
    e.add_argument(
        "--log-spec",
        default=None,
        metavar="FILE",
        help="topics, joint names, effort kind, the filter's R and Q ([filter]) (TOML)",
    )
    e.add_argument("--estimator", default=None, help="estimator name (default the scenario's)")
    e.add_argument(
        "--out",
        default=None,
        help="run folder (default runs/estimate-<log>-<stamp>); never the log, inside it or "
        "around it, even with --force",
    )
    e.add_argument("--runtime", choices=("compiled", "python"), default="compiled")
    e.add_argument("--no-plots", action="store_true", help="skip the figures")
    e.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out run folder that amsfe wrote (never an input)",
    )


def from_args(args: argparse.Namespace) -> int:
    """``amsfe estimate LOG`` from its parsed options (:func:`add_arguments`)."""
    startup_s = command_startup_s()
    log = Path(args.log)
    out = Path(args.out) if args.out else default_out(log)
    opts = EstimateOptions(
        args.scenario,
        args.log_spec,
        args.estimator,
        args.runtime,
        not args.no_plots,
        args.force,
        robot=args.robot,
        verbose=True,
    )
    run = estimate_command(log, out, opts, startup_s)
    print_summary(summary(run), out)
    from amsfe_sym.apps.plots.cost import hint_line

    if hint := hint_line(run.figures_s, (run.timing.startup_s or 0.0) + run.timing.wall_s):
        print(f"  {hint}")
    return 0


def _write(
    run: EstimateRun,
    joints: tuple[str, ...] | list[str],
    options: EstimateOptions,
    clock: Phases | None = None,
    startup_s: float | None = None,
) -> None:
    """The run folder; ``summary.json`` last, with the time the rest took (``clock``: the
    command's phases so far, :attr:`EstimateRun.timing` is set from it)."""
    log, est = run.log, run.estimate

    def fill(tmp: Path) -> None:
        import pyarrow.parquet as pq

        N = est.x_hat.shape[1]
        cols: dict[str, Any] = {"t": log.t}
        for i in range(N):
            cols[f"est_{i}"] = est.x_hat[:, i]
        for i in range(N):
            cols[f"var_{i}"] = est.P_diag[:, i]
        if est.nees is not None:
            cols["nees"] = est.nees
        # no dictionary encoding: float columns have no repeats to find (0.42 -> 0.06 s and
        # 20 % smaller for 60 s of a Panda; the same values read back)
        pq.write_table(_arrow_table(cols), tmp / "estimates.parquet", use_dictionary=False)
        (tmp / "config.toml").write_text(
            f"# the scenario amsfe estimate used on {log.path}\n"
            + dump_toml(run.scenario.to_dict())
        )
        from amsfe_sym.logs.write import write_estimate_bag

        # a bag's times are unsigned: a sim-time log whose first stamp is jittered below 0
        # starts its estimates at 0 (moved by less than T / 2)
        start = max(log.t0_ns, 0) * 1e-9
        write_estimate_bag(tmp / "estimates", start, log.t, joints, est.x_hat, est.P_diag)
        if options.plots:
            t = time.perf_counter()
            figures(run, tmp)
            run.figures_s = time.perf_counter() - t
        if clock is not None:
            wall = clock.lap("write")
            p = clock.spent
            run.timing = CommandTiming(
                startup_s, p.get("setup", 0.0), p.get("library", 0.0), p["write"], wall
            )
        write_json(tmp / "summary.json", summary(run))

    write_folder(run.out, fill, replace=options.force)


def _arrow_table(cols: dict[str, Any]) -> Any:
    """float64 columns as a ``pyarrow`` table, NaN as null (what ``pandas``' ``to_parquet``
    wrote: the same table, without its index metadata), built from the arrays' buffers:
    ``pa.array`` and ``pa.table`` import ``pandas`` to test their input (0.4-0.6 s)."""
    import pyarrow as pa

    arrays = []
    for v in cols.values():
        a = np.ascontiguousarray(v, dtype=np.float64)
        nan = np.isnan(a)
        nulls = int(nan.sum())
        valid = pa.py_buffer(np.packbits(~nan, bitorder="little")) if nulls else None
        arrays.append(
            pa.Array.from_buffers(pa.float64(), a.size, [valid, pa.py_buffer(a)], null_count=nulls)
        )
    return pa.Table.from_arrays(arrays, names=list(cols))


def default_out(log_path: Path) -> Path:
    """``runs/estimate-<log name>-<UTC time>``."""
    from datetime import datetime, timezone

    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"estimate-{log_path.stem}-{stamp}"
