"""Many messages into a rosbag2 being written by ``rosbags`` (MCAP storage, no compression)
at once: the bytes ``rosbags``' ``Writer.write`` would write one call at a time
(docs/how-to/logs.md, "Speed").

``rosbags``' MCAP writer builds each message record with a few ``BytesIO`` writes and each
message index entry with two more (~3 us a message on an idle machine: 0.36 s for the
120,002 messages of a 60 s Panda's estimates).  Here the records of a chunk are built with
numpy, the chunk is closed as ``rosbags`` closes it (a chunk ends after the message that
takes it past 1 MiB; message indexes in order of each channel's first message in the
chunk), and the writer's counters are moved on, so that ``Writer.close`` writes the same
summary and ``metadata.yaml``.  It relies on ``rosbags``' writer internals (0.11):
:func:`write_many` checks them and returns False when they are not as expected (the caller
then writes message by message); ``tests/test_bulk_write.py`` requires the same bytes.
"""

from __future__ import annotations

from collections.abc import Sequence
from io import BytesIO
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["write_many"]

#: A message record's bytes before its payload: opcode, record length, channel, sequence,
#: log time, publish time.
_HEADER = np.dtype(
    [("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("seq", "<u4"), ("log", "<u8"),
     ("pub", "<u8")]
)  # fmt: skip
#: ``rosbags`` closes a chunk once it holds more than this [bytes].
_CHUNK = 2**20


def _usable(writer: Any) -> bool:
    """Whether ``writer`` is a ``rosbags`` rosbag2 writer into uncompressed MCAP storage whose
    open chunk holds no message yet (the state :func:`write_many` knows how to continue)."""
    storage = getattr(writer, "storage", None)
    chunk = getattr(storage, "chunk", None)
    return (
        type(storage).__name__ == "McapWriter"
        and getattr(storage, "compression", None) == ""
        and getattr(getattr(writer, "compression_mode", None), "name", None) == "NONE"
        and chunk is not None
        and not getattr(chunk, "msgs", True)
        and all(hasattr(storage, a) for a in ("bio", "chunks", "channel_stats"))
        and all(hasattr(writer, a) for a in ("counts", "min_timestamp", "max_timestamp"))
    )


def write_many(
    writer: Any,
    connections: Sequence[Any],
    stamps: NDArray[np.int64],
    payloads: Sequence[list[bytes]],
) -> bool:
    """Write, for each log time ``stamps[k]`` [ns], ``payloads[j][k]`` on ``connections[j]``
    (in that order: what ``writer.write(connections[j], stamps[k], payloads[j][k])`` in a
    loop over k, then j, writes).  False (nothing written) when ``writer`` is not in a
    state this module knows."""
    if not _usable(writer) or not len(stamps):
        return False
    storage = writer.storage
    J, K = len(connections), len(stamps)
    cids = np.tile(np.asarray([c.id for c in connections], dtype=np.int64), K)
    times = np.repeat(np.asarray(stamps, dtype=np.int64), J)
    flat = [p for row in zip(*payloads, strict=True) for p in row]
    lengths = np.fromiter((len(p) for p in flat), dtype=np.int64, count=len(flat))
    sizes = _HEADER.itemsize + lengths
    start = 0
    while start < len(flat):
        pos = storage.chunk.bio.tell()
        ends = pos + np.cumsum(sizes[start:])
        over = np.flatnonzero(ends > _CHUNK)
        stop = start + (int(over[0]) + 1 if over.size else len(ends))
        _chunk(writer, cids[start:stop], times[start:stop], flat[start:stop], sizes[start:stop])
        if over.size:
            _close_chunk(storage)
        start = stop
    for cid, parts in storage.chunk.msgs.items():  # the open chunk: entries as rosbags keeps them
        t = np.concatenate([p[0] for p in parts]).tolist()
        o = np.concatenate([p[1] for p in parts]).tolist()
        storage.chunk.msgs[cid] = list(zip(t, o, strict=True))
    for c in connections:
        storage.channel_stats[c.id] += K
        writer.counts[c.id] += K
    lo, hi = int(np.min(stamps)), int(np.max(stamps))
    storage.message_start_time = min(lo, storage.message_start_time)
    storage.message_end_time = max(hi, storage.message_end_time)
    writer.min_timestamp = min(lo, writer.min_timestamp)
    writer.max_timestamp = max(hi, writer.max_timestamp)
    return True


def _chunk(
    writer: Any,
    cids: NDArray[np.int64],
    times: NDArray[np.int64],
    payloads: list[bytes],
    sizes: NDArray[np.int64],
) -> None:
    """Append message records to the open chunk and note their index entries."""
    chunk = writer.storage.chunk
    pos = chunk.bio.tell()
    head = np.zeros(len(payloads), dtype=_HEADER)
    head["op"] = 0x05
    head["length"] = sizes - 9  # the record's length after its opcode and length
    head["channel"] = cids
    head["log"] = times
    head["pub"] = times
    raw = head.tobytes()
    n = _HEADER.itemsize
    chunk.bio.write(
        b"".join(b for i, p in enumerate(payloads) for b in (raw[i * n : (i + 1) * n], p))
    )
    offsets = pos + np.concatenate([[0], np.cumsum(sizes)[:-1]])
    for cid in _first_seen(cids):
        mine = cids == cid
        chunk.msgs[int(cid)].append((times[mine], offsets[mine]))
    chunk.message_start_time = min(int(times.min()), chunk.message_start_time)
    chunk.message_end_time = max(int(times.max()), chunk.message_end_time)


def _first_seen(values: NDArray[np.int64]) -> list[int]:
    """Distinct values in order of first appearance."""
    uniq, first = np.unique(values, return_index=True)
    return [int(u) for u in uniq[np.argsort(first)]]


def _close_chunk(storage: Any) -> None:
    """``rosbags``' ``McapWriter.close_chunk`` with the index entries as arrays (the chunk's
    ``msgs``: channel -> [(times, offsets)]) and no compression."""
    from rosbags.rosbag2.storage_mcap import (
        PendingChunk,
        write_record,
        write_string,
        write_uint32,
        write_uint64,
    )

    chunk = storage.chunk
    data = chunk.bio.getvalue()
    rec = BytesIO()
    write_uint64(rec, chunk.message_start_time)
    write_uint64(rec, chunk.message_end_time)
    write_uint64(rec, len(data))
    write_uint32(rec, 0)
    write_string(rec, storage.compression)
    write_uint64(rec, len(data))
    rec.write(data)
    chunk_start = storage.bio.tell()
    write_record(storage.bio, 0x06, rec)
    chunk_end = storage.bio.tell()
    offsets = []
    for cid, parts in chunk.msgs.items():
        offsets.append((cid, storage.bio.tell()))
        t = np.concatenate([p[0] for p in parts])
        o = np.concatenate([p[1] for p in parts])
        pairs = np.empty(2 * t.size, dtype="<u8")
        pairs[0::2], pairs[1::2] = t, o
        rec = BytesIO()
        rec.write(int(cid).to_bytes(2, "little"))
        write_uint32(rec, t.size * 16)
        rec.write(pairs.tobytes())
        write_record(storage.bio, 0x07, rec)
    rec = BytesIO()
    write_uint64(rec, chunk.message_start_time)
    write_uint64(rec, chunk.message_end_time)
    write_uint64(rec, chunk_start)
    write_uint64(rec, chunk_end - chunk_start)
    write_uint32(rec, len(offsets) * 10)
    for cid, offset in offsets:
        rec.write(int(cid).to_bytes(2, "little"))
        write_uint64(rec, offset)
    write_uint64(rec, storage.bio.tell() - chunk_end)
    write_string(rec, storage.compression)
    write_uint64(rec, len(data))
    write_uint64(rec, len(data))
    storage.chunks.append(rec)
    storage.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), type(chunk.msgs)(list))
