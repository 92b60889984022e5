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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.apps.estimate_filter import (
    HELD_THETA_STD,
    INPUT_UNKNOWN_ESTIMATOR,
    OOSM_REFUSES,
    ROBOT_TORQUE_STD,
    estimator_note,
    filter_for_log,
)
from amsfe_sym.apps.estimate_report import (
    CommandTiming,
    EstimateRun,
    figures,
    nis_report,
    print_summary,
    summary,
)
from amsfe_sym.apps.estimate_start import LogLinkStart, scenario_start
from amsfe_sym.apps.phases import Phases, command_startup_s
from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.toml import dump_toml, tomllib
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.read import LogRateError, RobotLog, plan_log, read_config, read_log
from amsfe_sym.logs.source import log_topics
from amsfe_sym.logs.spec import read_log_spec
from amsfe_sym.scenario import Scenario, load_scenario, parse_scenario

if TYPE_CHECKING:  # the spec module is imported when a log's rate needs it, not at start
    from amsfe_sym.load.spec import RobotSpec

__all__ = [
    "HELD_THETA_STD",
    "INPUT_UNKNOWN_ESTIMATOR",
    "ROBOT_TORQUE_STD",
    "EstimateOptions",
    "EstimateRun",
    "add_arguments",
    "default_out",
    "default_scenario",
    "estimate_command",
    "from_args",
    "nis_report",
    "print_summary",
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


def default_scenario(robot: str) -> Scenario:
    """The settings ``amsfe estimate LOG --robot ROBOT`` runs with: the scenario defaults
    (``[filter]``: process noise 0.1 N m, :data:`ROBOT_TORQUE_STD` once the log is read,
    then the log spec's ``[filter]``: :func:`~amsfe_sym.apps.estimate_filter.filter_for_log`;
    buffer 1000 steps; ``[encoders]`` and
    ``[camera]``: the sensor noise the filter's R is built from; docs/reference/scenarios.md), the
    ``oosm`` estimator (:data:`INPUT_UNKNOWN_ESTIMATOR` once the log shows no applied
    torque), and the estimate's start replaced by the log's first sample
    (:func:`_start_from_log`).  No plant or trajectory is used."""
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(robot)
    n = len(modelled_joints(spec) or ())
    zeros = [0.0] * n
    filt: dict[str, float | int] = {}
    if spec.camera.delay + 1 > 1000:
        filt["buffer_steps"] = 2 * spec.camera.delay + 1
    data = {
        "name": f"estimate-{spec.name}",
        "robot": str(spec.spec_path or spec.urdf) if Path(robot).exists() else robot,
        "estimator": "oosm",
        "trajectory": {"kind": "constant", "q": zeros},
        "plant": {"q0": zeros, "qd0": zeros},
        "estimate0": {"q": zeros, "qd": zeros, "motor": "encoders"},
        "filter": filt,
    }
    return parse_scenario(data, Path(f"--robot {robot}"))


def _link_start(sc: Scenario, log: RobotLog, lib: Any, effort: Any) -> LogLinkStart:
    """The link angles of the log's first sample by its effort kind, a balance missing
    :data:`ROBOT_TORQUE_STD` of torque (:func:`~amsfe_sym.apps.estimate_start.scenario_start`;
    docs/explanation/effort.md, "Where the estimate starts")."""
    return scenario_start(sc, log, lib, effort, ROBOT_TORQUE_STD)


def _start_from_log(
    sc: Scenario, log: RobotLog, start: LogLinkStart, hold_theta: bool = False
) -> Scenario:
    """``[estimate0]`` from the log's first encoder sample: link angles ``start`` (by the
    effort's kind, :func:`_link_start`; its 1-sigma when it has one), link rates = the
    measured velocities (motor states: the sample itself).  The filter's R and Q:
    :func:`~amsfe_sym.apps.estimate_filter.filter_for_log`.

    ``hold_theta`` (a log read at a period longer than the robot's T, its library built with
    model substeps): theta is held at the spec's initial value (1-sigma
    :data:`HELD_THETA_STD`; ``[filter] theta_rate_std = 0`` there).  At such a period the joint
    modes turn by many radians a step (w T = 26 for the Panda at 1/30 s) and the model has
    no spring damping: the one-step sensitivity of the link angles to theta (eqs. 1a, 4)
    follows the aliased phase of an undamped oscillation, not the static deflection the
    data show, and on the real Panda log the payload ran from 0 to 21 kg in 90 steps before
    every estimator diverged (docs/how-to/logs.md, "A real Panda recording, worked")."""
    n = log.u.shape[1]
    z0 = log.z[0]
    e0 = replace(sc.estimate0, q=tuple(map(float, start.q)), qd=tuple(map(float, z0[n:])))
    if start.std is not None:
        e0 = replace(e0, std={**dict(e0.std), "q": start.std})
    if hold_theta:
        e0 = replace(e0, std={**dict(e0.std), "theta": HELD_THETA_STD})
    return replace(sc, estimate0=e0)


def _robot_of(scenario_robot: str) -> tuple[str, list[str], float, int]:
    """(name, joints, T, N) of a robot from its spec, without generating anything."""
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(scenario_robot)
    joints = modelled_joints(spec) or []
    return spec.name, joints, spec.model.T, 4 * len(joints) + len(spec.theta)


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
        mine, theirs = _robot_of(sc.robot), _robot_of(from_config.robot)
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


def _generated_at_period(robot: str, period: float) -> RobotSpec | None:
    """The spec of ``robot`` at ``period`` [s] when ``amsfe generate ROBOT --period`` has
    already built its library (:func:`~amsfe_sym.codegen.modes.spec_at_period`, found in the
    cache without building anything), else None: then the rate refusal stands."""
    from amsfe_sym.codegen.build import cached_library
    from amsfe_sym.codegen.modes import spec_at_period

    spec = spec_at_period(robot, period)
    return spec if cached_library(spec) is not None else None


def _with_modes_fix(exc: LogRateError, robot: str) -> LogRateError:
    """The rate refusal with :func:`~amsfe_sym.codegen.modes.period_fix`'s command (with the
    substeps the joint modes need)."""
    from amsfe_sym.codegen.modes import period_fix

    head = str(exc).split(". Fix: ")[0]
    fix = period_fix(robot, exc.period)
    return LogRateError(f"{head}. Fix: {fix}, or record at the robot's rate", exc.period)


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
    effort = _effort_options(spec, options.log_spec)  # checked before anything is read
    clock.lap("setup")
    topics = log_topics(log_path)
    config = read_config(log_path, spec, topics)
    clock.lap("read")
    sc = _scenario(log_path, config, options)
    name, joints, T, N = _robot_of(sc.robot)
    clock.lap("setup")
    plan = plan_log(log_path, spec, joints, topics)
    if options.verbose:
        for line in plan.lines():
            print(f"  {line}")
    derived = None
    try:
        log = read_log(log_path, spec, joints, T, N, plan, robot=name)
    except LogRateError as exc:  # the robot generated at the log's period, if it is cached
        clock.lap("read")
        derived = _generated_at_period(sc.robot, exc.period)
        if derived is None:
            raise _with_modes_fix(exc, sc.robot) from None
        if options.verbose:
            print(f"  the log's period {exc.period:g} s: library {derived.name} (cached)")
        clock.lap("library")
        log = read_log(log_path, spec, joints, derived.model.T, N, plan, robot=name)
    log.config = config
    clock.lap("read")
    robot_defaults = options.scenario is None and (options.robot is not None or config is None)
    settled = filter_for_log(
        sc, log, spec, robot_defaults=robot_defaults, hold_theta=derived is not None
    )
    sc = settled.scenario
    if robot_defaults and options.estimator is None and log.effort_kind != "applied":
        sc = sc.with_overrides(estimator=INPUT_UNKNOWN_ESTIMATOR)
        print(
            f"  estimator {INPUT_UNKNOWN_ESTIMATOR}: the default for effort kind "
            f"{log.effort_kind!r} ({OOSM_REFUSES}); --estimator to choose"
        )
    elif note := estimator_note(log.effort_kind, sc.estimator):
        print(f"  {note}")
    if options.verbose:
        c = log.clock
        print(
            f"  clock: log time - header stamp = {c.median:+.6f} s (spread {c.spread:.2e} s); "
            "log times moved onto the stamp clock"
        )
        for line in settled.lines:
            print(f"  {line}")
    from amsfe_sym.codegen import library_for

    clock.lap("setup")
    lib = library_for(sc, robot=derived)
    clock.lap("library")
    effort = replace(effort, positions=spec.positions)
    if robot_defaults:
        # --robot: the defaults, started from the log (theta held at a slower period)
        start = _link_start(sc, log, lib, effort)
        sc = _start_from_log(sc, log, start, hold_theta=derived is not None)
        if options.verbose:
            print(f"  start: link angles from {start.how}")
    est, feed = _estimator(sc, lib, log, options, effort)
    from amsfe_sym.logs.replay import estimate_log

    clock.lap("setup")
    result = estimate_log(feed, est, states=lib.N)
    clock.lap("estimate")
    run = EstimateRun(
        log, result, sc, out, clock.spent["read"], clock.spent["estimate"], noise=settled.noise
    )
    _write(run, lib.manifest.joints, options, clock, startup_s)
    return run


def _effort_options(spec: Any, path: str | None) -> Any:
    """The :class:`~amsfe_sym.estimation.effort.EffortSpec` of the log spec's ``[effort]``
    noise keys (its kind is the log's, set later); a bad value is one ConfigError line."""
    from amsfe_sym.estimation.effort import effort_spec

    return effort_spec(dict(spec.effort_options), f"{path or 'log spec'} [effort]")


def _estimator(
    sc: Scenario, lib: Any, log: RobotLog, options: EstimateOptions, effort: Any = None
) -> Any:
    """The estimator and the log it is fed: for an effort of kind ``joint_torque`` or
    ``none``, :func:`~amsfe_sym.sim.effort.effort_estimator`'s (the input and encoder
    measurements derived from the log, docs/explanation/effort.md), the library's C estimator with
    ``--runtime compiled`` (the default; oosm's inverse backward map with the input as states
    is refused there in one line: docs/explanation/effort.md, "Compiled").  ``effort``:
    the log spec's ``[effort]`` noise keys and ``[joints] positions`` as an ``EffortSpec``
    (None: the defaults); its kind is replaced by the log's."""
    from amsfe_sym.estimation.effort import EffortSpec
    from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing
    from amsfe_sym.sim.effort import effort_estimator

    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    compiled = options.runtime == "compiled"
    if log.effort_kind == "applied":
        return build_estimator(sc, lib, sensors, log.z[0], compiled=compiled), log
    spec = replace(effort or EffortSpec(), kind=log.effort_kind)
    built = effort_estimator(sc, lib, sensors, log.z, log.effort, spec, compiled=compiled)
    return built.estimator, replace(log, u=built.inputs.u, z=built.inputs.z_encoder)


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
    print_summary(summary(estimate_command(log, out, opts, startup_s)), out)
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
            figures(run, tmp)
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
