"""The first messages of a log's topics, for the topic search before a log is read
(:func:`amsfe_sym.logs.plan.plan_log`, :func:`~amsfe_sym.logs.plan.read_config`;
docs/how-to/logs.md, "Speed").

An indexed MCAP (a ``.mcap``, a rosbag2 folder of one) is cut with numpy from the fewest
chunks that hold them (:mod:`amsfe_sym.logs.stream`'s chunk cutter), where ``mcap``'s reader
parsed every record of a chunk in Python and ``rosbags`` opened the folder each time; any
other log is read message by message (:func:`amsfe_sym.logs.source.first_payloads`), with
the same result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from amsfe_sym.arrays import IntArray
from amsfe_sym.logs.chunks import NotIndexed, checked_chunks, cut, summary_of
from amsfe_sym.logs.source import TopicData, TopicInfo, direct_mcap, log_topics
from amsfe_sym.logs.source import first_payloads as by_message

__all__ = ["first_messages", "first_payloads"]


def first_payloads(
    path: Path, topics: set[str], infos: dict[str, TopicInfo] | None = None, count: int = 1
) -> dict[str, TopicData]:
    """:func:`amsfe_sym.logs.source.first_payloads` (the first ``count`` payloads of each
    of ``topics``, the same result), cut with numpy from an indexed MCAP's first chunks
    (:func:`first_messages`); any other log is read message by message, as there."""
    infos = infos if infos is not None else log_topics(path)
    wanted = {t for t in topics if t in infos}
    file = direct_mcap(path)
    cut = first_messages(file, wanted, count) if file is not None and wanted else None
    if cut is None:
        return by_message(path, wanted, infos, count)
    return {
        t: TopicData(
            infos[t], np.asarray(cut.get(t, ([], []))[0], np.int64), cut.get(t, ([], []))[1]
        )
        for t in wanted
    }


def first_messages(
    path: Path, topics: set[str], count: int = 1
) -> dict[str, tuple[list[int], list[bytes]]] | None:
    """The first ``count`` messages (log times [ns], payloads) of each of ``topics`` in the
    indexed MCAP file ``path``, in log-time order (ties: file order), as ``mcap``'s reader
    gives them; None for a file without a summary or message indexes (the caller reads it
    message by message).

    Chunks are taken in order of their first log time, only those holding a topic still
    short of its messages, until no chunk left can hold an earlier one: a log's first
    chunk for a topic's first message, where ``mcap``'s reader parsed every record of it in
    Python (20-40 ms for a 1 MB chunk; docs/how-to/logs.md, "Speed").

    Raises:
        LogError: unreadable or damaged.
    """
    try:
        summary = summary_of(path)
        chunks = checked_chunks(path, summary)
    except NotIndexed:
        return None
    channels = {cid: ch.topic for cid, ch in summary.channels.items() if ch.topic in topics}
    found: dict[str, tuple[list[IntArray], list[list[bytes]]]] = {
        t: ([], []) for t in set(channels.values())
    }

    def settled(topic: str, start: int) -> bool:
        parts = found[topic][0]
        have = np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
        return have.size >= count and int(have[count - 1]) < start

    with path.open("rb") as fh:
        for c in sorted(chunks, key=lambda c: (c.message_start_time, c.chunk_start_offset)):
            mine = {
                cid: off
                for cid, off in c.message_index_offsets.items()
                if cid in channels and not settled(channels[cid], c.message_start_time)
            }
            if not mine:
                continue
            fh.seek(c.chunk_start_offset)
            record = fh.read(c.chunk_length + c.message_index_length)
            for cid, times, payloads in cut(path, c, record, mine):
                k = min(count, len(times))
                found[channels[cid]][0].append(times[:k])
                found[channels[cid]][1].append(payloads[:k])
    out = {}
    for topic, (parts, raws) in found.items():
        t = np.concatenate(parts) if parts else np.zeros(0, np.int64)
        r = [x for part in raws for x in part]
        order = np.argsort(t, kind="stable")[:count]
        out[topic] = ([int(t[i]) for i in order], [r[i] for i in order])
    return out
