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


class Payloads(Sequence[bytes]):
    """Many payloads in one buffer, without a ``bytes`` object each: payload i is
    ``buffer[offsets[i] : offsets[i] + lengths[i]]`` (a sequence of ``bytes`` to whoever
    iterates it; the bulk decoders gather rows of equal length from the buffer at once)."""

    def __init__(self, buffer: NDArray[np.uint8], offsets: IntArray, lengths: IntArray) -> None:
        self.buffer, self.offsets, self.lengths = buffer, offsets, lengths

    @classmethod
    def of(cls, raws: Sequence[bytes]) -> Payloads:
        """Payloads given one by one."""
        lengths = np.fromiter((len(r) for r in raws), dtype=np.int64, count=len(raws))
        offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        buffer = np.frombuffer(b"".join(bytes(r) for r in raws), dtype=np.uint8)
        return cls(buffer, offsets[: len(raws)], lengths)

    def __len__(self) -> int:
        return int(self.lengths.size)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        start = int(self.offsets[i])
        return self.buffer[start : start + int(self.lengths[i])].tobytes()

    def rows(self, index: IntArray, length: int) -> NDArray[np.uint8]:
        """Payloads ``index`` (all ``length`` bytes long) as a (len(index), length) array."""
        return self.buffer[self.offsets[index][:, None] + np.arange(length)]


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


# ---------------------------------------------------------------------- bulk decoders
# A topic's messages almost always share one layout: the same frame_id, joint names and
# value counts, only the stamp and the values change.  One payload is walked in Python (the
# rules of rosbags' deserializers: CDR aligns each primitive to its size relative to the
# payload after the 4-byte encapsulation header, an empty float64 sequence is not aligned,
# strings carry a NUL, up to 3 trailing bytes are allowed; ROS 1 has no alignment, no NUL and
# a uint32 seq before the stamp), which marks every byte as structure (lengths, counts,
# strings, the encapsulation kind) or value (stamp, seq, float64s, padding).  Every payload of
# the same length whose structure bytes equal the walked one's has the same layout: its
# values are read for all of them at once with numpy.  Payloads of another layout get their
# own walk (up to _MAX_LAYOUTS per length); a payload the walk does not take (big-endian,
# truncated, bad UTF-8, ...) sends the whole call to the reference, errors included.

_MAX_LAYOUTS = 16


class _UnusualError(Exception):
    """A payload the bulk walk does not take (the reference decides)."""


class _Walk:
    """One payload's layout: the structure mask and the offsets of its values."""

    def __init__(self, raw: bytes, encoding: Encoding) -> None:
        self.raw, self.cdr = raw, encoding == "cdr"
        self.base = 4 if self.cdr else 0
        self.pos = 0  # relative to the encapsulation header's end (CDR alignment)
        self.structure = np.ones(len(raw), dtype=np.bool_)
        if self.cdr:
            if len(raw) < 4 or raw[:2] != b"\x00\x01":  # little-endian CDR only
                raise _UnusualError
            self.structure[2:4] = False  # encapsulation options: ignored by rosbags too

    def _take(self, n: int, value: bool) -> int:
        at = self.base + self.pos
        if n < 0 or at + n > len(self.raw):
            raise _UnusualError
        if value:
            self.structure[at : at + n] = False
        self.pos += n
        return at

    def align(self, n: int) -> None:
        if self.cdr:
            self._take(-self.pos % n, value=True)  # padding: any bytes

    def u32(self, value: bool = False) -> int:
        self.align(4)
        at = self._take(4, value)
        return int.from_bytes(self.raw[at : at + 4], "little")

    def string(self) -> str:
        n = self.u32()
        if self.cdr and n < 1:
            raise _UnusualError
        at = self._take(n, value=False)
        if self.cdr and self.raw[at + n - 1] != 0:
            raise _UnusualError
        try:
            return self.raw[at : at + n - self.cdr].decode()
        except UnicodeDecodeError:
            raise _UnusualError from None

    def header(self) -> int:
        """The header; returns the offset of ``stamp`` (int32 sec, uint32 nanosec)."""
        if not self.cdr:
            self.u32(value=True)  # ROS 1 seq
        self.align(4)
        at = self._take(8, value=True)
        self.string()  # frame_id
        return at

    def float64s(self) -> tuple[int, int]:
        """A ``float64[]``: (offset, count)."""
        count = self.u32()
        if count and self.cdr:
            self.align(8)
        return self._take(8 * count, value=True), count

    def fixed_float64s(self, count: int) -> int:
        self.align(8)
        return self._take(8 * count, value=True)

    def finish(self) -> None:
        end = self.base + self.pos
        trailing = len(self.raw) - end
        if trailing < 0 or trailing > (3 if self.cdr else 0):
            raise _UnusualError
        self.structure[end:] = False


@dataclass
class _Layout:
    """What a walk found: the structure mask and, per message type, its offsets."""

    structure: NDArray[np.bool_]
    stamp: int = -1
    names: tuple[str, ...] = ()
    arrays: tuple[tuple[int, int], ...] = ()  # float64 sequences (offset, count)


def _walk_joint_state(raw: bytes, encoding: Encoding) -> _Layout:
    w = _Walk(raw, encoding)
    stamp = w.header()
    names = tuple(w.string() for _ in range(w.u32()))
    arrays = tuple(w.float64s() for _ in range(3))
    w.finish()
    return _Layout(w.structure, stamp, names, arrays)


