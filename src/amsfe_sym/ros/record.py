"""``amsfe node --record DIR``: what the node received and published, as a rosbag2 in MCAP
in the layout of ``amsfe simulate --bag`` (:mod:`amsfe_sym.logs.write`), so that
``amsfe estimate DIR`` reproduces the node's estimates and Foxglove shows the session.

Topics and times (ns, the samples' own stamps; a frame is logged at the tick that fused it,
its arrival): the encoders, camera frames (stamp = exposure), the applied torque (JointState
effort: the effort topic's, or the node's command; with the effort on the encoders' topic, in
the encoders' JointState of its tick, one message a tick as a driver's ``/joint_states``), the
truth and ``/joint_states`` (true q, qd; not when that is the encoders' or the effort's topic)
when a simulated arm sends it, ``/amsfe/config`` (robot, scenario, estimator: what
``amsfe estimate`` needs), ``/robot_description`` (the URDF), and the outputs: estimate,
estimate_std, theta, diagnostics, commands (the hold command last), and ``/tf`` as
``simulate --bag`` has it (world -> every link of the estimated arm, ``est/``-prefixed, and
of the true one when a simulated arm sends its truth; at
:data:`~amsfe_sym.logs.write.TF_RATE_HZ`, by Pinocchio when the record is written, with a
URDF).

**Every topic is the value of its own tick.**  The truth carries no stamp (a
Float64MultiArray) and DDS does not order deliveries across topics, so a truth is matched to
its tick by the publishers' source timestamps, as the frames are: the simulated arm sends the
truth of tick k after the encoder sample of k - 1 and before the one of k
(:meth:`NodeRecord.truth_sent`).  A truth that arrives after its tick's sample waits for it;
one that never comes leaves its tick without a truth (counted in the metadata), never with
another tick's.

**Streamed to disk, one writer**.  :meth:`NodeRecord.open` claims
the folder before the node starts: it is created (refused in one line when it exists) and
holds a lock file made with ``O_EXCL`` holding the writer's pid, so a second node naming the
same path is refused before it starts, also when the first one died (its lock stays: a dead
writer's record is not reused, it is named as unfinished).  Every :data:`SEGMENT_TICKS` ticks
the ticks older than :data:`LAG_TICKS` are written as one complete MCAP file of the bag
(``<name>_<i>.mcap``) and ``metadata.yaml`` is rewritten atomically to list it, so memory is
bounded and a SIGKILL leaves a bag readable up to the last segment, its metadata saying
``amsfe.record: unfinished``.  :meth:`NodeRecord.write` (every exit of the node: the end, a
hold, a signal) writes the rest and says ``finished`` with the reason the node stopped
(``amsfe.end``).  The bag and its lock: :mod:`amsfe_sym.ros.record_bag`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.ledger import note_written, resolved
from amsfe_sym.core.toml import dump_toml
from amsfe_sym.errors import RunFolderError, describe
from amsfe_sym.logs.write import TF_RATE_HZ
from amsfe_sym.ros.record_bag import LOCK, Message, Row, SegmentedBag, record_state, refuse_locked
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = ["LAG_TICKS", "LOCK", "SEGMENT_TICKS", "NodeRecord", "record_state", "refuse_locked"]

FloatArray = NDArray[np.float64]

JS = "sensor_msgs/msg/JointState"
F64 = "std_msgs/msg/Float64MultiArray"
PS = "geometry_msgs/msg/PointStamped"
STR = "std_msgs/msg/String"
TF = "tf2_msgs/msg/TFMessage"


#: Ticks kept in memory before they are written as one segment of the bag.
SEGMENT_TICKS = 2000

#: Ticks held back at a segment's cut (a truth or an effort of a tick may still arrive).
LAG_TICKS = 100


class NodeRecord:
    """The messages of one node run, by topic, with their log times [ns], streamed to the
    bag folder in segments (module docstring).

    Args:
        sc: The scenario the node runs (written as ``/amsfe/config``).
        lib: Its library.
        spec: The node's topics.
        names: The joint names of the JointStates (the robot's q order).
        out: The bag folder, claimed now (:meth:`open`); None: claimed by :meth:`open` or
            :meth:`write` later (everything kept in memory until then).
        segment_ticks: Ticks a segment holds (:data:`SEGMENT_TICKS`).

    Raises:
        RunFolderError: ``out`` exists (another writer's, or any folder).
    """

    def __init__(
        self,
        sc: Scenario,
        lib: ModelLibrary,
        spec: TopicSpec,
        names: Sequence[str],
        out: Path | None = None,
        segment_ticks: int = SEGMENT_TICKS,
    ) -> None:
        self.spec, self.names, self.n, self.lib = spec, list(names), lib.n, lib
        self._tf_every = max(1, round(1.0 / (TF_RATE_HZ * lib.T)))
        self._T_ns = round(lib.T * 1e9)
        self._segment_ticks, self._since_flush = max(1, segment_ticks), 0
        self._ticks = 0
        self._truth_q: dict[int, FloatArray] = {}  # the true q of a tick (its /tf), by ns
        self._sent: tuple[int, int] | None = None  # the last tick's (ns, sample sent) [ns]
        self._truths: list[tuple[int, FloatArray]] = []  # (sent, x) not yet matched
        self._awaiting: list[tuple[int, int, int]] = []  # ticks (ns, prev sent, sent) without
        self.truth_missing = 0  # ticks written without their truth (it never came in time)
        urdf = Path(lib.manifest.urdf) if lib.manifest.urdf else None
        self.urdf = urdf.read_text() if urdf is not None and urdf.is_file() else None
        self._rows: list[Row] = []
        self.config = {
            "tool": "amsfe_sym",
            "robot": lib.manifest.spec or lib.manifest.urdf,
            "library": lib.manifest.name,
            "scenario_toml": dump_toml(sc.to_dict()),
            "runtime": "ros-node",
            "estimator": sc.estimator,
            "T": lib.T,
        }
        self.out: Path | None = None
        self._bag: SegmentedBag | None = None
        self._stop_meta: dict[str, str] = {}
        if out is not None:
            self.open(out)

    # ------------------------------------------------------------------ the path
    def open(self, out: Path) -> None:
        """Claim the bag folder ``out`` (module docstring): created with its lock file and an
        empty, unfinished ``metadata.yaml``.

        Raises:
            RunFolderError: ``out`` exists: a record being written (the writer's pid), an
                unfinished one of a writer that died, or any other folder or file.
        """
        self._bag = SegmentedBag.claim(Path(out))
        self.out = self._bag.path

    # ------------------------------------------------------------------ the ticks
    def _add(self, topic: str, msgtype: str, ns: int, *data: Any) -> None:
        self._rows.append((topic, msgtype, ns, data))

    def encoders(self, ns: int, z: FloatArray, sent_ns: int | None = None) -> None:
        """An encoder sample [qm, qmd] stamped ``ns``, sent by its publisher at ``sent_ns``
        (its source timestamp [ns]: a truth sent since the previous sample's is this tick's,
        :meth:`truth_sent`)."""
        self._add(self.spec.encoders, JS, ns, ns, None, z[: self.n], z[self.n :], None)
        if sent_ns is None:
            return
        prev = -1 if self._sent is None else self._sent[1]
        self._sent = (ns, sent_ns)
        mine = [x for s, x in self._truths if prev < s <= sent_ns]
        self._truths = [(s, x) for s, x in self._truths if s > sent_ns]  # a later tick's
        if mine:
            self.truth(ns, mine[-1])
        else:
            self._awaiting.append((ns, prev, sent_ns))

    @property
    def awaiting_truth(self) -> bool:
        """A tick recorded whose truth has not come yet (DDS orders no deliveries across
        topics: the last tick's truth can arrive after its sample)."""
        return bool(self._awaiting)

    def truth_sent(self, sent_ns: int, x: FloatArray) -> None:
        """A truth message [q, qd, qm, qmd, theta] as received, sent at ``sent_ns`` (its
        source timestamp [ns]): recorded at the tick whose encoder sample was the first sent
        after it (now, if that sample is already in; else when it comes)."""
        x = np.array(x, dtype=float)
        for i, (ns, prev, sent) in enumerate(self._awaiting):
            if prev < sent_ns <= sent:
                del self._awaiting[i]
                self.truth(ns, x)
                return
        if self._sent is None or sent_ns > self._sent[1]:
            self._truths.append((sent_ns, x))
            del self._truths[:-LAG_TICKS]  # bounded: a truth with no tick is dropped

    def frame(self, arrival_ns: int, exposure_ns: int, z: FloatArray) -> None:
        """A camera frame exposed at ``exposure_ns`` and fused at the tick ``arrival_ns``."""
        self._add(self.spec.camera, PS, arrival_ns, exposure_ns, float(z[0]), float(z[1]))

    def applied(self, ns: int, u: FloatArray) -> None:
        """The torque applied over the tick stamped ``ns`` [N m]."""
        self._add(self.spec.effort, JS, ns, ns, None, None, None, np.array(u, dtype=float))

    def truth(self, ns: int, x: FloatArray) -> None:
        """The true state [q, qd, qm, qmd, theta] at the tick ``ns`` (and, as
        ``amsfe simulate --bag`` has it, the true q, qd on ``/joint_states``, unless the
        encoders or the effort are on that topic: it is theirs)."""
        n = self.n
        self._truth_q[ns] = np.array(x[:n], dtype=float)
        self._add(self.spec.truth, F64, ns, np.array(x, dtype=float))
        if "/joint_states" not in (self.spec.encoders, self.spec.effort):
            self._add("/joint_states", JS, ns, ns, None, x[:n], x[n : 2 * n], None)

    def outputs(
        self, ns: int, x_hat: FloatArray, std: FloatArray, theta: FloatArray, u: FloatArray | None
    ) -> None:
        """What the node published for the tick stamped ``ns`` (its last call of a tick: a
        segment may be written here)."""
        n = self.n
        self._add(self.spec.estimate, JS, ns, ns, None, x_hat[:n], x_hat[n : 2 * n], None)
        self._add(self.spec.estimate_std, JS, ns, ns, None, std[:n], std[n : 2 * n], None)
        self._add(self.spec.theta, F64, ns, np.array(theta, dtype=float))
        if u is not None:
            self._add(self.spec.commands, F64, ns, np.array(u, dtype=float))
        if self.urdf is not None and self._ticks % self._tf_every == 0:
            self._add("/tf", TF, ns, ns, np.array(x_hat[:n], dtype=float))  # drawn when written
        self._ticks += 1
        self._since_flush += 1
        if self._bag is not None and self._since_flush >= self._segment_ticks:
            self._flush(ns - LAG_TICKS * self._T_ns)

    def diagnostics(self, ns: int, text: str) -> None:
        """A diagnostics JSON the node published at the tick ``ns``."""
        self._add(self.spec.diagnostics, STR, ns, text)

    def hold(self, ns: int, u: FloatArray) -> None:
        """The hold command published when the node stopped (logged at ``ns``, the last
        tick's stamp)."""
        self._add(self.spec.commands, F64, ns, np.array(u, dtype=float))

    def stopped(self, line: str, exit_code: int | None, watchdog: str | None) -> None:
        """How the node stopped: its one line, the exit code (None: a signal) and the
        watchdog's reason name (None: not a watchdog's hold; docs/watchdogs.md).  Into the
        metadata (``amsfe.exit_code``, ``amsfe.watchdog``) and, when no segment is written
        yet (a run shorter than :data:`SEGMENT_TICKS`), ``/amsfe/config`` (``stop``)."""
        self.config["stop"] = {"line": line, "exit_code": exit_code, "watchdog": watchdog}
        self._stop_meta = {
            "amsfe.exit_code": "signal" if exit_code is None else str(exit_code),
            "amsfe.watchdog": watchdog or "",
        }

    # ------------------------------------------------------------------ writing
    def _flush(self, cut_ns: int | None) -> None:
        """Write the rows stamped before ``cut_ns`` (None: all) as one segment."""
        assert self._bag is not None
        self._since_flush = 0
        if cut_ns is None:
            rows, self._rows = self._rows, []
            self.truth_missing += len(self._awaiting)
            self._awaiting = []
        else:
            rows = [r for r in self._rows if r[2] < cut_ns]
            self._rows = [r for r in self._rows if r[2] >= cut_ns]
            self.truth_missing += sum(1 for a in self._awaiting if a[0] < cut_ns)
            self._awaiting = [a for a in self._awaiting if a[0] >= cut_ns]
        if not rows:
            return
        rows.sort(key=lambda r: r[2])  # stable: a tick's rows keep their order
        if self._bag.segments == 0:
            start = rows[0][2]
            head = [(self.spec.config, STR, start, (json.dumps(self.config),))]
            if self.urdf is not None:  # Foxglove draws the arm from it
                head.append(("/robot_description", STR, start, (self.urdf,)))
            rows = [*head, *rows]
        tf_rows = []
        for topic, msgtype, ns, data in rows:
            if msgtype == TF:
                arms = [("est/", data[1])]
                truth = self._truth_q.get(ns)
                if truth is not None:
                    arms.insert(0, ("", truth))
                tf_rows.append((topic, msgtype, ns, (ns, arms)))
            else:
                tf_rows.append((topic, msgtype, ns, data))
        if cut_ns is None:
            self._truth_q.clear()
        else:
            self._truth_q = {k: v for k, v in self._truth_q.items() if k >= cut_ns}
        self._bag.write_segment(_one_joint_state_a_tick(tf_rows, self.spec), self._message_maker)

    def _message_maker(self) -> Message:
        """Builds a message of a row (``rosbags`` types)."""
        from amsfe_sym.logs.source import typestore

        ts = typestore().types
        empty = np.zeros(0)
        tf = None
        if self.urdf is not None:
            from amsfe_sym.logs.write import tf_builder

            tf = tf_builder(self.lib)
        layout = ts["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)

        def header(ns: int, frame: str = "") -> Any:
            t = ts["builtin_interfaces/msg/Time"](
                sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000
            )
            return ts["std_msgs/msg/Header"](stamp=t, frame_id=frame)

        def message(msgtype: str, data: tuple[Any, ...]) -> Any:
            if msgtype == JS:
                ns, _, pos, vel, eff = data
                return ts[JS](
                    header=header(ns),
                    name=self.names,
                    position=np.asarray(empty if pos is None else pos, dtype=np.float64),
                    velocity=np.asarray(empty if vel is None else vel, dtype=np.float64),
                    effort=np.asarray(empty if eff is None else eff, dtype=np.float64),
                )
            if msgtype == PS:
                ns, u, v = data
                point = ts["geometry_msgs/msg/Point"](x=u, y=v, z=0.0)
                return ts[PS](header=header(ns, "camera"), point=point)
            if msgtype == F64:
                return ts[F64](layout=layout, data=np.asarray(data[0], dtype=np.float64))
            if msgtype == TF and tf is not None:
                return tf(*data)
            return ts[STR](data=data[0])

        return message

    def write(self, out: Path | None = None, reason: str = "done") -> Path:
        """Write what is left, mark the bag finished with ``reason`` (why the node stopped,
        one line) and release the folder: the bag folder.

        Args:
            out: The folder, when :meth:`open` was not called (claimed now).
            reason: The metadata's ``amsfe.end``.

        Raises:
            RunFolderError: ``out`` differs from the folder claimed, or cannot be claimed.
        """
        if self._bag is None:
            if out is None:
                raise RunFolderError(
                    describe("node record", "a folder to write", "none", "pass --record DIR")
                )
            self.open(out)
        assert self._bag is not None
        if out is not None and resolved(out) != self._bag.path:
            raise RunFolderError(
                describe(
                    "node record",
                    f"the folder it claimed ({self._bag.path})",
                    str(out),
                    "write it where it was opened",
                )
            )
        self._flush(None)
        extra = {"amsfe.truth_missing": str(self.truth_missing), **self._stop_meta}
        self._bag.finish(reason, extra)
        note_written([self._bag.path])
        return self._bag.path


def _one_joint_state_a_tick(rows: Sequence[Row], spec: TopicSpec) -> Iterator[Row]:
    """``rows`` as written: with the effort on the encoders' topic (``spec.effort ==
    spec.encoders``, a driver's ``/joint_states``), the effort of a tick goes into the
    JointState of that tick's encoder sample (position, velocity and effort in one message,
    as the arm sent it; of two efforts stamped alike, the later, the one the log reader
    holds); an effort with no sample of its stamp (one the live loop skipped) stays an
    effort-only JointState.  Separate topics: ``rows`` unchanged."""
    topic = spec.encoders
    if spec.effort != topic:
        yield from rows
        return
    effort: dict[int, Any] = {}
    samples: set[int] = set()
    for t, msgtype, ns, data in rows:
        if t == topic and msgtype == JS:
            if data[2] is None:
                effort[ns] = data[4]
            else:
                samples.add(ns)
    for row in rows:
        t, msgtype, ns, data = row
        if t == topic and msgtype == JS:
            if data[2] is None and ns in samples:
                continue  # in its sample's message
            if data[2] is not None and ns in effort:
                row = (t, msgtype, ns, (*data[:4], effort[ns]))
        yield row
