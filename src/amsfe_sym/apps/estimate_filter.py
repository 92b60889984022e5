"""The filter ``amsfe estimate`` runs a log with (docs/how-to/logs.md, "The filter's R and Q on a
log"): ``--robot``'s defaults, then a scenario's ``[filter]``, then the log spec's
``[filter]`` (key by key, the log spec wins); the encoder noise measured from the log
(:mod:`amsfe_sym.logs.noise`) printed, and used where the log spec says ``"log"``."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from amsfe_sym.logs.noise import EncoderNoise, encoder_noise
from amsfe_sym.logs.read import RobotLog
from amsfe_sym.scenario import Scenario, with_filter
from amsfe_sym.topics.spec import FROM_LOG, TopicSpec

__all__ = [
    "HELD_THETA_STD",
    "INPUT_UNKNOWN_ESTIMATOR",
    "OOSM_REFUSES",
    "ROBOT_TORQUE_STD",
    "LogFilter",
    "current_r",
    "estimator_note",
    "filter_for_log",
]

#: The estimator of ``--robot`` for a log whose applied torque is not logged (effort kind
#: ``joint_torque`` or ``none``): with the input as states oosm's A1 update finds its
#: retrodicted covariance indefinite and refuses every camera frame; replay's exact
#: re-filtering fuses them (docs/explanation/effort.md sections 2-3).
INPUT_UNKNOWN_ESTIMATOR = "replay"
#: Why oosm fuses no frame with the input estimated, as both printed lines give it.
OOSM_REFUSES = (
    "oosm's single-lag update refuses camera frames when the input is estimated; "
    "docs/explanation/effort.md section 2"
)


def estimator_note(effort_kind: str, estimator: str) -> str | None:
    """One line for a user whose estimator will fuse no camera frame because the effort is
    not the applied torque (``oosm`` with kind ``joint_torque`` or ``none``), else None.
    The log path (``amsfe estimate`` with a scenario) and the live node print the same."""
    if estimator != "oosm" or effort_kind not in ("joint_torque", "none"):
        return None
    return (
        f"estimator oosm with effort kind {effort_kind!r} fuses no camera frame "
        f"({OOSM_REFUSES}); --estimator {INPUT_UNKNOWN_ESTIMATOR} fuses them"
    )


#: ``[filter] link_torque_std`` and ``motor_torque_std`` [N m] of ``estimate --robot`` on a
#: log without the applied torque or slower than T (:func:`filter_for_log`): the
#: torque a real arm's model misses (a URDF's end effector, torque sensor offsets); the
#: scenario default 0.1 N m is for amsfe's own exact simulations.  The real Panda log of
#: docs/how-to/logs.md ("A real Panda recording, worked") misses up to 4.2 N m of gravity torque;
#: with 0.1 N m every estimator diverges on it.
ROBOT_TORQUE_STD = 5.0

#: 1-sigma [unit] of theta(0|0) when ``estimate --robot`` holds theta at the spec's
#: initial value (a log slower than the robot's T).
HELD_THETA_STD = 1e-6

#: The R keys measured from the log, and the attribute of :class:`EncoderNoise` each takes.
_NOISE_KEYS = {"encoder_q_std": "q_std", "encoder_qd_std": "qd_std"}


@dataclass(frozen=True)
class LogFilter:
    """The filter settled for a log.

    Attributes:
        scenario: The scenario with its ``[filter]`` settled.
        noise: The encoder noise measured from the log (None: not measured).
        lines: What ``amsfe estimate`` prints about it (the measured noise; the log spec's
            keys and what each replaced).
    """

    scenario: Scenario
    noise: EncoderNoise | None
    lines: tuple[str, ...]


def current_r(sc: Scenario) -> tuple[float, float]:
    """The encoder R the filter uses [rad, rad/s]: ``[filter] encoder_q_std`` and
    ``encoder_qd_std``, 0 meaning the ``[encoders]`` sensor's (quantization not counted)."""
    f = sc.filter
    return (f.encoder_q_std or sc.encoders.q_std, f.encoder_qd_std or sc.encoders.qd_std)


