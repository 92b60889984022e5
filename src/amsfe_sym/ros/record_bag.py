"""The bag a node's record streams to (:mod:`amsfe_sym.ros.record`): a rosbag2 folder (MCAP)
claimed with a lock file before the node starts, written as a series of complete MCAP files
by one writer thread, its ``metadata.yaml`` rewritten atomically after each, so a SIGKILL
leaves a bag readable up to its last segment, its metadata saying ``amsfe.record:
unfinished``; and the one-line refusals of a path that holds
another writer's record.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from amsfe_sym.core.folders import MARKER, pid_alive
from amsfe_sym.core.interrupts import wait_held
from amsfe_sym.core.jsonfile import to_json
from amsfe_sym.core.ledger import resolved
from amsfe_sym.errors import RunFolderError, describe

__all__ = ["LOCK", "Message", "Row", "SegmentedBag", "record_state", "refuse_locked"]

#: The lock file of a record being written (holds the writer's pid).
LOCK = ".amsfe-record.lock"

#: One message of the record: (topic, message type, stamp ns, the message's data).
Row = tuple[str, str, int, tuple[Any, ...]]

#: Builds the message (``rosbags`` type) of a row's type and data.
Message = Callable[[str, tuple[Any, ...]], Any]


class SegmentedBag:
    """A rosbag2 folder (MCAP) written as a series of complete MCAP files, its
    ``metadata.yaml`` rewritten atomically after each (module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.segments = 0  # segments handed to the writer
        self._written = 0  # segments written
        self._jobs: queue.Queue[tuple[list[Row], Callable[[], Message]] | None]
        self._jobs = queue.Queue(maxsize=2)  # bounded: the node waits rather than piling up
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._files: list[dict[str, Any]] = []
        self._topics: dict[str, dict[str, Any]] = {}  # name -> topic_metadata + count
        self._custom = {"amsfe.record": "unfinished", "amsfe.writer_pid": str(os.getpid())}

    @classmethod
    def claim(cls, out: Path) -> SegmentedBag:
        """Create ``out`` with its lock file (``O_EXCL``, the pid) and an empty metadata."""
        path = resolved(out)
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            path.mkdir()
        except FileExistsError:
            raise RunFolderError(_taken(path)) from None
        try:
            fd = os.open(path / LOCK, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:  # (created between the two: another writer's)
            raise RunFolderError(_taken(path)) from None
        with os.fdopen(fd, "w") as fh:
            fh.write(f"{os.getpid()}\n")
        (path / MARKER).write_text("written by amsfe_sym (amsfe node --record)\n")
        bag = cls(path)
        bag._write_metadata()
        return bag

    def write_segment(self, rows: Iterable[Row], maker: Callable[[], Message]) -> None:
        """Hand ``rows`` to the writer thread, which writes them as the next MCAP file and
        then the metadata listing it (serializing a tick costs ~0.8 ms of Python: done
        beside the node's loop, not in it; at most two segments wait); ``maker()`` builds
        the message builder (once, in the writer thread: the /tf one loads the robot)."""
        if self._error is not None:
            raise self._error
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, name="amsfe-record", daemon=True)
            self._thread.start()
        self.segments += 1
        self._put((list(rows), maker))

    def _put(self, job: tuple[list[Row], Callable[[], Message]] | None) -> None:
        """Queue ``job`` for the writer, waiting for room with Ctrl-C and SIGTERM held
        between waits (:func:`~amsfe_sym.core.interrupts.wait_held`: raised inside the
        queue's lock, an interruption would leave it held and the writer, then the drain,
        waiting forever)."""

        def put(timeout: float) -> bool:
            try:
                self._jobs.put(job, timeout=timeout)
            except queue.Full:
                return False
            return True

        wait_held(put)

    def _work(self) -> None:
        message: Message | None = None
        while (job := self._jobs.get()) is not None:
            if self._error is None:
                try:
                    rows, maker = job
                    message = maker() if message is None else message
                    self._write(rows, message)
                except BaseException as exc:  # raised in the node's thread, at its next call
                    self._error = exc

    def _drain(self) -> None:
        """Wait for the writer thread to write every segment handed to it."""
        if self._thread is not None:
            self._put(None)
            thread = self._thread

            def joined(timeout: float) -> bool:
                thread.join(timeout)
                return not thread.is_alive()

            wait_held(joined)
            self._thread = None
        if self._error is not None:
            raise self._error

    def _write(self, rows: list[Row], message: Message) -> None:
        """Write ``rows`` as the next MCAP file, then the metadata listing it."""
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.metadata import dump_qos_v9

        from amsfe_sym.logs.source import typestore

        store = typestore()
        name = f"{self.path.name}_{self._written}"
        tmp = self.path / f".{name}.tmp"
        if tmp.exists():
            shutil.rmtree(tmp)
        writer = Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns: dict[str, Any] = {}
        counts: dict[str, int] = {}
        t_min, t_max = 2**63 - 1, 0
        try:
            for topic, msgtype, ns, data in rows:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
                writer.write(conns[topic], ns, store.serialize_cdr(message(msgtype, data), msgtype))
                counts[topic] = counts.get(topic, 0) + 1
                t_min, t_max = min(t_min, ns), max(t_max, ns)
        finally:
            writer.close()
        mcap = self.path / f"{name}.mcap"
        (tmp / f"{tmp.name}.mcap").replace(mcap)
        shutil.rmtree(tmp)
        for topic, c in conns.items():
            entry = self._topics.setdefault(
                topic,
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": c.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": dump_qos_v9([]),
                        "type_description_hash": c.digest,
                    },
                    "message_count": 0,
                },
            )
            entry["message_count"] += counts[topic]
        total = sum(counts.values())
        self._files.append(
            {
                "path": mcap.name,
                "starting_time": {"nanoseconds_since_epoch": t_min if total else 0},
                "duration": {"nanoseconds": max(0, t_max - t_min)},
                "message_count": total,
            }
        )
        self._written += 1
        self._write_metadata()

    def finish(self, reason: str, extra: dict[str, str]) -> None:
        """Wait for the segments handed over, mark the bag finished with ``reason`` and
        remove the lock."""
        self._drain()
        self._custom.update({"amsfe.record": "finished", "amsfe.end": reason, **extra})
        self._write_metadata()
        with contextlib.suppress(FileNotFoundError):
            (self.path / LOCK).unlink()

    def _write_metadata(self) -> None:
        starts = [
            f["starting_time"]["nanoseconds_since_epoch"] for f in self._files if f["message_count"]
        ]
        ends = [
            f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"]
            for f in self._files
            if f["message_count"]
        ]
        start = min(starts, default=0)
        info = {
            "version": 9,
            "storage_identifier": "mcap",
            "relative_file_paths": [f["path"] for f in self._files],
            "duration": {"nanoseconds": max(ends, default=0) - start},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(f["message_count"] for f in self._files),
            "topics_with_message_count": list(self._topics.values()),
            "compression_format": "",
            "compression_mode": "",
            "files": self._files,
            "custom_data": self._custom,
            "ros_distro": "rosbags",
        }
        tmp = self.path / "metadata.yaml.tmp"
        # JSON is YAML (1.2): rosbag2 and rosbags read it
        tmp.write_text(to_json({"rosbag2_bagfile_information": info}, indent=1) + "\n")
        tmp.replace(self.path / "metadata.yaml")


