"""MCAP chunks cut with numpy (docs/how-to/logs.md, "Speed"): the summary's chunk indexes checked
against the file, a chunk decompressed once (none, zstd, lz4) and each wanted channel's
payloads located at the offsets its message index lists, no Python object per message.
:mod:`amsfe_sym.logs.stream` reads whole topics with it, :mod:`amsfe_sym.logs.firsts` the
first messages of a few."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import IntArray
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.layout import Payloads

__all__ = [
    "MAX_CHUNK",
    "MESSAGE_HEADER",
    "NotIndexed",
    "checked_chunks",
    "cut",
    "decompress",
    "gather_u64",
    "summary_of",
    "u64",
    "unreadable",
]


class NotIndexed(Exception):  # noqa: N818 - a signal to take the other path, not an error
    """The MCAP has no summary with chunk and message indexes."""


MESSAGE_HEADER = 1 + 8 + 2 + 4 + 8 + 8  # opcode, length, channel, sequence, two times
#: The largest decompressed chunk taken [bytes] (recorders write ~1-10 MB; a larger figure in
#: a summary is damage, not a chunk to allocate).
MAX_CHUNK = 1 << 31


def unreadable(path: Path, exc: BaseException, expected: str = "a complete MCAP file") -> LogError:
    """The one error of a log that cannot be read (``expected``: what it should have been)."""
    return LogError(
        describe(
            f"log {path}",
            expected,
            f"{type(exc).__name__}: {exc}",
            "re-record it, or check that the file was copied whole (a recorder killed "
            "mid-write leaves an MCAP without its summary section)",
        )
    )


#: Summaries parsed, by (file, inode, size, modification time, the file's last 40 bytes: the
#: footer with the summary's offset and CRC): a log's summary is asked for by the first
#: messages' search and by the read, and ``mcap`` parses it in Python (0.2 s for the 607
#: chunks of a 60 s log with 30 Hz images).  The last few files only.
_SUMMARIES: dict[tuple[str, int, int, int, bytes], Any] = {}


def _summary_key(path: Path) -> tuple[str, int, int, int, bytes] | None:
    try:
        st = path.stat()
        with path.open("rb") as fh:
            fh.seek(max(st.st_size - 40, 0))
            tail = fh.read(40)
    except OSError:
        return None  # (opening it says why)
    return (str(path.resolve()), st.st_ino, st.st_size, st.st_mtime_ns, tail)


def summary_of(path: Path) -> Any:
    from mcap.reader import make_reader

    key = _summary_key(path)
    if key is not None and key in _SUMMARIES:
        return _SUMMARIES[key]
    try:
        with path.open("rb") as fh:
            summary = make_reader(fh).get_summary()
    except Exception as exc:  # mcap raises its own and OS errors: one line either way
        raise unreadable(path, exc) from exc
    if summary is None or (not summary.chunk_indexes and summary.channels):
        raise NotIndexed
    if key is not None:
        while len(_SUMMARIES) >= 4:
            del _SUMMARIES[next(iter(_SUMMARIES))]
        _SUMMARIES[key] = summary
    return summary


def decompress(path: Path, compression: str, data: bytes, size: int) -> bytes:
    try:
        if compression == "":
            return data
        if compression == "zstd":
            import zstandard

            return bytes(zstandard.ZstdDecompressor().decompress(data, max_output_size=size))
        if compression == "lz4":
            import lz4.frame  # type: ignore[import-untyped]

            return bytes(lz4.frame.decompress(data))
    except Exception as exc:
        raise unreadable(path, exc) from exc
    raise unreadable(path, ValueError(f"chunk compression {compression!r}"))


def u64(buf: bytes, at: int) -> int:
    return int.from_bytes(buf[at : at + 8], "little")


def checked_chunks(path: Path, summary: Any) -> list[Any]:
    """The summary's chunk indexes in file order, each checked to lie inside the file (the
    summary's numbers decide what is read); :class:`NotIndexed` without message indexes."""
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    if any(not c.message_index_offsets for c in chunks if c.uncompressed_size):
        raise NotIndexed
    size = path.stat().st_size
    for c in chunks:
        end = c.chunk_start_offset + c.chunk_length
        index_end = end + c.message_index_length
        if not (
            0 < c.chunk_start_offset < end <= index_end <= size
            and all(end <= off < index_end for off in c.message_index_offsets.values())
            and 0 <= c.uncompressed_size <= MAX_CHUNK
        ):
            raise unreadable(path, ValueError(f"a chunk index out of the file: {c}"))
    return chunks


def cut(
    path: Path, c: Any, record: bytes, mine: dict[int, int]
) -> list[tuple[int, IntArray, Payloads]]:
    """(channel, log times, payloads) of each channel of ``mine`` (channel id -> offset of
    its message index) in one chunk record, each in log-time order (ties: file order)."""
    out = []
    try:
        at = 1 + 8 + 8 + 8 + 8 + 4  # opcode, length, start, end, uncompressed size, crc
        n = int.from_bytes(record[at : at + 4], "little")
        compression = record[at + 4 : at + 4 + n].decode()
        at += 4 + n
        size = u64(record, at)
        data = decompress(path, compression, record[at + 8 : at + 8 + size], c.uncompressed_size)
        buf = np.frombuffer(data, dtype=np.uint8)
        for cid, index_at in sorted(mine.items()):
            rel = index_at - c.chunk_start_offset
            if record[rel] != 0x07:
                raise ValueError(f"no message index at {index_at}")
            count = int.from_bytes(record[rel + 11 : rel + 15], "little")
            pairs = np.frombuffer(record, dtype="<u8", count=count // 8, offset=rel + 15)
            times = pairs[0::2].astype(np.int64)
            offsets = pairs[1::2].astype(np.int64)
            if offsets.size and (offsets.min() < 0 or offsets.max() + MESSAGE_HEADER > buf.size):
                raise ValueError("a message index points past its chunk")
            lengths = gather_u64(buf, offsets + 1) - (MESSAGE_HEADER - 9)
            if np.any(buf[offsets] != 0x05) or np.any(lengths < 0):
                raise ValueError("a message index points at no message")
            if np.any(offsets + MESSAGE_HEADER + lengths > buf.size):
                raise ValueError("a message runs past its chunk")
            order = np.argsort(times, kind="stable")
            out.append(
                (cid, times[order], Payloads(buf, offsets[order] + MESSAGE_HEADER, lengths[order]))
            )
    except LogError:
        raise
    except Exception as exc:
        raise unreadable(path, exc) from exc
    return out


def gather_u64(buf: NDArray[np.uint8], at: IntArray) -> IntArray:
    """Little-endian uint64 at each offset ``at`` of ``buf``."""
    idx = at[:, None] + np.arange(8)
    return np.ascontiguousarray(buf[idx]).view("<u8")[:, 0].astype(np.int64)