def filter_for_log(
    sc: Scenario,
    log: RobotLog,
    spec: TopicSpec,
    *,
    robot_defaults: bool,
    hold_theta: bool = False,
) -> LogFilter:
    """``sc`` with the ``[filter]`` of a log settled, in this order (each over the last):

    1. ``robot_defaults`` (``amsfe estimate LOG --robot ROBOT``, no scenario): the process
       torque (``link_torque_std``, ``motor_torque_std``) is :data:`ROBOT_TORQUE_STD` when
       the applied torque is not logged (effort kind ``joint_torque`` or ``none``) or with
       ``hold_theta``; with the applied torque at the robot's T it stays 0.1 N m (at 5 N m
       oosm's A1 update refuses every frame of a paper_2link driver log as indefinite).
       ``hold_theta`` (a log read at a period longer than the robot's T, its library built
       with model substeps): theta is held (``theta_rate_std = 0``; its 1-sigma
       :data:`HELD_THETA_STD` is the start's, docs/how-to/logs.md).  The encoder noise is
       measured from the log (:func:`~amsfe_sym.logs.noise.encoder_noise`, the median over
       joints) and printed as a suggestion, not used: as the default R it made the filter
       optimistic, or its covariance indefinite, on simulated logs whose default Q is too
       small (docs/how-to/logs.md, "The encoder noise from the log").
    2. the scenario's ``[filter]`` (``sc`` as given, with ``--scenario``);
    3. the log spec's ``[filter]`` (``spec.filter_options``); ``encoder_q_std = "log"``
       (``encoder_qd_std``) is the measured noise.

    The result passes the scenario's own checks
    (:func:`~amsfe_sym.scenario.read.validate`).  The noise is measured with step 1 or a
    ``"log"``, and printed, used or not.

    Raises:
        ConfigError: a value the scenario's checks refuse (a process torque of 0).
    """
    f = sc.filter
    if robot_defaults and (hold_theta or log.effort_kind != "applied"):
        f = replace(f, link_torque_std=ROBOT_TORQUE_STD, motor_torque_std=ROBOT_TORQUE_STD)
    if robot_defaults and hold_theta:
        f = replace(f, theta_rate_std=0.0)
    opts = dict(spec.filter_options)
    wanted = [k for k in _NOISE_KEYS if opts.get(k) == FROM_LOG]
    lines: list[str] = []
    noise = None
    if wanted or robot_defaults:
        noise = encoder_noise(log.z, log.u.shape[1])
        changes: dict[str, Any] = {}
        for k in wanted:
            value = getattr(noise, _NOISE_KEYS[k])
            if value is not None:
                changes[k] = value
        q, qd = current_r(replace(sc, filter=f))
        if changes:
            how = f'used for {", ".join(changes)} ("{FROM_LOG}" in the log spec)'
        elif wanted:
            how = f"every channel constant: the filter's R stays {q:.1e} rad, {qd:.1e} rad/s"
        else:
            how = (
                f"the filter's R is {q:.1e} rad, {qd:.1e} rad/s: to use it set [filter] "
                f'encoder_q_std = "{FROM_LOG}", encoder_qd_std = "{FROM_LOG}" (or numbers) '
                "in the log spec"
            )
        f = replace(f, **changes)
        lines.append(f"encoder noise from the log: {noise.line()}; {how}")
    given = {k: v for k, v in opts.items() if v != FROM_LOG}
    if given:
        was = ", ".join(f"{k} {v:g} (was {getattr(f, k):g})" for k, v in given.items() if _num(v))
        rest = ", ".join(f"{k} {v}" for k, v in given.items() if not _num(v))
        where = spec.source or "the log spec"
        lines.append(f"[filter] of {where}: " + ", ".join(p for p in (was, rest) if p))
    source = f"{spec.source or 'log spec'} [filter] over the filter's defaults"
    out = with_filter(replace(sc, filter=f), given, source)
    return LogFilter(out, noise, tuple(lines))


def _num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)
