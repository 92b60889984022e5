"""Messages of a recorded log, without ROS: a rosbag2 folder (MCAP or sqlite3 storage, read
with ``rosbags``) or a plain ``.mcap`` file (read with ``mcap``, decoded with ``rosbags``'
CDR deserializers).  Why both: docs/logs.md, "Libraries".
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.decode import Encoding, deserialize, typestore

__all__ = ["Message", "iter_messages", "typestore"]


@dataclass(frozen=True)
class Message:
    """One decoded message.

    Attributes:
        topic: Its topic.
        msgtype: Its ROS 2 type, e.g. ``sensor_msgs/msg/JointState``.
        log_time_ns: When the recorder received it [ns] (the arrival time).
        raw: Its payload (decoded by :meth:`decode` once its type was checked, or in bulk
            per topic by :mod:`amsfe_sym.logs.decode`).
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


def _unreadable(path: Path, exc: BaseException) -> LogError:
    return LogError(
        describe(
            f"log {path}",
            "a complete rosbag2 folder or .mcap file",
            f"{type(exc).__name__}: {exc}",
            "re-record it, or check that the file was copied whole (a recorder killed "
            "mid-write leaves an MCAP without its summary section)",
        )
    )


def iter_messages(path: Path, topics: set[str]) -> Iterator[Message]:
    """The messages of ``topics`` in ``path``, in log-time order.

    Raises:
        LogError: not a log, unreadable or truncated.
    """
    if not path.exists():
        raise LogError(describe(f"log {path}", "an existing folder or file", "nothing", ""))
    if path.is_dir():
        yield from _rosbag2(path, topics)
    elif path.suffix == ".mcap":
        yield from _mcap(path, topics)
    else:
        raise LogError(
            describe(
                f"log {path}",
                "a rosbag2 folder (with metadata.yaml) or a .mcap file",
                f"a {path.suffix or 'plain'} file",
                "pass the bag's folder",
            )
        )


def _rosbag2(path: Path, topics: set[str]) -> Iterator[Message]:
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises its own and OS errors: one line either way
        raise _unreadable(path, exc) from exc
    try:
        conns = [c for c in reader.connections if c.topic in topics]
        if not conns:  # (rosbags reads every connection when given none)
            return
        try:
            for conn, t, raw in reader.messages(connections=conns):
                yield Message(conn.topic, conn.msgtype, int(t), bytes(raw))
        except Exception as exc:
            raise _unreadable(path, exc) from exc
    finally:
        reader.close()


def _mcap(path: Path, topics: set[str]) -> Iterator[Message]:
    from mcap.reader import make_reader

    try:
        with path.open("rb") as fh:
            reader = make_reader(fh)
            for schema, channel, message in reader.iter_messages(topics=sorted(topics)):
                name = schema.name if schema is not None else ""
                yield Message(channel.topic, name, int(message.log_time), bytes(message.data))
    except LogError:
        raise
    except Exception as exc:
        raise _unreadable(path, exc) from exc