def _taken(path: Path) -> str:
    """The one line refusing a record path that exists."""
    lock = path / LOCK
    pid = None
    with contextlib.suppress(OSError, ValueError):
        pid = int(lock.read_text().split()[0])
    if pid is not None and pid_alive(pid):
        found = f"a record being written there by process {pid}"
        fix = "give each node its own --record folder"
    elif pid is not None:
        found = f"an unfinished record of process {pid}, which is no longer running"
        fix = "keep it (it is readable up to its last segment) and choose another --record"
    else:
        found = "an existing folder or file"
        fix = "choose another --record (a record is never written over)"
    return describe(f"--record {path}", "a new folder, one writer", found, fix)


def refuse_locked(path: Path) -> None:
    """Refuse, in one line, a ``--record`` path holding a record's lock file (a writer at
    work, or one that died: :func:`_taken`); anything else is left to
    :func:`~amsfe_sym.core.outputs.check_output`.

    Raises:
        RunFolderError: the lock file is there.
    """
    if (Path(path) / LOCK).exists():
        raise RunFolderError(_taken(resolved(path)))


def record_state(path: Path) -> dict[str, str]:
    """The ``amsfe.*`` keys of a record's metadata (``amsfe.record``: ``finished`` or
    ``unfinished``; ``amsfe.end``: why the node stopped); {} for a bag without them."""
    try:
        doc = json.loads((Path(path) / "metadata.yaml").read_text())
    except (OSError, ValueError):
        return {}
    custom = doc.get("rosbag2_bagfile_information", {}).get("custom_data") or {}
    return {k: str(v) for k, v in custom.items() if str(k).startswith("amsfe.")}
