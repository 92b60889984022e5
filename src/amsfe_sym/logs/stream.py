"""A log's topics as decoded columns, read in bounded memory (docs/how-to/logs.md, "Speed").

:func:`read_topics` is what the log reader calls instead of iterating messages one by one:
it returns, per topic, the message type, the log times and the payloads decoded in bulk
(:mod:`amsfe_sym.logs.decode`).  Memory holds the decoded columns and one slice of raw
payloads at a time, never every message as an object.

- An MCAP file (a plain ``.mcap``, or the files of a rosbag2 folder in MCAP storage) is read
  chunk by chunk: the summary (``mcap``'s reader) gives each chunk's offset, compression
  (none, zstd, lz4) and message indexes; a chunk is decompressed once and each wanted
  channel's payloads are cut out of it with numpy at the offsets its message index lists, no
  Python object per message.
- A ROS 1 ``.bag`` is read the same way: ``rosbags``' reader parses its index (chunk and
  offset of each message), each chunk is decompressed once (none, bz2, lz4) and the
  payloads are cut out of it with numpy.
- Anything else (an MCAP without a summary or message indexes, sqlite3 storage, a bag
  whose index does not point at message records) goes through
  :func:`amsfe_sym.logs.source.iter_messages` and is decoded in slices of :data:`SLICE`
  messages.

Both give each topic's messages in log-time order (ties: file order), as ``iter_messages``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import IntArray
from amsfe_sym.core.interrupts import result_held
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.chunks import (
    NotIndexed,
    checked_chunks,
    cut,
    summary_of,
    unreadable,
)
from amsfe_sym.logs.decode import (
    Encoding,
    Float64Arrays,
    JointStates,
    Payloads,
    Points,
    Strings,
    concat_decoded,
    decode_payloads,
)

__all__ = [
    "PROGRESS_MIN_S",
    "SLICE",
    "Topic",
    "read_topics",
]

Decoded = JointStates | Points | Float64Arrays | Strings

#: Messages decoded at once on the message-by-message path (bounds the raw bytes held).
SLICE = 65536
#: ... and payload bytes (images: a slice of large messages is cut at this size).
SLICE_BYTES = 64 << 20
#: Logs spanning at least this long [s] get a progress bar (``progress=None``).
PROGRESS_MIN_S = 5.0

Progress = Callable[[int, int], None]
#: A topic's own decoder (``decode(payloads, encoding, where)``, e.g. an image topic's
#: marker detector, :class:`amsfe_sym.vision.detections.ImageDecoder`), by topic; it may
#: return a ``Future`` of the slice's columns (decoded on other threads while the reading
#: goes on, :class:`amsfe_sym.vision.prefetch.Prefetch`), resolved when the topic is joined.
Decoders = dict[str, Callable[..., Any]]


class _Bar:
    """A tqdm bar behind the ``(done, total)`` callback (made when first called)."""

    def __init__(self, desc: str, unit: str) -> None:
        self.desc, self.unit, self.last = desc, unit, 0
        self.bar: Any = None

    def __call__(self, done: int, total: int) -> None:
        if self.bar is None:
            from tqdm import tqdm

            scale = self.unit == "B"
            self.bar = tqdm(
                total=total or None, desc=self.desc, unit=self.unit, unit_scale=scale,
                mininterval=0.5, leave=False, delay=1.0,
            )  # fmt: skip
        self.bar.update(done - self.last)
        self.last = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


@dataclass
class Topic:
    """One topic of a log, decoded.

    Attributes:
        name: The topic.
        msgtype: Its ROS 2 type name, e.g. ``sensor_msgs/msg/JointState``.
        encoding: ``cdr`` or ``ros1``.
        log_time_ns: When the recorder received each message [ns], (M,), non-decreasing.
        decoded: The payloads as columns (:mod:`amsfe_sym.logs.decode`), or None for a type
            the decoders do not know (then ``raw`` holds the payloads).
        raw: The payloads of a type without a decoder.
    """

    name: str
    msgtype: str
    encoding: Encoding
    log_time_ns: IntArray
    decoded: Decoded | None
    raw: list[bytes] = field(default_factory=list)

    @property
    def count(self) -> int:
        """Messages on the topic."""
        return int(self.log_time_ns.size)


class _Parts:
    """A topic's decoded slices, joined at the end."""

    def __init__(
        self, name: str, msgtype: str, encoding: Encoding, decoder: Callable[..., Any] | None = None
    ) -> None:
        self.name, self.msgtype, self.encoding = name, msgtype, encoding
        self.decoder = decoder
        self.times: list[IntArray] = []
        self.decoded: list[Any] = []
        self.raw: list[bytes] = []
        # small slices of a bulk-decoded topic, copied out and decoded together: a log whose
        # chunks are cut small by large messages (images) would otherwise decode its
        # encoders ~100 messages a call (bounded as the message path: SLICE, SLICE_BYTES)
        self._pending: list[Payloads] = []
        self._held = (0, 0)  # (messages, bytes) pending
        self._where = ""

    def add(self, times: IntArray, payloads: Payloads, where: str) -> None:
        self.times.append(times)
        if self.decoder is not None:
            dec = self.decoder(payloads, self.encoding, where)
        elif isinstance(payloads, Payloads) and len(payloads) < SLICE:
            self._pending.append(Payloads.join([payloads]))
            n, b = self._held
            self._held = (n + len(payloads), b + int(payloads.lengths.sum()))
            self._where = where
            if self._held[0] >= SLICE or self._held[1] >= SLICE_BYTES:
                self._flush()
            return
        else:
            self._flush()
            dec = decode_payloads(self.msgtype, payloads, self.encoding, where)
        self._keep(dec, payloads)

    def _keep(self, dec: Any, payloads: Payloads) -> None:
        if dec is None:
            self.raw.extend(payloads)
        else:
            self.decoded.append(dec)

    def _flush(self) -> None:
        if self._pending:
            joined = Payloads.join(self._pending)
            self._pending, self._held = [], (0, 0)
            self._keep(decode_payloads(self.msgtype, joined, self.encoding, self._where), joined)

    def topic(self) -> Topic:
        self._flush()
        times = np.concatenate(self.times) if self.times else np.zeros(0, np.int64)
        order = np.argsort(times, kind="stable")
        sorted_already = bool(np.all(order == np.arange(order.size)))
        slices = [result_held(d) if isinstance(d, Future) else d for d in self.decoded]
        decoded = concat_decoded(slices) if slices else None
        raw = self.raw
        if not sorted_already:
            if decoded is not None:
                decoded = _take(decoded, order)
            raw = [raw[i] for i in order] if raw else raw
        return Topic(self.name, self.msgtype, self.encoding, times[order], decoded, raw)


