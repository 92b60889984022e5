"""How ``amsfe estimate`` (and the Python API, :class:`amsfe_sym.api.Estimator`) reads a log
for a robot and builds the estimator it runs over it: the default settings of ``--robot``,
the log on the robot's tick grid (or at the period of a library generated for it), the
filter settled for the log, the start from its first sample, the estimator of its kind of
effort (docs/how-to/logs.md, docs/explanation/effort.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.apps.estimate_filter import (
    HELD_THETA_STD,
    INPUT_UNKNOWN_ESTIMATOR,
    OOSM_REFUSES,
    ROBOT_TORQUE_STD,
    LogFilter,
    estimator_note,
    filter_for_log,
)
from amsfe_sym.apps.estimate_start import LogLinkStart, scenario_start
from amsfe_sym.apps.phases import Phases
from amsfe_sym.logs.read import LogRateError, RobotLog, plan_log, read_log
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.scenario import Scenario, parse_scenario

if TYPE_CHECKING:  # the spec module is imported when a log's rate needs it, not at start
    from amsfe_sym.load.spec import RobotSpec

__all__ = [
    "LogEstimator",
    "default_scenario",
    "effort_options",
    "estimator_for_log",
    "read_robot_log",
    "robot_of",
]


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


def robot_of(scenario_robot: str) -> tuple[str, list[str], float, int]:
    """(name, joints, T, N) of a robot from its spec, without generating anything."""
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(scenario_robot)
    joints = modelled_joints(spec) or []
    return spec.name, joints, spec.model.T, 4 * len(joints) + len(spec.theta)


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


def read_robot_log(
    log_path: Path,
    spec: LogSpec,
    robot: str,
    topics: Any = None,
    *,
    verbose: bool = False,
    clock: Phases | None = None,
) -> tuple[RobotLog, RobotSpec | None]:
    """Read ``log_path`` for ``robot`` (a shipped name or a ``robot.toml``): the topic plan
    (printed with ``verbose``), then the log on the robot's tick grid.  A log at another
    rate than the robot's T is read at the period of the robot's library generated for it
    when ``amsfe generate ROBOT --period`` has built one (then its spec is returned too;
    else None).  ``topics``: the container's topics when already listed
    (:func:`~amsfe_sym.logs.source.log_topics`).

    Raises:
        LogError: the log cannot be used; LogRateError (a LogError) with the
            ``amsfe generate --period`` that fits it when no such library is cached.
    """
    name, joints, T, N = robot_of(robot)
    plan = plan_log(log_path, spec, joints, topics)
    if verbose:
        for line in plan.lines():
            print(f"  {line}")
    try:
        return read_log(log_path, spec, joints, T, N, plan, robot=name), None
    except LogRateError as exc:  # the robot generated at the log's period, if it is cached
        if clock is not None:
            clock.lap("read")
        derived = _generated_at_period(robot, exc.period)
        if derived is None:
            raise _with_modes_fix(exc, robot) from None
        if verbose:
            print(f"  the log's period {exc.period:g} s: library {derived.name} (cached)")
        if clock is not None:
            clock.lap("library")
        return read_log(log_path, spec, joints, derived.model.T, N, plan, robot=name), derived


@dataclass(frozen=True)
class LogEstimator:
    """The estimator ``amsfe estimate`` runs over a read log (:func:`estimator_for_log`).

    Attributes:
        scenario: The scenario with its filter and start settled for the log.
        lib: The robot's library (at the log's period when it was derived).
        estimator: The estimator at x(0|0), P(0|0).
        feed: The log it is fed (for an effort of kind ``joint_torque`` or ``none`` its
            inputs and encoder rows are derived from the logged effort, docs/explanation/effort.md).
        filter: The filter settled for the log (the measured encoder noise, its lines).
    """

    scenario: Scenario
    lib: Any
    estimator: Any
    feed: RobotLog
    filter: LogFilter


def estimator_for_log(
    sc: Scenario,
    log: RobotLog,
    spec: LogSpec,
    effort: Any,
    *,
    robot_defaults: bool,
    estimator_given: bool,
    derived: RobotSpec | None = None,
    compiled: bool = True,
    verbose: bool = False,
    clock: Phases | None = None,
) -> LogEstimator:
    """The estimator of ``sc`` for ``log`` as ``amsfe estimate`` builds it: the filter
    settled (:func:`~amsfe_sym.apps.estimate_filter.filter_for_log`), the estimator of an
    effort that is not the applied torque (:data:`INPUT_UNKNOWN_ESTIMATOR` with
    ``robot_defaults`` unless ``estimator_given``), the library loaded (generated if need
    be), with ``robot_defaults`` the start from the log's first sample, and the estimator
    built (``compiled``: the library's C one).  ``effort``: the log spec's ``[effort]`` as an
    ``EffortSpec`` (:func:`effort_options`).  The notes a user needs are printed; with
    ``verbose`` also the clock offset, the filter's lines and the start.

    Raises:
        ConfigError, CodegenError: a setting the filter, the library or the builders refuse.
    """
    settled = filter_for_log(
        sc, log, spec, robot_defaults=robot_defaults, hold_theta=derived is not None
    )
    sc = settled.scenario
    if robot_defaults and not estimator_given and log.effort_kind != "applied":
        sc = sc.with_overrides(estimator=INPUT_UNKNOWN_ESTIMATOR)
        print(
            f"  estimator {INPUT_UNKNOWN_ESTIMATOR}: the default for effort kind "
            f"{log.effort_kind!r} ({OOSM_REFUSES}); --estimator to choose"
        )
    elif note := estimator_note(log.effort_kind, sc.estimator):
        print(f"  {note}")
    if verbose:
        c = log.clock
        print(
            f"  clock: log time - header stamp = {c.median:+.6f} s (spread {c.spread:.2e} s); "
            "log times moved onto the stamp clock"
        )
        if spec.camera_time_offset:  # the topic spec's [camera] time_offset, in whole ticks
            shift = spec.exposure_shift(log.T)
            print(
                f"  camera: exposures {spec.camera_time_offset * 1e3:+.3f} ms before the stamps "
                f"([camera] time_offset), taken {shift} tick(s) earlier"
            )
        for line in settled.lines:
            print(f"  {line}")
    from amsfe_sym.codegen import library_for

    if clock is not None:
        clock.lap("setup")
    lib = library_for(sc, robot=derived)
    if clock is not None:
        clock.lap("library")
    effort = replace(effort, positions=spec.positions)
    if robot_defaults:
        # --robot: the defaults, started from the log (theta held at a slower period)
        start = _link_start(sc, log, lib, effort)
        sc = _start_from_log(sc, log, start, hold_theta=derived is not None)
        if verbose:
            print(f"  start: link angles from {start.how}")
    est, feed = _estimator(sc, lib, log, compiled, effort)
    return LogEstimator(sc, lib, est, feed, settled)


def effort_options(spec: Any, path: str | None) -> Any:
    """The :class:`~amsfe_sym.estimation.effort.EffortSpec` of the log spec's ``[effort]``
    noise keys (its kind is the log's, set later); a bad value is one ConfigError line."""
    from amsfe_sym.estimation.effort import effort_spec

    return effort_spec(dict(spec.effort_options), f"{path or 'log spec'} [effort]")


def _estimator(sc: Scenario, lib: Any, log: RobotLog, compiled: bool, effort: Any = None) -> Any:
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
    if log.effort_kind == "applied":
        return build_estimator(sc, lib, sensors, log.z[0], compiled=compiled), log
    spec = replace(effort or EffortSpec(), kind=log.effort_kind)
    built = effort_estimator(sc, lib, sensors, log.z, log.effort, spec, compiled=compiled)
    return built.estimator, replace(log, u=built.inputs.u, z=built.inputs.z_encoder)
