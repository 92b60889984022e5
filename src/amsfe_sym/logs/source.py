"""The payloads of a recorded log, without ROS, topic by topic (docs/how-to/logs.md, "Containers").

Containers: a ROS 1 ``.bag`` (``rosbags``' AnyReader; payloads in the ROS 1 wire format), a
rosbag2 folder in MCAP or sqlite3 storage (``rosbags``), a plain ``.mcap`` file (``mcap``,
CDR or ROS 1 payloads).  Anything else (a JSON-encoded MCAP, a ``.db3`` file alone, a text
file) is refused in one line naming what was found.

What a reader gets: :func:`log_topics` (every topic with its type, encoding and count, from
the container's metadata), :func:`first_payloads` (the first few payloads of some topics, to
look at joint names before anything is read in full) and :func:`iter_messages` (payloads one
by one; :mod:`amsfe_sym.logs.stream` reads whole topics in bulk and falls back on it for
containers it does not cut itself).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.arrays import IntArray
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.chunks import unreadable
from amsfe_sym.logs.decode import Encoding, deserialize, typestore

__all__ = [
    "Message",
    "TopicData",
    "TopicInfo",
    "direct_mcap",
    "first_payloads",
    "iter_messages",
    "log_topics",
    "typestore",
]


@dataclass(frozen=True)
class Message:
    """One message (kept for callers that want one; the reader works on :class:`TopicData`).

    Attributes:
        topic: Its topic.
        msgtype: Its ROS 2 type name, e.g. ``sensor_msgs/msg/JointState`` (ROS 1 types are
            named the same way).
        log_time_ns: When the recorder received it [ns] (the arrival time).
        raw: Its payload.
        encoding: How ``raw`` is serialized: ``cdr`` (ROS 2) or ``ros1`` (a ROS 1 bag).
    """

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes
    encoding: Encoding = "cdr"

    def decode(self) -> Any:
        """The message as a ``rosbags`` dataclass.

        Raises:
            LogError: the bytes do not decode as the message's type (a corrupt message).
        """
        where = f"a {self.msgtype} message on {self.topic} at {self.log_time_ns} ns"
        return deserialize(self.raw, self.msgtype, self.encoding, where)


@dataclass(frozen=True)
class TopicInfo:
    """A topic as the container's metadata describes it.

    Attributes:
        topic: Its name.
        msgtype: Its message type (ROS 2 spelling; ``""`` when the container has no schema).
        encoding: ``cdr`` or ``ros1`` (what :mod:`amsfe_sym.logs.decode` reads), or what an
            MCAP channel says otherwise (``json``, ...: refused when a role needs the topic).
        count: Messages on it (None where the container does not say).
    """

    topic: str
    msgtype: str
    encoding: str
    count: int | None

    def payload_encoding(self, path: Path) -> Encoding:
        """The encoding as :mod:`amsfe_sym.logs.decode` takes it.

        Raises:
            LogError: neither CDR nor ROS 1 (e.g. a JSON-encoded MCAP channel).
        """
        if self.encoding == "cdr":
            return "cdr"
        if self.encoding == "ros1":
            return "ros1"
        raise LogError(
            describe(
                f"log {path}: topic {self.topic}",
                "messages encoded as cdr (ROS 2) or ros1",
                f"message encoding {self.encoding!r}",
                "record with ros2 bag record (-s mcap) or rosbag record, or convert the log to "
                "CDR (e.g. with the mcap CLI from a ROS 2 bag)",
            )
        )


@dataclass
class TopicData:
    """Every payload of one topic, in log-time order.

    Attributes:
        info: The topic.
        log_time_ns: Receive time of each payload [ns], (M,).
        raws: The payloads (decode with :mod:`amsfe_sym.logs.decode`).
    """

    info: TopicInfo
    log_time_ns: IntArray
    raws: list[bytes] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.raws)


def _unreadable(path: Path, exc: BaseException) -> LogError:
    return unreadable(path, exc, "a complete ROS 1 .bag, rosbag2 folder or .mcap file")


def _kind(path: Path) -> str:
    """``bag`` | ``rosbag2`` | ``mcap``, or a one-line refusal naming what ``path`` is."""
    if not path.exists():
        raise LogError(
            describe(
                f"log {path}",
                "an existing .bag, rosbag2 folder or .mcap",
                "nothing at that path",
                "check the path (a rosbag2 recording is the folder holding metadata.yaml)",
            )
        )
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "rosbag2"
        found = sorted(p.name for p in path.iterdir())[:5]
        raise LogError(
            describe(
                f"log {path}",
                "a rosbag2 folder (with metadata.yaml), a ROS 1 .bag or a .mcap file",
                f"a folder without metadata.yaml (holding {found})",
                "pass the bag's own folder or one .mcap / .bag file inside it",
            )
        )
    with path.open("rb") as fh:
        head = fh.read(13)
    if head.startswith(b"#ROSBAG V2.0"):
        return "bag"
    if head.startswith(b"\x89MCAP0\r\n"):
        return "mcap"
    what = {
        ".db3": "a rosbag2 sqlite3 database alone",
        ".bag": "a .bag without the ROS 1 bag header (#ROSBAG V2.0)",
        ".mcap": "a .mcap without the MCAP magic bytes",
    }.get(path.suffix, f"a {path.suffix or 'extension-less'} file starting with {head[:8]!r}")
    fix = {
        ".db3": "pass the folder holding it and its metadata.yaml",
    }.get(
        path.suffix,
        "convert it to a ROS 1 .bag, a rosbag2 folder or an .mcap (docs/how-to/logs.md)",
    )
    raise LogError(
        describe(
            f"log {path}", "a ROS 1 .bag, a rosbag2 folder (MCAP or sqlite3) or an .mcap", what, fix
        )
    )


def log_topics(path: Path) -> dict[str, TopicInfo]:
    """Every topic of the log at ``path`` with its type, encoding and message count.

    Raises:
        LogError: not a log of a supported container, unreadable, truncated, or a topic whose
            messages are neither CDR nor ROS 1 (e.g. a JSON-encoded MCAP).
    """
    kind = _kind(path)
    try:
        if kind == "mcap":
            return _mcap_topics(path)
        direct = _direct_mcap(path, kind)
        if direct is not None:
            found = _summary_topics(direct, rosbag2=True)
            if found is not None:
                return found
        return _rosbags_topics(path, kind)
    except LogError:
        raise
    except Exception as exc:  # rosbags / mcap raise their own and OS errors: one line
        raise _unreadable(path, exc) from exc


def direct_mcap(path: Path) -> Path | None:
    """The one MCAP file a log is (a ``.mcap``, or a rosbag2 folder holding exactly one and
    no sqlite3 database), read with ``mcap`` and :mod:`amsfe_sym.logs.stream`; else None."""
    kind = _kind(path)
    return path if kind == "mcap" else _direct_mcap(path, kind)


def _direct_mcap(path: Path, kind: str) -> Path | None:
    """The MCAP file of a rosbag2 folder that holds exactly one (and no sqlite3 database),
    read with ``mcap`` as a plain ``.mcap``: opening the folder with ``rosbags``'
    AnyReader (its import, ``metadata.yaml`` and every connection) took 40-150 ms each time
    the topics or a first message were looked up (docs/how-to/logs.md, "Speed").  None otherwise
    (``rosbags`` reads it, as before)."""
    if kind != "rosbag2" or any(path.glob("*.db3")):
        return None
    files = list(path.glob("*.mcap"))
    return files[0] if len(files) == 1 else None


def _rosbags_topics(path: Path, kind: str) -> dict[str, TopicInfo]:
    """:func:`log_topics` through ``rosbags``' AnyReader (ROS 1 bags, sqlite3 and split
    rosbag2 folders, an MCAP without a summary)."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        out: dict[str, TopicInfo] = {}
        enc = "ros1" if kind == "bag" else "cdr"
        for c in reader.connections:
            prev = out.get(c.topic)
            count = int(c.msgcount) + (prev.count or 0 if prev else 0)
            out[c.topic] = TopicInfo(c.topic, str(c.msgtype), enc, count)
        return out