def _take(dec: Any, order: IntArray) -> Any:
    """Rows ``order`` of decoded columns (the names of JointStates stay in first-appearance
    order of the reordered rows)."""
    if isinstance(dec, Strings):
        return Strings([dec.data[i] for i in order])
    if isinstance(dec, JointStates):
        index = dec.names_index[order]
        first = sorted(set(index.tolist()), key=lambda i: int(np.argmax(index == i)))
        remap = np.zeros(len(dec.names), np.int64)
        remap[first] = np.arange(len(first))
        return JointStates(
            dec.stamp_ns[order],
            [dec.names[i] for i in first],
            remap[index],
            dec.position[order],
            dec.velocity[order],
            dec.effort[order],
            dec.counts[order],
        )
    kwargs = {k: v[order] for k, v in vars(dec).items()}
    return type(dec)(**kwargs)


def read_topics(
    path: Path,
    topics: Iterable[str],
    progress: Progress | bool | None = None,
    decoders: Decoders | None = None,
) -> dict[str, Topic]:
    """The ``topics`` of the log at ``path``, decoded (a topic with no message: absent).

    Args:
        path: A rosbag2 folder, a ``.mcap`` file, or what ``iter_messages`` reads.
        topics: The topics wanted.
        progress: A callback ``(done, total)`` (bytes of an MCAP, else messages with total
            0), True or False for a tqdm bar or none; None: a bar for an MCAP spanning at
            least :data:`PROGRESS_MIN_S`, or once :data:`SLICE` messages were read otherwise
            (a bar shows once the read has taken 1 s).
        decoders: Topics decoded by their own decoder instead of their type's (an image
            topic's marker detector), called on each slice of payloads as it is cut.

    Raises:
        LogError: unreadable, truncated, or a payload that does not decode.
    """
    wanted = set(topics)
    own = decoders or {}
    if path.is_file() and path.suffix == ".bag":
        parts_bag: dict[str, _Parts] = {}
        bar = _Bar(f"read {path.name}", "B")
        try:
            _read_bag(path, wanted, parts_bag, _callback(progress, bar), own)
            return {name: t for name, p in parts_bag.items() if (t := p.topic()).count}
        except NotIndexed:
            pass
        finally:
            bar.close()
    files = _mcap_files(path)
    if files is not None:
        parts: dict[str, _Parts] = {}
        bar = _Bar(f"read {path.name}", "B")
        try:
            for f in files:
                _read_mcap(f, wanted, parts, _callback(progress, bar), progress is None, own)
            out = {name: p.topic() for name, p in parts.items()}
            return {name: t for name, t in out.items() if t.count}
        except NotIndexed:
            pass
        finally:
            bar.close()
    bar = _Bar(f"read {path.name}", "msg")
    try:
        return _read_messages(path, wanted, _callback(progress, bar), own)
    finally:
        bar.close()


