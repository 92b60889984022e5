"""A topic's payloads -> numpy arrays, all messages at once (docs/how-to/logs.md, "Speed").

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
from typing import Any

import numpy as np

from amsfe_sym.arrays import FloatArray, IntArray
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.layout import (
    Encoding,
    Payloads,
    UnusualError,
    Walk,
    groups,
    walk_float64_array,
    walk_joint_state,
    walk_point,
)

__all__ = [
    "DECODERS",
    "Encoding",
    "Float64Arrays",
    "JointStates",
    "Payloads",
    "Points",
    "Strings",
    "concat_decoded",
    "decode_float64_arrays",
    "decode_joint_states",
    "decode_payloads",
    "decode_points",
    "decode_strings",
    "deserialize",
    "typestore",
]


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


_STORES: dict[str, Any] = {}


def typestore(encoding: Encoding = "cdr") -> Any:
    """``rosbags``' standard message definitions: ROS 2 (Humble) for ``cdr``, ROS 1 (Noetic,
    whose ``std_msgs/Header`` starts with a ``uint32 seq``) for ``ros1``."""
    if encoding not in _STORES:
        from rosbags.typesys import Stores, get_typestore

        store = Stores.ROS1_NOETIC if encoding == "ros1" else Stores.ROS2_HUMBLE
        _STORES[encoding] = get_typestore(store)
    return _STORES[encoding]


def deserialize(raw: bytes, msgtype: str, encoding: Encoding = "cdr", where: str = "") -> Any:
    """One payload as a ``rosbags`` message object.

    Raises:
        LogError: the bytes do not decode as ``msgtype`` (a corrupt or mislabelled message).
    """
    try:
        if encoding == "ros1":
            return typestore("ros1").deserialize_ros1(raw, msgtype)
        return typestore("cdr").deserialize_cdr(raw, msgtype)
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


def _reference_joint_states(
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


def _reference_points(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Points:
    """``geometry_msgs/msg/PointStamped`` payloads -> :class:`Points`."""
    t = "geometry_msgs/msg/PointStamped"
    stamps, xyz = np.zeros(len(raws), np.int64), np.zeros((len(raws), 3))
    for i, raw in enumerate(raws):
        msg = deserialize(raw, t, encoding, where)
        stamps[i] = _stamp(msg)
        xyz[i] = (msg.point.x, msg.point.y, msg.point.z)
    return Points(stamps, xyz)


def _reference_float64_arrays(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> Float64Arrays:
    """``std_msgs/msg/Float64MultiArray`` payloads -> :class:`Float64Arrays`."""
    t = "std_msgs/msg/Float64MultiArray"
    rows = [np.asarray(deserialize(r, t, encoding, where).data, np.float64).ravel() for r in raws]
    counts = np.array([r.size for r in rows], np.int64)
    return Float64Arrays(_padded(rows, int(counts.max(initial=0))), counts)


def _reference_strings(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> Strings:
    """``std_msgs/msg/String`` payloads -> :class:`Strings`."""
    return Strings([str(deserialize(r, "std_msgs/msg/String", encoding, where).data) for r in raws])


def decode_joint_states(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> JointStates:
    """``sensor_msgs/msg/JointState`` payloads -> :class:`JointStates` (in bulk; the same
    arrays as the reference, ``_reference_joint_states``).

    Raises:
        LogError: a payload that does not decode.
    """
    found = groups(raws, encoding, walk_joint_state) if raws else []
    if found is None:
        return _reference_joint_states(raws, encoding, where)
    M = len(raws)
    first: dict[tuple[str, ...], int] = {}  # names -> the first row carrying them
    for g in found:
        first[g.layout.names] = min(first.get(g.layout.names, M), int(g.rows[0]))
    names = sorted(first, key=first.__getitem__)
    order = {n: i for i, n in enumerate(names)}
    counts = np.zeros((M, 3), np.int64)
    for g in found:
        counts[g.rows] = [c for _, c in g.layout.arrays]
    width = max([len(n) for n in names] + [int(counts.max(initial=0))])
    stamps, index = np.zeros(M, np.int64), np.zeros(M, np.int64)
    fields = [np.full((M, width), np.nan) for _ in range(3)]
    for g in found:
        stamps[g.rows] = g.stamps()
        index[g.rows] = order[g.layout.names]
        for i, out in enumerate(fields):
            count = g.layout.arrays[i][1]
            if count:
                out[g.rows, :count] = g.float64s(i)
    return JointStates(stamps, names, index, fields[0], fields[1], fields[2], counts)


def decode_points(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Points:
    """``geometry_msgs/msg/PointStamped`` payloads -> :class:`Points` (in bulk)."""
    found = groups(raws, encoding, walk_point) if raws else []
    if found is None:
        return _reference_points(raws, encoding, where)
    stamps, xyz = np.zeros(len(raws), np.int64), np.zeros((len(raws), 3))
    for g in found:
        stamps[g.rows] = g.stamps()
        xyz[g.rows] = g.float64s(0)
    return Points(stamps, xyz)


def decode_float64_arrays(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> Float64Arrays:
    """``std_msgs/msg/Float64MultiArray`` payloads -> :class:`Float64Arrays` (in bulk)."""
    found = groups(raws, encoding, walk_float64_array) if raws else []
    if found is None:
        return _reference_float64_arrays(raws, encoding, where)
    counts = np.zeros(len(raws), np.int64)
    for g in found:
        counts[g.rows] = g.layout.arrays[0][1]
    values = np.full((len(raws), int(counts.max(initial=0))), np.nan)
    for g in found:
        count = g.layout.arrays[0][1]
        if count:
            values[g.rows, :count] = g.float64s(0)
    return Float64Arrays(values, counts)


def decode_strings(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Strings:
    """``std_msgs/msg/String`` payloads -> :class:`Strings` (each walked without rosbags)."""
    out = []
    for raw in raws:
        try:
            w = Walk(raw, encoding)
            out.append(w.string())
            w.finish()
        except UnusualError:
            return _reference_strings(raws, encoding, where)
    return Strings(out)


#: The bulk decoder of each message type.
DECODERS: dict[str, Any] = {
    "sensor_msgs/msg/JointState": decode_joint_states,
    "geometry_msgs/msg/PointStamped": decode_points,
    "std_msgs/msg/Float64MultiArray": decode_float64_arrays,
    "std_msgs/msg/String": decode_strings,
}


def decode_payloads(
    msgtype: str, raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> JointStates | Points | Float64Arrays | Strings | None:
    """The payloads of one topic by its type's decoder; None for a type without one."""
    fn = DECODERS.get(msgtype)
    return None if fn is None else fn(raws, encoding, where)