def _walk_point(raw: bytes, encoding: Encoding) -> _Layout:
    w = _Walk(raw, encoding)
    stamp = w.header()
    xyz = w.fixed_float64s(3)
    w.finish()
    return _Layout(w.structure, stamp, (), ((xyz, 3),))


def _walk_float64_array(raw: bytes, encoding: Encoding) -> _Layout:
    w = _Walk(raw, encoding)
    for _ in range(w.u32()):  # layout.dim: label (structure), size, stride (values)
        w.string()
        w.u32(value=True)
        w.u32(value=True)
    w.u32(value=True)  # data_offset
    data = w.float64s()
    w.finish()
    return _Layout(w.structure, -1, (), (data,))


@dataclass
class _Group:
    """Payloads of one layout: their row numbers and their bytes, one row each."""

    rows: IntArray
    data: NDArray[np.uint8]
    layout: _Layout

    def column(self, offset: int, count: int, dtype: str) -> NDArray[Any]:
        size = np.dtype(dtype).itemsize
        block = np.ascontiguousarray(self.data[:, offset : offset + size * count])
        return block.view(dtype).reshape(len(self.rows), count)

    def stamps(self) -> IntArray:
        sec = self.column(self.layout.stamp, 1, "<i4")[:, 0].astype(np.int64)
        nanosec = self.column(self.layout.stamp + 4, 1, "<u4")[:, 0].astype(np.int64)
        return sec * 1_000_000_000 + nanosec

    def float64s(self, i: int) -> FloatArray:
        offset, count = self.layout.arrays[i]
        return self.column(offset, count, "<f8").astype(np.float64)


def _groups(raws: Sequence[bytes], encoding: Encoding, walk: Any) -> list[_Group] | None:
    """The payloads by layout, or None when one of them is for the reference."""
    payloads = raws if isinstance(raws, Payloads) else Payloads.of(raws)
    lengths = payloads.lengths
    out: list[_Group] = []
    for length in np.unique(lengths):
        rows = np.flatnonzero(lengths == length)
        data = payloads.rows(rows, int(length))
        for _ in range(_MAX_LAYOUTS):
            try:
                layout = walk(payloads[int(rows[0])], encoding)
            except _UnusualError:
                return None
            mask = layout.structure
            same = (data[:, mask] == data[0, mask]).all(axis=1)
            out.append(_Group(rows[same], data[same], layout))
            rows, data = rows[~same], data[~same]
            if rows.size == 0:
                break
        else:
            return None  # more layouts than it is worth: the reference
    return out


def decode_joint_states(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> JointStates:
    """``sensor_msgs/msg/JointState`` payloads -> :class:`JointStates` (in bulk; the same
    arrays as the reference, ``_reference_joint_states``).

    Raises:
        LogError: a payload that does not decode.
    """
    groups = _groups(raws, encoding, _walk_joint_state) if raws else []
    if groups is None:
        return _reference_joint_states(raws, encoding, where)
    M = len(raws)
    first: dict[tuple[str, ...], int] = {}  # names -> the first row carrying them
    for g in groups:
        first[g.layout.names] = min(first.get(g.layout.names, M), int(g.rows[0]))
    names = sorted(first, key=first.__getitem__)
    order = {n: i for i, n in enumerate(names)}
    counts = np.zeros((M, 3), np.int64)
    for g in groups:
        counts[g.rows] = [c for _, c in g.layout.arrays]
    width = max([len(n) for n in names] + [int(counts.max(initial=0))])
    stamps, index = np.zeros(M, np.int64), np.zeros(M, np.int64)
    fields = [np.full((M, width), np.nan) for _ in range(3)]
    for g in groups:
        stamps[g.rows] = g.stamps()
        index[g.rows] = order[g.layout.names]
        for i, out in enumerate(fields):
            count = g.layout.arrays[i][1]
            if count:
                out[g.rows, :count] = g.float64s(i)
    return JointStates(stamps, names, index, fields[0], fields[1], fields[2], counts)


def decode_points(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Points:
    """``geometry_msgs/msg/PointStamped`` payloads -> :class:`Points` (in bulk)."""
    groups = _groups(raws, encoding, _walk_point) if raws else []
    if groups is None:
        return _reference_points(raws, encoding, where)
    stamps, xyz = np.zeros(len(raws), np.int64), np.zeros((len(raws), 3))
    for g in groups:
        stamps[g.rows] = g.stamps()
        xyz[g.rows] = g.float64s(0)
    return Points(stamps, xyz)


def decode_float64_arrays(
    raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = ""
) -> Float64Arrays:
    """``std_msgs/msg/Float64MultiArray`` payloads -> :class:`Float64Arrays` (in bulk)."""
    groups = _groups(raws, encoding, _walk_float64_array) if raws else []
    if groups is None:
        return _reference_float64_arrays(raws, encoding, where)
    counts = np.zeros(len(raws), np.int64)
    for g in groups:
        counts[g.rows] = g.layout.arrays[0][1]
    values = np.full((len(raws), int(counts.max(initial=0))), np.nan)
    for g in groups:
        count = g.layout.arrays[0][1]
        if count:
            values[g.rows, :count] = g.float64s(0)
    return Float64Arrays(values, counts)


def decode_strings(raws: Sequence[bytes], encoding: Encoding = "cdr", where: str = "") -> Strings:
    """``std_msgs/msg/String`` payloads -> :class:`Strings` (each walked without rosbags)."""
    out = []
    for raw in raws:
        try:
            w = _Walk(raw, encoding)
            out.append(w.string())
            w.finish()
        except _UnusualError:
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
