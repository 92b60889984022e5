"""``amsfe play LOG``: a recorded log's sensor topics on ROS 2 at their recorded pace (or
``rate`` times it), with ``/clock``, so a recorded session replays into ``amsfe node`` (the
ROS tool for this, ``ros2 bag play``, is not installable from the package index).

The topics are the input roles of the topic spec (encoders, effort, camera, truth) that the
log holds; a log is read by the log reader's own code (:mod:`amsfe_sym.logs.source`: a ROS 1
``.bag``, a rosbag2 folder in MCAP or sqlite3, a plain ``.mcap``), and each message goes out
as CDR: as recorded when it is CDR, converted when it is ROS 1 (a ROS 1 bag's bytes were
published as they were, and the node's Fast CDR could not read them).  Each
publisher's history holds :data:`~amsfe_sym.ros.middleware.QUEUE_SECONDS` of its topic at
the log's rate (:func:`~amsfe_sym.ros.middleware.depth_for`), so a reader that falls behind
on a loaded machine catches up instead of losing samples.  Messages of one log
time are published together, the encoder sample last, so that a node has the frames that
arrived at a tick and the torque of the tick before when its sample arrives.  DDS does not
order deliveries across topics, so with ``ordered`` a group's camera and effort messages
are acknowledged by every reader (reliable QoS) before its encoder sample goes out: a node
then has them when the sample arrives, at the cost of the recorded pace
(docs/how-to/ros.md).  The writers heartbeat every 1 ms in both modes
(:func:`~amsfe_sym.ros.middleware.use_lockstep_profile`): a sample a reader dropped (its side
of the match not made yet when the first samples went out, or a full buffer on a loaded
machine) is sent again within milliseconds; at Fast DDS's default 3 s heartbeat the
reliable stream of that topic waited seconds for it, and a node without ``--ordered``
estimated those ticks with a held torque (a false ``innovation`` hold).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from amsfe_sym.errors import LogError, RosError, describe
from amsfe_sym.ros.middleware import (
    check_parameters,
    depth_for,
    qos_profile,
    spec_parameters,
    start,
    stop,
    use_lockstep_profile,
)
from amsfe_sym.topics import TopicSpec

__all__ = [
    "PLAYED_ROLES",
    "RATE_MAX",
    "RATE_MIN",
    "PlayOptions",
    "PlayReport",
    "play_log",
    "ros1_to_cdr",
]

#: The speed factors ``play --rate`` takes (docs/input-rules.md): a thousandth of the recorded
#: pace (1e-9 played a 2 s log over 63 years) to a thousand times it.
RATE_MIN = 1e-3
RATE_MAX = 1e3

#: The roles ``play`` publishes (the sensors, and the truth of a simulated run).
PLAYED_ROLES = ("camera", "effort", "truth", "encoders")


@dataclass(frozen=True)
class PlayOptions:
    """How ``amsfe play`` runs.

    Attributes:
        rate: Speed factor of the recorded pace (2: twice as fast).
        spec: The topic spec: which recorded topics play which role.
        start_timeout: Longest wait for a subscriber of the encoders [s, wall].
        ros_args: ``--ros-args`` for rclpy.
        domain_id: ROS_DOMAIN_ID (None: the environment's).
        ordered: Wait for every reader's acknowledgement of a log time's messages before
            its encoder sample (module docstring).
        ack_timeout: ``ordered``: longest wait for one acknowledgement [s, wall].
    """

    rate: float = 1.0
    spec: TopicSpec = field(default_factory=TopicSpec)
    start_timeout: float = 30.0
    ros_args: tuple[str, ...] = ()
    domain_id: int | None = None
    ordered: bool = False
    ack_timeout: float = 10.0


@dataclass(frozen=True)
class PlayReport:
    """What was played: messages by topic, the log's span [s] and the wall time [s]."""

    messages: dict[str, int]
    log_s: float
    wall_s: float


def _message_class(msgtype: str) -> Any:
    pkg, _, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError) as exc:
        raise RosError(
            describe(
                f"message type {msgtype}",
                "a type of the installed ROS 2 message packages",
                "none",
                'pip install -e ".[ros]"',
            )
        ) from exc