def _callback(progress: Progress | bool | None, bar: _Bar) -> Progress | None:
    if progress is None or progress is True:
        return bar
    return progress or None


def _mcap_files(path: Path) -> list[Path] | None:
    """The MCAP files of ``path`` (a ``.mcap``, or a rosbag2 folder in MCAP storage)."""
    if path.is_file() and path.suffix == ".mcap":
        return [path]
    if path.is_dir() and (path / "metadata.yaml").is_file():
        files = sorted(path.glob("*.mcap"))
        if files and not list(path.glob("*.db3")):
            return files
    return None


def _read_messages(
    path: Path, wanted: set[str], progress: Progress | None, decoders: Decoders
) -> dict[str, Topic]:
    from amsfe_sym.logs.source import iter_messages

    parts: dict[str, _Parts] = {}
    pending: dict[str, tuple[list[int], list[bytes]]] = {}
    held: dict[str, int] = {}  # payload bytes pending, by topic

    def flush(name: str) -> None:
        times, raws = pending.pop(name)
        parts[name].add(np.array(times, np.int64), Payloads.of(raws), f"topic {name}")

    for done, m in enumerate(iter_messages(path, wanted), start=1):
        if m.topic not in parts:
            enc: Encoding = getattr(m, "encoding", "cdr")
            parts[m.topic] = _Parts(m.topic, m.msgtype, enc, decoders.get(m.topic))
        times, raws = pending.setdefault(m.topic, ([], []))
        times.append(int(m.log_time_ns))
        raws.append(m.raw)
        held[m.topic] = held.get(m.topic, 0) + len(m.raw)
        if len(raws) >= SLICE or held[m.topic] >= SLICE_BYTES:
            flush(m.topic)
            held[m.topic] = 0
        if progress is not None and done % SLICE == 0:
            progress(done, 0)
    for name in list(pending):
        flush(name)
    return {name: p.topic() for name, p in parts.items()}


# ---------------------------------------------------------------------- MCAP, chunk by chunk
def _read_mcap(
    path: Path,
    wanted: set[str],
    parts: dict[str, _Parts],
    progress: Progress | None,
    auto: bool,
    decoders: Decoders,
) -> None:
    summary = summary_of(path)
    stats = summary.statistics
    span = 0.0 if stats is None else (stats.message_end_time - stats.message_start_time) * 1e-9
    if auto and span < PROGRESS_MIN_S:
        progress = None
    channels = {
        cid: ch
        for cid, ch in summary.channels.items()
        if ch.topic in wanted and ch.message_encoding == "cdr"
    }
    if len(channels) < sum(1 for ch in summary.channels.values() if ch.topic in wanted):
        raise NotIndexed  # another message encoding: the message path decides
    for ch in channels.values():
        schema = summary.schemas.get(ch.schema_id)
        name = schema.name if schema is not None else ""
        if ch.topic not in parts:
            parts[ch.topic] = _Parts(ch.topic, name, "cdr", decoders.get(ch.topic))
    chunks = checked_chunks(path, summary)
    total = sum(c.chunk_length for c in chunks)
    done = 0
    with path.open("rb") as fh:
        for c in chunks:
            mine = {cid: off for cid, off in c.message_index_offsets.items() if cid in channels}
            done += c.chunk_length
            if mine:
                fh.seek(c.chunk_start_offset)
                record = fh.read(c.chunk_length + c.message_index_length)
                _chunk(path, c, record, mine, channels, parts)
            if progress is not None:
                progress(done, total)