def _pad(a: FloatArray, width: int) -> FloatArray:
    if a.shape[1] == width:
        return a
    out = np.full((a.shape[0], width), np.nan)
    out[:, : a.shape[1]] = a
    return out


def concat_decoded(parts: Sequence[Any]) -> Any:
    """Decoded slices of one topic (one type), joined as if decoded in one call."""
    first = parts[0]
    if hasattr(first, "concat"):  # a decoder's own columns (vision.detections.Detections)
        return first.concat(parts)
    if isinstance(first, Strings):
        return Strings([s for p in parts for s in p.data])
    if isinstance(first, Points):
        return Points(
            np.concatenate([p.stamp_ns for p in parts]), np.concatenate([p.xyz for p in parts])
        )
    if isinstance(first, Float64Arrays):
        width = max(p.values.shape[1] for p in parts)
        return Float64Arrays(
            np.concatenate([_pad(p.values, width) for p in parts]),
            np.concatenate([p.counts for p in parts]),
        )
    names: list[tuple[str, ...]] = []
    seen: dict[tuple[str, ...], int] = {}
    index = []
    for p in parts:
        for n in p.names:
            if n not in seen:
                seen[n] = len(names)
                names.append(n)
        remap = np.array([seen[n] for n in p.names] or [0], np.int64)
        index.append(remap[p.names_index])
    width = max(p.position.shape[1] for p in parts)

    def joined(f: str) -> FloatArray:
        return np.concatenate([_pad(getattr(p, f), width) for p in parts])

    return JointStates(
        np.concatenate([p.stamp_ns for p in parts]),
        names,
        np.concatenate(index),
        joined("position"),
        joined("velocity"),
        joined("effort"),
        np.concatenate([p.counts for p in parts]),
    )