def ros1_to_cdr(raw: bytes, msgtype: str, where: str = "") -> bytes:
    """A ROS 1 payload as the CDR of its ROS 2 type: decoded with ROS 1 (Noetic)
    definitions, built again field by field as the ROS 2 (Humble) type (what ROS 1 has and
    ROS 2 lacks, ``std_msgs/Header``'s ``seq``, is dropped) and serialized.

    Raises:
        LogError: the bytes do not decode as ``msgtype``.
    """
    from amsfe_sym.logs.decode import deserialize, typestore

    store = typestore("cdr")
    msg = _as_ros2(deserialize(raw, msgtype, "ros1", where), store)
    return bytes(store.serialize_cdr(msg, msgtype))


def _as_ros2(obj: Any, store: Any) -> Any:
    """A ROS 1 message object rebuilt with ``store``'s (ROS 2) types, recursively."""
    name = getattr(obj, "__msgtype__", None)
    if name is not None:
        cls = store.types[name]
        return cls(**{f: _as_ros2(getattr(obj, f), store) for f in cls.__dataclass_fields__
                      if f != "__msgtype__"})  # fmt: skip
    if isinstance(obj, list):
        return [_as_ros2(x, store) for x in obj]
    return obj


def _groups(path: Path, topics: dict[str, str]) -> Iterator[tuple[int, list[tuple[str, bytes]]]]:
    """(log time [ns], [(topic, CDR)]) per log time, encoder samples last in each."""
    from amsfe_sym.logs.source import iter_messages

    order = {t: i for i, t in enumerate(topics)}
    group: list[tuple[str, bytes]] = []
    now: int | None = None
    for m in iter_messages(path, set(topics)):
        if now is not None and m.log_time_ns != now:
            yield now, sorted(group, key=lambda g: order[g[0]])
            group = []
        now = m.log_time_ns
        where = f"log {path}: {m.topic} at {m.log_time_ns} ns"
        raw = ros1_to_cdr(m.raw, m.msgtype, where) if m.encoding == "ros1" else m.raw
        group.append((m.topic, raw))
    if now is not None:
        yield now, sorted(group, key=lambda g: order[g[0]])


def _topics(path: Path, spec: TopicSpec) -> tuple[dict[str, str], dict[str, float]]:
    """topic -> message type of the played roles the log holds, in :data:`PLAYED_ROLES`
    order (the encoders last), and each one's mean rate [Hz] over the log (from the
    container's counts and the encoders' span; 0 where the container has no count).

    Raises:
        LogError: not a log the reader reads, or no encoder topic.
    """
    from amsfe_sym.logs.source import log_topics

    infos = log_topics(path)
    have = {t: i.msgtype for t, i in infos.items()}
    out: dict[str, str] = {}
    for role in PLAYED_ROLES:
        topic = spec.topic(role)
        if topic in have:
            out.pop(topic, None)  # a topic of several roles goes out once, at its last role
            out[topic] = have[topic]
    if spec.encoders not in out:
        raise LogError(
            describe(
                f"log {path}",
                f"the encoders on {spec.encoders}",
                f"topics {sorted(have)}",
                "name the log's encoder topic in a topic spec ([topics] encoders)",
            )
        )
    for topic in out:
        infos[topic].payload_encoding(path)  # a JSON-encoded MCAP: refused in one line
    span = _span_s(path, spec.encoders)
    rates = {t: (infos[t].count or 0) / span if span > 0 else 0.0 for t in out}
    return out, rates


def _span_s(path: Path, topic: str) -> float:
    """The log-time span of ``topic`` [s] (first to last message)."""
    from amsfe_sym.logs.source import iter_messages

    first = last = None
    for m in iter_messages(path, {topic}):
        if first is None:
            first = m.log_time_ns
        last = m.log_time_ns
    return 0.0 if first is None or last is None else (last - first) * 1e-9