def _chunk(
    path: Path,
    c: Any,
    record: bytes,
    mine: dict[int, int],
    channels: dict[int, Any],
    parts: dict[str, _Parts],
) -> None:
    """One chunk record (and its message indexes after it): each wanted channel's payloads."""
    for cid, times, payloads in cut(path, c, record, mine):
        topic = channels[cid].topic
        parts[topic].add(times, payloads, f"topic {topic}")


# ---------------------------------------------------------------------- ROS 1 .bag
def _gather_u32(buf: NDArray[np.uint8], at: IntArray) -> IntArray:
    """Little-endian uint32 at each offset ``at`` of ``buf``."""
    idx = at[:, None] + np.arange(4)
    return np.ascontiguousarray(buf[idx]).view("<u4")[:, 0].astype(np.int64)


def _read_bag(
    path: Path,
    wanted: set[str],
    parts: dict[str, _Parts],
    progress: Progress | None,
    decoders: Decoders,
) -> None:
    """A ROS 1 bag (format 2.0) through its index, chunk by chunk."""
    from rosbags.rosbag1 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags' ReaderError and OS errors: one line either way
        raise LogError(
            describe(
                f"log {path}",
                "a complete, indexed ROS 1 bag (format 2.0)",
                f"{type(exc).__name__}: {exc}",
                "re-record it, or run `rosbag reindex` on it (a recorder killed mid-write "
                "leaves a bag without its index)",
            )
        ) from exc
    try:
        conns = {c.id: c for c in reader.connections if c.topic in wanted}
        by_chunk: dict[int, dict[int, list[tuple[int, int]]]] = {}
        for cid, c in conns.items():
            if c.topic not in parts:
                parts[c.topic] = _Parts(c.topic, c.msgtype, "ros1", decoders.get(c.topic))
            elif parts[c.topic].msgtype != c.msgtype:
                raise NotIndexed  # two types on one topic: the message path refuses it
            for e in reader.indexes.get(cid, []):
                by_chunk.setdefault(e.chunk_pos, {}).setdefault(cid, []).append((e.time, e.offset))
        total = sum(reader.chunks[pos].datasize for pos in by_chunk) or 1
        done = 0
        with path.open("rb") as fh:
            for pos in sorted(by_chunk):
                chunk = reader.chunks[pos]
                fh.seek(chunk.datapos)
                try:
                    data = bytes(chunk.decompressor(fh.read(chunk.datasize)))
                except Exception as exc:
                    raise unreadable(path, exc) from exc
                buf = np.frombuffer(data, dtype=np.uint8)
                for cid, entries in sorted(by_chunk[pos].items()):
                    _bag_messages(path, data, buf, entries, parts[conns[cid].topic])
                done += chunk.datasize
                if progress is not None:
                    progress(done, total)
    finally:
        reader.close()


def _bag_messages(
    path: Path,
    data: bytes,
    buf: NDArray[np.uint8],
    entries: list[tuple[int, int]],
    part: _Parts,
) -> None:
    """One connection's messages in one decompressed chunk: a record is a uint32 header
    length, the header (``op=0x02`` for message data), a uint32 data length, the data."""
    arr = np.array(sorted(entries, key=lambda e: e[0]), dtype=np.int64).reshape(-1, 2)
    times, offsets = arr[:, 0], arr[:, 1]
    if offsets.size == 0:
        return
    if offsets.max() + 4 > buf.size:
        raise unreadable(path, ValueError("an index entry points past its chunk"))
    header = _gather_u32(buf, offsets)
    if np.any(offsets + 8 + header > buf.size):
        raise unreadable(path, ValueError("a record runs past its chunk"))
    for off, n in zip(offsets.tolist(), header.tolist(), strict=True):
        if data.find(b"op=\x02", off + 4, off + 4 + n) < 0:
            raise NotIndexed  # a connection record first, or worse: the message path decides
    length = _gather_u32(buf, offsets + 4 + header)
    start = offsets + 8 + header
    if np.any(start + length > buf.size):
        raise unreadable(path, ValueError("a message runs past its chunk"))
    part.add(times, Payloads(buf, start, length), f"topic {part.name}")
