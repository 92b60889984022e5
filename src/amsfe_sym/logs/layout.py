"""Payload layouts: what lets the bulk decoders of :mod:`amsfe_sym.logs.decode` read a
topic's messages all at once (docs/how-to/logs.md, "Speed").

A topic's messages almost always share one layout: the same frame_id, joint names and
value counts, only the stamp and the values change.  One payload is walked in Python (the
rules of rosbags' deserializers: CDR aligns each primitive to its size relative to the
payload after the 4-byte encapsulation header, an empty float64 sequence is not aligned,
strings carry a NUL, up to 3 trailing bytes are allowed; ROS 1 has no alignment, no NUL and
a uint32 seq before the stamp), which marks every byte as structure (lengths, counts,
strings, the encapsulation kind) or value (stamp, seq, float64s, padding).  Every payload of
the same length whose structure bytes equal the walked one's has the same layout: its
values are read for all of them at once with numpy.  Payloads of another layout get their
own walk (up to MAX_LAYOUTS per length); a payload the walk does not take (big-endian,
truncated, bad UTF-8, ...) sends the whole call to the reference, errors included.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray, IntArray

__all__ = [
    "MAX_LAYOUTS",
    "Encoding",
    "Group",
    "Layout",
    "Payloads",
    "UnusualError",
    "Walk",
    "groups",
    "walk_float64_array",
    "walk_joint_state",
    "walk_point",
]


#: How payloads are serialized: ``cdr`` (ROS 2: rosbag2, MCAP) or ``ros1`` (a ROS 1 ``.bag``).
Encoding = Literal["cdr", "ros1"]


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
        buffer = np.frombuffer(b"".join(raws), dtype=np.uint8)
        return cls(buffer, offsets[: len(raws)], lengths)

    def __len__(self) -> int:
        return int(self.lengths.size)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        start = int(self.offsets[i])
        return self.buffer[start : start + int(self.lengths[i])].tobytes()

    @classmethod
    def join(cls, parts: Sequence[Payloads]) -> Payloads:
        """Several slices as one, their bytes copied out of their buffers (a chunk's buffer
        is not held: only the payloads' own bytes)."""
        lengths = np.concatenate([p.lengths for p in parts]) if parts else np.zeros(0, np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)[: lengths.size]
        pieces = []
        for p in parts:
            at = np.concatenate([[0], np.cumsum(p.lengths)[:-1]]).astype(np.int64)
            gather = np.repeat(p.offsets - at[: p.lengths.size], p.lengths)
            pieces.append(p.buffer[gather + np.arange(gather.size)])
        buffer = np.concatenate(pieces) if pieces else np.zeros(0, np.uint8)
        return cls(buffer, starts, lengths.astype(np.int64))

    def view(self, i: int) -> NDArray[np.uint8]:
        """Payload ``i`` as a view of the buffer (no copy: an image's pixels stay where the
        chunk put them)."""
        start = int(self.offsets[i])
        return self.buffer[start : start + int(self.lengths[i])]

    def rows(self, index: IntArray, length: int) -> NDArray[np.uint8]:
        """Payloads ``index`` (all ``length`` bytes long) as a (len(index), length) array."""
        if length == 0:
            return np.zeros((len(index), 0), dtype=np.uint8)
        # rows of a sliding-window view: no (rows x length) index array, one copy of the bytes
        windows = np.lib.stride_tricks.sliding_window_view(self.buffer, length)
        return np.asarray(windows[self.offsets[index]])


MAX_LAYOUTS = 16


class UnusualError(Exception):
    """A payload the bulk walk does not take (the reference decides)."""


class Walk:
    """One payload's layout: the structure mask and the offsets of its values."""

    def __init__(self, raw: bytes, encoding: Encoding) -> None:
        self.raw, self.cdr = raw, encoding == "cdr"
        self.base = 4 if self.cdr else 0
        self.pos = 0  # relative to the encapsulation header's end (CDR alignment)
        self.structure = np.ones(len(raw), dtype=np.bool_)
        if self.cdr:
            if len(raw) < 4 or raw[:2] != b"\x00\x01":  # little-endian CDR only
                raise UnusualError
            self.structure[2:4] = False  # encapsulation options: ignored by rosbags too

    def _take(self, n: int, value: bool) -> int:
        at = self.base + self.pos
        if n < 0 or at + n > len(self.raw):
            raise UnusualError
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
            raise UnusualError
        at = self._take(n, value=False)
        if self.cdr and self.raw[at + n - 1] != 0:
            raise UnusualError
        try:
            return self.raw[at : at + n - self.cdr].decode()
        except UnicodeDecodeError:
            raise UnusualError from None

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
            raise UnusualError
        self.structure[end:] = False


@dataclass
class Layout:
    """What a walk found: the structure mask and, per message type, its offsets."""

    structure: NDArray[np.bool_]
    stamp: int = -1
    names: tuple[str, ...] = ()
    arrays: tuple[tuple[int, int], ...] = ()  # float64 sequences (offset, count)


def walk_joint_state(raw: bytes, encoding: Encoding) -> Layout:
    w = Walk(raw, encoding)
    stamp = w.header()
    names = tuple(w.string() for _ in range(w.u32()))
    arrays = tuple(w.float64s() for _ in range(3))
    w.finish()
    return Layout(w.structure, stamp, names, arrays)


def walk_point(raw: bytes, encoding: Encoding) -> Layout:
    w = Walk(raw, encoding)
    stamp = w.header()
    xyz = w.fixed_float64s(3)
    w.finish()
    return Layout(w.structure, stamp, (), ((xyz, 3),))


def walk_float64_array(raw: bytes, encoding: Encoding) -> Layout:
    w = Walk(raw, encoding)
    for _ in range(w.u32()):  # layout.dim: label (structure), size, stride (values)
        w.string()
        w.u32(value=True)
        w.u32(value=True)
    w.u32(value=True)  # data_offset
    data = w.float64s()
    w.finish()
    return Layout(w.structure, -1, (), (data,))


@dataclass
class Group:
    """Payloads of one layout: their row numbers and their bytes, one row each."""

    rows: IntArray
    data: NDArray[np.uint8]
    layout: Layout

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


def groups(raws: Sequence[bytes], encoding: Encoding, walk: Any) -> list[Group] | None:
    """The payloads by layout, or None when one of them is for the reference."""
    payloads = raws if isinstance(raws, Payloads) else Payloads.of(raws)
    lengths = payloads.lengths
    out: list[Group] = []
    for length in np.unique(lengths):
        rows = np.flatnonzero(lengths == length)
        data = payloads.rows(rows, int(length))
        for _ in range(MAX_LAYOUTS):
            try:
                layout = walk(payloads[int(rows[0])], encoding)
            except UnusualError:
                return None
            mask = layout.structure
            same = (data[:, mask] == data[0, mask]).all(axis=1)
            out.append(Group(rows[same], data[same], layout))
            rows, data = rows[~same], data[~same]
            if rows.size == 0:
                break
        else:
            return None  # more layouts than it is worth: the reference
    return out
