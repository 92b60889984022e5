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
URDF).  Kept in memory, written when the node stops (complete or absent:
:func:`amsfe_sym.core.folders.write_folder`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.toml import dump_toml
from amsfe_sym.logs.write import TF_RATE_HZ
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = ["NodeRecord"]

FloatArray = NDArray[np.float64]

JS = "sensor_msgs/msg/JointState"
F64 = "std_msgs/msg/Float64MultiArray"
PS = "geometry_msgs/msg/PointStamped"
STR = "std_msgs/msg/String"
TF = "tf2_msgs/msg/TFMessage"


class NodeRecord:
    """The messages of one node run, by topic, with their log times [ns].

    Args:
        sc: The scenario the node runs (written as ``/amsfe/config``).
        lib: Its library.
        spec: The node's topics.
        names: The joint names of the JointStates (the robot's q order).
    """

    def __init__(
        self, sc: Scenario, lib: ModelLibrary, spec: TopicSpec, names: Sequence[str]
    ) -> None:
        self.spec, self.names, self.n, self.lib = spec, list(names), lib.n, lib
        self._tf_every = max(1, round(1.0 / (TF_RATE_HZ * lib.T)))
        self._ticks = 0
        self._truth: tuple[int, FloatArray] | None = None  # the last truth: (ns, q)
        urdf = Path(lib.manifest.urdf) if lib.manifest.urdf else None
        self.urdf = urdf.read_text() if urdf is not None and urdf.is_file() else None
        self._rows: list[tuple[str, str, int, tuple[Any, ...]]] = []
        self.config = {
            "tool": "amsfe_sym",
            "robot": lib.manifest.spec or lib.manifest.urdf,
            "library": lib.manifest.name,
            "scenario_toml": dump_toml(sc.to_dict()),
            "runtime": "ros-node",
            "estimator": sc.estimator,
            "T": lib.T,
        }

    def _add(self, topic: str, msgtype: str, ns: int, *data: Any) -> None:
        self._rows.append((topic, msgtype, ns, data))

    def encoders(self, ns: int, z: FloatArray) -> None:
        """An encoder sample [qm, qmd] stamped ``ns``."""
        self._add(self.spec.encoders, JS, ns, ns, None, z[: self.n], z[self.n :], None)

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
        self._truth = (ns, np.array(x[:n], dtype=float))
        self._add(self.spec.truth, F64, ns, np.array(x, dtype=float))
        if "/joint_states" not in (self.spec.encoders, self.spec.effort):
            self._add("/joint_states", JS, ns, ns, None, x[:n], x[n : 2 * n], None)

    def outputs(
        self, ns: int, x_hat: FloatArray, std: FloatArray, theta: FloatArray, u: FloatArray | None
    ) -> None:
        """What the node published for the tick stamped ``ns``."""
        n = self.n
        self._add(self.spec.estimate, JS, ns, ns, None, x_hat[:n], x_hat[n : 2 * n], None)
        self._add(self.spec.estimate_std, JS, ns, ns, None, std[:n], std[n : 2 * n], None)
        self._add(self.spec.theta, F64, ns, np.array(theta, dtype=float))
        if u is not None:
            self._add(self.spec.commands, F64, ns, np.array(u, dtype=float))
        if self.urdf is not None and self._ticks % self._tf_every == 0:
            arms = [("est/", np.array(x_hat[:n], dtype=float))]
            if self._truth is not None and self._truth[0] == ns:
                arms.insert(0, ("", self._truth[1]))
            self._add("/tf", TF, ns, ns, arms)  # drawn when written
        self._ticks += 1

    def diagnostics(self, ns: int, text: str) -> None:
        """A diagnostics JSON the node published at the tick ``ns``."""
        self._add(self.spec.diagnostics, STR, ns, text)

    def hold(self, ns: int, u: FloatArray) -> None:
        """The hold command published when the node stopped (logged at ``ns``, the last
        tick's stamp)."""
        self._add(self.spec.commands, F64, ns, np.array(u, dtype=float))

    def stopped(self, line: str, exit_code: int | None, watchdog: str | None) -> None:
        """How the node stopped, into ``/amsfe/config`` (``stop``): its one line, the exit
        code (None: a signal) and the watchdog's reason name (None: not a watchdog's hold;
        docs/watchdogs.md)."""
        self.config["stop"] = {"line": line, "exit_code": exit_code, "watchdog": watchdog}

    def write(self, out: Path) -> Path:
        """Write the bag folder ``out`` (complete or absent)."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        from amsfe_sym.logs.source import typestore

        store = typestore()
        ts = store.types
        start = min((r[2] for r in self._rows), default=0)

        def header(ns: int, frame: str = "") -> Any:
            t = ts["builtin_interfaces/msg/Time"](
                sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000
            )
            return ts["std_msgs/msg/Header"](stamp=t, frame_id=frame)

        empty = np.zeros(0)
        tf = None
        if any(r[1] == TF for r in self._rows):
            from amsfe_sym.logs.write import tf_builder

            tf = tf_builder(self.lib)
        layout = ts["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)

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

        def inner(tmp: Path) -> None:
            bag_dir = tmp / out.name
            writer = Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
            writer.open()
            conns: dict[str, Any] = {}
            try:
                head = [(self.spec.config, STR, start, (json.dumps(self.config),))]
                if self.urdf is not None:  # Foxglove draws the arm from it
                    head.append(("/robot_description", STR, start, (self.urdf,)))
                rows = [*head, *_one_joint_state_a_tick(self._rows, self.spec)]
                for topic, msgtype, ns, data in rows:
                    if topic not in conns:
                        conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
                    raw = store.serialize_cdr(message(msgtype, data), msgtype)
                    writer.write(conns[topic], ns, raw)
            finally:
                writer.close()
            for p in bag_dir.iterdir():
                p.rename(tmp / p.name)
            bag_dir.rmdir()

        return write_folder(out, inner)


def _one_joint_state_a_tick(
    rows: Sequence[tuple[str, str, int, tuple[Any, ...]]], spec: TopicSpec
) -> Iterator[tuple[str, str, int, tuple[Any, ...]]]:
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