def _mcap_topics(path: Path) -> dict[str, TopicInfo]:
    """The topics of a plain ``.mcap`` from its summary (refused without one)."""
    found = _summary_topics(path, rosbag2=False)
    if found is None:
        raise _unreadable(path, ValueError("no summary section"))
    return found


def _summary_topics(path: Path, rosbag2: bool) -> dict[str, TopicInfo] | None:
    """The topics of an MCAP file from its summary, None without one.  ``rosbag2``: the
    file of a rosbag2 folder, described as ``rosbags`` does (every payload CDR, a channel
    without messages counted 0, the channels of one topic added up)."""
    from mcap.reader import make_reader

    with path.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        if summary is None:
            return None
        stats = summary.statistics
        counts = stats.channel_message_counts if stats else {}
        out: dict[str, TopicInfo] = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            name = _ros2_name(schema.name if schema is not None else "")
            if not rosbag2:
                enc = str(ch.message_encoding)
                out[ch.topic] = TopicInfo(ch.topic, name, enc, counts.get(cid))
                continue
            prev = out.get(ch.topic)
            count = None if stats is None else counts.get(cid, 0)
            if prev is not None and count is not None:
                count += prev.count or 0
            out[ch.topic] = TopicInfo(ch.topic, name, "cdr", count)
        return out


