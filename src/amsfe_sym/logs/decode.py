"""A topic's payloads -> numpy arrays, all messages at once (docs/logs.md, "Speed").

The contract the log reader codes against: one call per topic and message type over the raw
payloads (CDR of rosbag2 / MCAP, or ROS 1 wire format of a ``.bag``), returning columns.
This module holds the reference implementation (``rosbags``' deserializers, message by
message); a bulk decoder must return exactly the same arrays (tests compare them bit for bit).

Conventions: a value a message does not carry is NaN; every array has one row per payload, in
the order given; stamps are ``header.stamp`` in integer nanoseconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import LogError, describe

__all__ = [
    "Encoding",
    "Float64Arrays",
    "JointStates",
    "Points",
    "Strings",
    "decode_float64_arrays",
    "decode_joint_states",
    "decode_points",
    "decode_strings",
    "deserialize",
    "typestore",
    "typestore_ros1",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: How payloads are serialized: ``cdr`` (ROS 2: rosbag2, MCAP) or ``ros1`` (a ROS 1 ``.bag``).
Encoding = Literal["cdr", "ros1"]


@dataclass
class JointStates:
    """``sensor_msgs/msg/JointState`` payloads as columns.

    Attributes:
        stamp_ns: ``header.stamp`` [ns], (M,).
        names: The distinct ``name`` lists, in order of first appearance.
        names_index: Which of ``names`` each message has, (M,).
        position, velocity, effort: (M, J) with J the longest ``name`` list [rad, rad/s,
            N m]; NaN where a message carries fewer values (an empty field: all NaN).
        counts: How many position, velocity and effort values each message carries, (M, 3)
            (a count that differs from its ``name`` list's length is a malformed sample).
    """

    stamp_ns: IntArray
    names: list[tuple[str, ...]]
    names_index: IntArray
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray
    counts: IntArray


@dataclass
class Points:
    """``geometry_msgs/msg/PointStamped`` payloads: ``stamp_ns`` (M,) [ns], ``xyz`` (M, 3)."""

    stamp_ns: IntArray
    xyz: FloatArray


@dataclass
class Float64Arrays:
    """``std_msgs/msg/Float64MultiArray`` payloads: ``values`` (M, L) NaN-padded to the
    longest, ``counts`` (M,) how many each carries."""

    values: FloatArray
    counts: IntArray


@dataclass
class Strings:
    """``std_msgs/msg/String`` payloads."""

    data: list[str]


_STORE: Any = None
_STORE_ROS1: Any = None


def typestore() -> Any:
    """The ROS 2 (Humble) standard message definitions of ``rosbags``."""
    global _STORE
    if _STORE is None:
        from rosbags.typesys import Stores, get_typestore

        _STORE = get_typestore(Stores.ROS2_HUMBLE)
    return _STORE


def typestore_ros1() -> Any:
    """The ROS 1 (Noetic) standard message definitions of ``rosbags``: a ROS 1 ``Header``
    carries ``seq`` before its stamp, so ROS 1 payloads are decoded with these (same type
    names, ``sensor_msgs/msg/JointState``; same field names)."""
    global _STORE_ROS1
    if _STORE_ROS1 is None:
        from rosbags.typesys import Stores, get_typestore

        _STORE_ROS1 = get_typestore(Stores.ROS1_NOETIC)
    return _STORE_ROS1


def deserialize(raw: bytes, msgtype: str, encoding: Encoding = "cdr", where: str = "") -> Any:
    """One payload as a ``rosbags`` message object.

    Raises:
        LogError: the bytes do not decode as ``msgtype`` (a corrupt or mislabelled message).
    """
    try:
        if encoding == "ros1":
            return typestore_ros1().deserialize_ros1(raw, msgtype)
        return typestore().deserialize_cdr(raw, msgtype)
    except Exception as exc:  # rosbags' SerdeError and friends: one line, not a trace
        raise LogError(
            describe(
                where or f"a {msgtype} message",
                f"bytes that decode as {msgtype} ({encoding})",
                f"{type(exc).__name__}: {exc}",
                "check the recorder and the message definitions; re-record or cut the message",
            )
        ) from exc


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _padded(rows: Sequence[FloatArray], width: int) -> FloatArray:
    out = np.full((len(rows), width), np.nan)
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


def decode_joint_states(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> JointStates:
    """``sensor_msgs/msg/JointState`` payloads -> :class:`JointStates`.

    Raises:
        LogError: a payload that does not decode.
    """
    t = "sensor_msgs/msg/JointState"
    stamps, index = np.zeros(len(raws), np.int64), np.zeros(len(raws), np.int64)
    names: list[tuple[str, ...]] = []
    seen: dict[tuple[str, ...], int] = {}
    fields: dict[str, list[FloatArray]] = {"position": [], "velocity": [], "effort": []}
    counts = np.zeros((len(raws), 3), np.int64)
    for i, raw in enumerate(raws):
        msg = deserialize(raw, t, encoding, where)
        stamps[i] = _stamp(msg)
        key = tuple(str(n) for n in msg.name)
        if key not in seen:
            seen[key] = len(names)
            names.append(key)
        index[i] = seen[key]
        for j, f in enumerate(fields):
            v = np.asarray(getattr(msg, f), dtype=np.float64).ravel()
            fields[f].append(v)
            counts[i, j] = v.size
    width = max([len(n) for n in names] + [int(counts.max(initial=0))])
    return JointStates(
        stamps,
        names,
        index,
        _padded(fields["position"], width),
        _padded(fields["velocity"], width),
        _padded(fields["effort"], width),
        counts,
    )


def decode_points(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Points:
    """``geometry_msgs/msg/PointStamped`` payloads -> :class:`Points`."""
    t = "geometry_msgs/msg/PointStamped"
    stamps, xyz = np.zeros(len(raws), np.int64), np.zeros((len(raws), 3))
    for i, raw in enumerate(raws):
        msg = deserialize(raw, t, encoding, where)
        stamps[i] = _stamp(msg)
        xyz[i] = (msg.point.x, msg.point.y, msg.point.z)
    return Points(stamps, xyz)


def decode_float64_arrays(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> Float64Arrays:
    """``std_msgs/msg/Float64MultiArray`` payloads -> :class:`Float64Arrays`."""
    t = "std_msgs/msg/Float64MultiArray"
    rows = [np.asarray(deserialize(r, t, encoding, where).data, np.float64).ravel() for r in raws]
    counts = np.array([r.size for r in rows], np.int64)
    return Float64Arrays(_padded(rows, int(counts.max(initial=0))), counts)


def decode_strings(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Strings:
    """``std_msgs/msg/String`` payloads -> :class:`Strings`."""
    return Strings([str(deserialize(r, "std_msgs/msg/String", encoding, where).data) for r in raws])
