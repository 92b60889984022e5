"""Which topic plays which role in a log, decided from its metadata and the first message
of a few topics, before anything is read in full or compiled (docs/how-to/logs.md, "Which topic
plays which role").

A role the topic spec names is taken as named (its type checked); otherwise its default topic
if the log has it; otherwise, for the encoders, the JointState topic whose names include every
joint of the robot (a driver's ``/joint_states``), and for the effort that same topic when it
carries effort values, or an effort-only JointState.  One topic may play several roles.  The
effort's kind is the spec's, else by shape: effort on a topic that also carries positions is
``none``, a separate effort topic is ``applied``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.arrays import IntArray
from amsfe_sym.errors import AmsfeError, LogError, describe
from amsfe_sym.logs.decode import JointStates, decode_joint_states, decode_strings
from amsfe_sym.logs.firsts import first_payloads
from amsfe_sym.logs.source import TopicInfo, log_topics
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.topics.roles import ROLES, EffortKind, joint_order

__all__ = [
    "JOINT_STATE",
    "LOG_ROLES",
    "LogPlan",
    "check_type",
    "joint_columns",
    "plan_log",
    "read_config",
    "refuse",
]


JOINT_STATE = "sensor_msgs/msg/JointState"
#: The input roles a log is read for (``config`` is read by :func:`read_config`).
LOG_ROLES = ("encoders", "effort", "camera", "truth")


@dataclass(frozen=True)
class LogPlan:
    """Which topic plays which role in a log, decided from its metadata and first messages.

    Attributes:
        path: The log.
        topics: Every topic of the log.
        roles: Role -> topic (``encoders`` always; ``effort``, ``camera``, ``truth`` where
            the log has them).  One topic may appear under several roles.
        how: Role -> how its topic was chosen: ``named`` (the topic spec), ``default`` (the
            role's default topic) or ``found`` (by message type and joint names).
        effort_kind: What the effort is (``none`` when there is no effort topic).
        kind_how: ``named`` (the spec said) or the shape rule that chose it.
        names: The log's JointState names of the robot's joints, in q order.
        unused: Role without a topic -> the log's topics of that role's types that play no
            role (a stream that is there but not used is said, never silent).
        camera_info: The CameraInfo topic when the camera topic is an image topic (its
            marker is detected: :mod:`amsfe_sym.vision`), else None.
    """

    path: Path
    topics: dict[str, TopicInfo]
    roles: dict[str, str]
    how: dict[str, str]
    effort_kind: EffortKind
    kind_how: str
    names: tuple[str, ...]
    unused: dict[str, list[str]] = field(default_factory=dict)
    camera_info: str | None = None

    @property
    def topics_read(self) -> set[str]:
        """Every topic the reader reads: the roles' and the camera's CameraInfo."""
        return set(self.roles.values()) | ({self.camera_info} if self.camera_info else set())

    def lines(self) -> list[str]:
        """One line per role saying which topic plays it and why (printed by estimate)."""
        out = []
        for role in LOG_ROLES:
            topic = self.roles.get(role)
            if topic is None:
                other = self.unused.get(role)
                out.append(
                    f"{role}: none"
                    + (f" (not used: {other}; name one in [topics] {role})" if other else "")
                )
                continue
            info = self.topics[topic]
            line = f"{role}: {topic} ({info.msgtype}, {self.how[role]})"
            if role == "effort":
                line += f", kind {self.effort_kind} ({self.kind_how})"
            if role == "camera" and self.camera_info is not None:
                line += f", images: the marker detected, CameraInfo {self.camera_info}"
            out.append(line)
        return out


def refuse(where: str, expected: str, found: str, fix: str) -> LogError:
    """A :class:`LogError` of one line: where, expected, found, fix."""
    return LogError(describe(where, expected, found, fix))


def check_type(path: Path, role: str, info: TopicInfo) -> None:
    """Refuse ``info``'s topic for ``role`` unless its type is one the role takes and its
    payloads are CDR or ROS 1 (a JSON-encoded channel is named)."""
    types = ROLES[role].types
    if info.msgtype not in types:
        raise refuse(
            f"log {path}: topic {info.topic} ({role})",
            f"messages of type {' or '.join(types)}",
            info.msgtype or "no type (a channel without a schema)",
            f"name the log's {role} topic in a topic spec's [topics] {role} (--log-spec; "
            "docs/reference/topics.md)",
        )
    info.payload_encoding(path)  # a JSON-encoded channel: refused here, by name


def read_config(
    path: Path, spec: LogSpec | None = None, topics: dict[str, TopicInfo] | None = None
) -> dict[str, Any] | None:
    """amsfe's run config stored in a log by ``amsfe simulate --bag``, or None.

    Raises:
        LogError: the config topic exists with another type than ``std_msgs/msg/String``
            (named, not "found none"), or its text is not a JSON object.
    """
    spec = spec or LogSpec()
    topics = topics if topics is not None else log_topics(path)
    info = topics.get(spec.config)
    if info is None:
        if "config" in spec.explicit:
            raise refuse(
                f"log {path}",
                f"the config topic {spec.config} named in the topic spec",
                f"no such topic (the log has {sorted(topics)})",
                "fix [topics] config, or drop it",
            )
        return None
    check_type(path, "config", info)
    data = first_payloads(path, {spec.config}, topics)[spec.config]
    if not data.raws:
        return None
    text = decode_strings(data.raws[:1], info.payload_encoding(path), f"log {path}").data[0]
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise refuse(
            f"log {path}: {spec.config}",
            "a JSON document (amsfe's run config)",
            f"{exc}",
            "point [topics] config at amsfe's config topic, or at a topic the log lacks",
        ) from exc
    if not isinstance(doc, dict):
        raise refuse(f"log {path}: {spec.config}", "a JSON object", type(doc).__name__, "as above")
    return doc


def _first_states(path: Path, topics: dict[str, TopicInfo], which: set[str]) -> dict[str, Any]:
    """The first JointState of each topic in ``which``, as :class:`JointStates` (one row)."""
    firsts = first_payloads(path, which, topics)
    out: dict[str, Any] = {}
    for t, d in firsts.items():
        if d.raws:
            out[t] = decode_joint_states(
                d.raws[:1], topics[t].payload_encoding(path), f"log {path}: {t}"
            )
    return out


def _has(js: JointStates, names: Sequence[str], field_: int) -> bool:
    """Whether the first message names every joint and carries ``field_``'s values
    (0 position, 1 velocity, 2 effort) for each of its names."""
    have = js.names[int(js.names_index[0])]
    return all(n in have for n in names) and int(js.counts[0, field_]) == len(have) > 0


def plan_log(
    path: Path,
    spec: LogSpec,
    joints: Sequence[str],
    topics: dict[str, TopicInfo] | None = None,
) -> LogPlan:
    """Which topic plays which role in the log at ``path`` for a robot with ``joints`` (q
    order), from the container's metadata (``topics``, as :func:`log_topics` gives it, or
    read here) and each candidate topic's first message.

    Raises:
        LogError: unreadable; a named topic missing or of the wrong type; a default topic of
            the wrong type; no encoder topic, or several that could be it; the robot's
            joints missing from the encoder topic (named).
    """
    topics = topics if topics is not None else log_topics(path)
    if topics and not any(i.encoding in ("cdr", "ros1") for i in topics.values()):
        next(iter(topics.values())).payload_encoding(path)  # e.g. a JSON MCAP: named
    names = tuple(spec.joint_names or joints)
    if len(names) != len(joints):
        raise refuse(
            "topic spec [joints] names",
            f"{len(joints)} names (the robot's joints {list(joints)}, in q order)",
            f"{list(names)}",
            f"give {len(joints)} names, the log's name of each robot joint in q order",
        )
    roles: dict[str, str] = {}
    how: dict[str, str] = {}
    for role in LOG_ROLES:
        topic = spec.topic(role)
        if role in spec.explicit:
            if topic not in topics:
                raise refuse(
                    f"log {path}",
                    f"the {role} topic {topic} named in the topic spec",
                    f"no such topic (the log has {sorted(topics)})",
                    f"fix [topics] {role} in the topic spec",
                )
            check_type(path, role, topics[topic])
            roles[role], how[role] = topic, "named"
        elif topic in topics:
            check_type(path, role, topics[topic])
            roles[role], how[role] = topic, "default"
    camera_info = _camera_images(path, spec, topics, roles, how)
    states = [t for t, i in topics.items() if i.msgtype == JOINT_STATE and i.encoding != "json"]
    firsts = _first_states(path, topics, set(states))
    if "encoders" not in roles:
        cands = [t for t in states if t in firsts and _has(firsts[t], names, 0)]
        if len(cands) > 1 and "/joint_states" in cands:
            cands = ["/joint_states"]
        if not cands:
            seen = {t: list(firsts[t].names[0]) for t in states if t in firsts}
            raise refuse(
                f"log {path}",
                f"a JointState topic with the positions of {list(names)} (the encoders)",
                f"JointState topics {seen}" if seen else f"none among {sorted(topics)}",
                "name the encoder topic ([topics] encoders) and the log's joint names "
                "([joints] names) in a topic spec (--log-spec; docs/reference/topics.md)",
            )
        if len(cands) > 1:
            raise refuse(
                f"log {path}",
                "one JointState topic with the robot's joints (the encoders)",
                f"several: {cands}",
                "name one in a topic spec's [topics] encoders (--log-spec)",
            )
        roles["encoders"], how["encoders"] = cands[0], "found"
    enc = roles["encoders"]
    if enc in firsts:  # the robot's joints in the encoder topic, checked by name now
        joint_columns(firsts[enc], names, f"log {path}: {enc}")
    if "effort" not in roles:
        first = firsts.get(enc)
        if first is not None and _has(first, names, 2):
            roles["effort"], how["effort"] = enc, "found"
        else:
            only = [
                t
                for t in states
                if t != enc
                and t in firsts
                and _has(firsts[t], names, 2)
                and int(firsts[t].counts[0, 0]) == 0
            ]
            if len(only) == 1:
                roles["effort"], how["effort"] = only[0], "found"
    kind: EffortKind
    if "effort" not in roles:
        kind, kind_how = "none", "no effort topic: encoders only"
        if spec.effort_kind not in (None, "none"):
            raise refuse(
                f"log {path}",
                f"an effort topic (the topic spec says [effort] kind = {spec.effort_kind!r})",
                f"none among {sorted(topics)}",
                'name it in [topics] effort, or say [effort] kind = "none"',
            )
    elif spec.effort_kind is not None:
        kind, kind_how = spec.effort_kind, "named"
    else:
        eff = roles["effort"]
        first = firsts.get(eff)
        if first is not None and int(first.counts[0, 0]) > 0:
            kind = "none"
            kind_how = (
                "the effort of a topic that also carries positions: a driver's measured "
                'effort; if it is the applied torque say [effort] kind = "applied", if it '
                'is a joint torque sensor\'s say "joint_torque"'
            )
        else:
            kind, kind_how = "applied", "a separate effort topic: the applied torque"
    if spec.positions == "link" and kind != "joint_torque":
        raise refuse(
            f'log {path}: [joints] positions = "link"',
            "a joint torque to make the motor angle of (qm = q + tau_J / Ks): [effort] kind "
            '= "joint_torque"',
            f"effort kind {kind!r} ({kind_how}): the link angles would be taken as motor angles",
            'say [effort] kind = "joint_torque" (a torque-sensing arm\'s tau_J), or drop '
            'positions = "link" if the positions are the motor\'s',
        )
    used = set(roles.values()) | ({camera_info} if camera_info else set())
    unused = {
        r: sorted(t for t, i in topics.items() if i.msgtype in ROLES[r].types and t not in used)
        for r in LOG_ROLES
        if r not in roles
    }
    return LogPlan(
        path,
        topics,
        roles,
        how,
        kind,
        kind_how,
        names,
        {r: u for r, u in unused.items() if u},
        camera_info,
    )


def _camera_images(
    path: Path,
    spec: LogSpec,
    topics: dict[str, TopicInfo],
    roles: dict[str, str],
    how: dict[str, str],
) -> str | None:
    """Without a camera topic yet: the log's one image topic (found); with an image camera
    topic: its CameraInfo topic (the spec's ``[camera] info``, else the ``camera_info``
    beside the images, else the log's only CameraInfo topic).

    Raises:
        LogError: an image topic without a CameraInfo topic, or with several to choose from.
    """
    from amsfe_sym.vision.spec import CAMERA_INFO, IMAGE_TYPES

    if "camera" not in roles:
        images = [t for t, i in topics.items() if i.msgtype in IMAGE_TYPES]
        if len(images) == 1:
            roles["camera"], how["camera"] = images[0], "found"
    if "camera" not in roles or topics[roles["camera"]].msgtype not in IMAGE_TYPES:
        return None
    image = roles["camera"]
    infos = sorted(t for t, i in topics.items() if i.msgtype == CAMERA_INFO)
    if spec.camera_info is not None:
        if spec.camera_info not in infos:
            raise refuse(
                f"log {path}",
                f"the CameraInfo topic {spec.camera_info} named in the topic spec",
                f"CameraInfo topics {infos}",
                "fix [camera] info in the topic spec",
            )
        return spec.camera_info
    beside = image.rsplit("/", 1)[0] + "/camera_info"
    if beside in infos:
        return beside
    if len(infos) == 1:
        return infos[0]
    raise refuse(
        f"log {path}: {image} (camera images)",
        "the camera's CameraInfo topic (its intrinsics and distortion)",
        f"CameraInfo topics {infos}" if infos else "none",
        "record the driver's camera_info topic, or name it in the topic spec's [camera] info",
    )


def joint_columns(js: JointStates, names: Sequence[str], where: str) -> IntArray:
    """(M, n) column of each robot joint (``names``, q order) in each message's padded
    arrays (extra names ignored; a joint missing or named twice: refused by name)."""
    try:
        per = [joint_order(ns, names, where) for ns in js.names]
    except AmsfeError as exc:
        raise LogError(str(exc)) from exc
    table = np.asarray(per, dtype=np.int64).reshape(len(per), len(names))
    return table[js.names_index]