def _ros2_name(name: str) -> str:
    """``sensor_msgs/JointState`` (ROS 1 spelling) -> ``sensor_msgs/msg/JointState``."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


def _payloads(path: Path, topics: set[str]) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log time [ns], payload) of ``topics``, in log-time order."""
    kind = _kind(path)
    if not topics:
        return
    try:
        direct = path if kind == "mcap" else _direct_mcap(path, kind)
        if direct is not None:
            yield from _mcap_payloads(direct, topics)
        else:
            yield from _rosbags_payloads(path, topics)
    except LogError:
        raise
    except Exception as exc:
        raise _unreadable(path, exc) from exc


def _mcap_payloads(path: Path, topics: set[str]) -> Iterator[tuple[str, int, bytes]]:
    """:func:`_payloads` of one MCAP file through ``mcap``'s reader."""
    from mcap.reader import make_reader

    with path.open("rb") as fh:
        for _s, channel, message in make_reader(fh).iter_messages(topics=sorted(topics)):
            yield channel.topic, int(message.log_time), bytes(message.data)


def _rosbags_payloads(path: Path, topics: set[str]) -> Iterator[tuple[str, int, bytes]]:
    """:func:`_payloads` through ``rosbags``' AnyReader."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        if not conns:  # (rosbags reads every connection when given none)
            return
        for conn, t, raw in reader.messages(connections=conns):
            yield conn.topic, int(t), bytes(raw)


def first_payloads(
    path: Path, topics: set[str], infos: dict[str, TopicInfo] | None = None, count: int = 1
) -> dict[str, TopicData]:
    """The first ``count`` payloads of each of ``topics`` (stops reading once every topic
    has them, or at the end of the log), message by message
    (:func:`amsfe_sym.logs.stream.first_payloads` cuts an indexed MCAP's with numpy)."""
    infos = infos if infos is not None else log_topics(path)
    wanted = {t for t in topics if t in infos}
    raws: dict[str, list[bytes]] = {t: [] for t in wanted}
    times: dict[str, list[int]] = {t: [] for t in wanted}
    left = set(wanted)
    if left:
        for topic, t, raw in _payloads(path, wanted):
            if topic in left:
                raws[topic].append(raw)
                times[topic].append(t)
                if len(raws[topic]) >= count:
                    left.discard(topic)
            if not left:
                break
    return {t: TopicData(infos[t], np.asarray(times[t], dtype=np.int64), raws[t]) for t in wanted}


def iter_messages(path: Path, topics: set[str]) -> Iterator[Message]:
    """The messages of ``topics`` in ``path``, in log-time order, one object each (for small
    uses; :func:`read_topics` holds only the payloads).

    Raises:
        LogError: not a log, unreadable or truncated.
    """
    infos = log_topics(path)
    for topic, t, raw in _payloads(path, {t for t in topics if t in infos}):
        info = infos[topic]
        yield Message(topic, info.msgtype, t, raw, info.payload_encoding(path))
