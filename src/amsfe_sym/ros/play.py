"""``amsfe play LOG``: a recorded log's sensor topics on ROS 2 at their recorded pace (or
``rate`` times it), with ``/clock``, so a recorded session replays into ``amsfe node`` (the
ROS tool for this, ``ros2 bag play``, is not installable from the package index).

The topics are the input roles of the topic spec (encoders, effort, camera, truth) that the
log holds; each message goes out as the bytes it was recorded as (CDR).  Messages of one log
time are published together, the encoder sample last, so that a node has the frames that
arrived at a tick and the torque of the tick before when its sample arrives.  DDS does not
order deliveries across topics, so with ``ordered`` a group's camera and effort messages
are acknowledged by every reader (reliable QoS) before its encoder sample goes out, the
writers heartbeating every 1 ms (:func:`~amsfe_sym.ros.middleware.use_lockstep_profile`):
a node then has them when the sample arrives, at the cost of the recorded pace
(docs/how-to/ros.md).
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
    qos_profile,
    spec_parameters,
    start,
    stop,
    use_lockstep_profile,
)
from amsfe_sym.topics import TopicSpec

__all__ = ["PLAYED_ROLES", "PlayOptions", "PlayReport", "play_log"]

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


def _groups(path: Path, topics: dict[str, str]) -> Iterator[tuple[int, list[tuple[str, bytes]]]]:
    """(log time [ns], [(topic, raw CDR)]) per log time, encoder samples last in each."""
    from rosbags.highlevel import AnyReader

    from amsfe_sym.logs.source import typestore

    order = {t: i for i, t in enumerate(topics)}
    with AnyReader([path], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        group: list[tuple[str, bytes]] = []
        now: int | None = None
        for conn, t, raw in reader.messages(connections=conns):
            if now is not None and t != now:
                yield now, sorted(group, key=lambda g: order[g[0]])
                group = []
            now = t
            group.append((conn.topic, bytes(raw)))
        if now is not None:
            yield now, sorted(group, key=lambda g: order[g[0]])


def _topics(path: Path, spec: TopicSpec) -> dict[str, str]:
    """topic -> message type of the played roles the log holds, in :data:`PLAYED_ROLES`
    order (the encoders last)."""
    from rosbags.highlevel import AnyReader

    from amsfe_sym.logs.source import typestore

    try:
        with AnyReader([path], default_typestore=typestore()) as reader:
            have = {c.topic: c.msgtype for c in reader.connections}
    except Exception as exc:  # rosbags raises its own kinds for unreadable bags
        raise LogError(
            describe(f"log {path}", "a rosbag2 folder or .mcap file", str(exc), "check the path")
        ) from exc
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
    return out


def play_log(path: Path, options: PlayOptions) -> PlayReport:
    """Publish the log at ``path`` (see the module docstring).

    Raises:
        LogError: an unreadable log, no encoder topic.
        RosError: no subscriber within ``start_timeout``; rclpy missing.
    """
    if not options.rate > 0:
        raise RosError(describe("play --rate", "a factor > 0", repr(options.rate), "e.g. 1"))
    if options.ordered:
        use_lockstep_profile()
    ctx = start(list(options.ros_args), options.domain_id)
    import rclpy
    from rclpy.duration import Duration

    node = rclpy.create_node("amsfe_play", context=ctx)
    try:
        spec = spec_parameters(node, options.spec, ())
        topics = _topics(path, spec)
        qos = qos_profile(spec)
        pubs = {t: node.create_publisher(_message_class(m), t, qos) for t, m in topics.items()}
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