def play_log(path: Path, options: PlayOptions) -> PlayReport:
    """Publish the log at ``path`` (see the module docstring).

    Raises:
        LogError: an unreadable log, no encoder topic.
        RosError: no subscriber within ``start_timeout``; rclpy missing.
    """
    if not RATE_MIN <= options.rate <= RATE_MAX:
        raise RosError(
            describe(
                "play --rate",
                f"a speed factor in [{RATE_MIN:g}, {RATE_MAX:g}]",
                repr(options.rate),
                "e.g. --rate 1 (the recorded pace)",
            )
        )
    use_lockstep_profile()  # a lost sample repaired in ~1 ms, not after a 3 s heartbeat
    ctx = start(list(options.ros_args), options.domain_id)
    import rclpy
    from rclpy.duration import Duration

    node = rclpy.create_node("amsfe_play", context=ctx)
    try:
        spec = spec_parameters(node, options.spec, ())
        check_parameters(node)  # a mistyped -p name: refused, not ignored
        topics, rates = _topics(path, spec)
        pubs = {
            t: node.create_publisher(
                _message_class(m), t, qos_profile(spec, depth=depth_for(rates[t], spec))
            )
            for t, m in topics.items()
        }
        from amsfe_sym.ros import messages as msgs

        clock = node.create_publisher(msgs.Clock, spec.clock, qos_profile(spec, depth=1))
        deadline = time.monotonic() + options.start_timeout
        while pubs[spec.encoders].get_subscription_count() < 1:
            if time.monotonic() > deadline:
                raise RosError(
                    describe(
                        "amsfe play",
                        f"a subscriber of {spec.encoders}",
                        f"none within {options.start_timeout:g} s",
                        "start `amsfe node SCENARIO` on the same ROS_DOMAIN_ID first",
                    )
                )
            time.sleep(0.02)
        # the node's other subscriptions: every one discovery knows of matched (a frame
        # published to a reader not yet matched is lost: volatile), and for 1 s at least any
        # the graph does not show yet, as long as a topic has no subscriber at all
        grace = time.monotonic() + 1.0
        while time.monotonic() < deadline and any(
            p.get_subscription_count() < max(node.count_subscribers(p.topic_name), 1)
            and (time.monotonic() < grace or node.count_subscribers(p.topic_name) > 0)
            for p in pubs.values()
        ):
            time.sleep(0.02)
        counts = dict.fromkeys(topics, 0)
        feeds = {spec.camera, spec.effort} - {spec.encoders}  # what the estimator reads
        t0_log: int | None = None
        t_log = 0
        t0 = time.perf_counter()
        for t_log, group in _groups(path, topics):
            if t0_log is None:
                t0_log = t_log
            wait = t0 + (t_log - t0_log) * 1e-9 / options.rate - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            clock.publish(msgs.clock(t_log))
            for topic, raw in group:
                if options.ordered and topic == spec.encoders:
                    _acked(pubs, group, feeds, options.ack_timeout)
                pubs[topic].publish(raw)
                counts[topic] += 1
        wall = time.perf_counter() - t0
        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=2))
        return PlayReport(counts, (t_log - (t0_log or 0)) * 1e-9, wall)
    finally:
        stop(ctx, node)


def _acked(
    pubs: dict[str, Any], group: list[tuple[str, bytes]], feeds: set[str], timeout: float
) -> None:
    """Wait (up to ``timeout`` [s] each) until every reader acknowledged the messages of
    ``group`` on the topics ``feeds`` (the camera and the effort: the truth is not waited for,
    it feeds no estimate)."""
    from rclpy.duration import Duration

    for topic in dict.fromkeys(t for t, _ in group if t in feeds):
        if not pubs[topic].wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9))):
            raise RosError(
                describe(
                    f"amsfe play --ordered: {topic}",
                    f"every reader's acknowledgement within {timeout:g} s",
                    "none",
                    "check the node is running (or play without --ordered)",
                )
            )
