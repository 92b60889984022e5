"""A simulated run -> a rosbag2 in MCAP storage that opens in Foxglove (docs/how-to/logs.md).

Topics (stamps in seconds from the run's start; log time = when the loop had the data; the
table with the message fields is in docs/how-to/logs.md): ``/motor_encoders`` (JointState: qm, qmd
as the loop read them), ``/motor_torque`` (JointState effort: the applied torque),
``/camera/marker`` (PointStamped: pixel u, v; stamp = exposure (+ the scenario's
``[camera] stamp_offset``), logged at arrival),
``/joint_states`` (true q, qd), ``/amsfe/estimate`` (estimated q, qd), ``/amsfe/truth``
(Float64MultiArray: the true state, for the NEES), ``/amsfe/config`` (String: JSON of the
robot, resolved scenario and runtime), ``/robot_description`` (String: the URDF) and ``/tf``
(world -> every link, true and ``est/``-prefixed, at :data:`TF_RATE_HZ`).  With images
(``amsfe simulate --bag --images``) the camera writes, instead of ``/camera/marker``, the
image the true camera took of the marker (``/camera/image_raw`` or its ``/compressed``) and
``/camera/camera_info``, with ``/camera/marker_detected`` (ImageMarker: the detected point,
drawn by Foxglove over the image) (:mod:`amsfe_sym.vision.sim_images`, docs/camera.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.core.folders import FolderJob, write_folders
from amsfe_sym.core.jsonfile import to_json
from amsfe_sym.core.toml import dump_toml
from amsfe_sym.logs.encode import JOINT_STATE, encode_joint_states
from amsfe_sym.logs.source import typestore
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.sim.result import RunResult

if TYPE_CHECKING:
    from amsfe_sym.vision.sim_images import ImageOptions

__all__ = [
    "TF_RATE_HZ",
    "bag_job",
    "run_bag_filler",
    "tf_builder",
    "write_estimate_bag",
    "write_run_bag",
]


#: Rate of the ``/tf`` messages [Hz] (enough to watch; the state topics carry every tick).
TF_RATE_HZ = 100.0


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def _header(t: float, frame: str = "") -> Any:
    return _header_ns(_ns(t), frame)


def _header_ns(ns: int, frame: str = "") -> Any:
    ts = typestore().types
    stamp = ts["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return ts["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


class _Bag:
    """A rosbag2 (MCAP storage) being written: typed connections by topic."""

    def __init__(self, path: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.conns: dict[str, Any] = {}

    def write(self, topic: str, msgtype: str, t: float, msg: Any) -> None:
        self.write_raw(topic, msgtype, _ns(t), typestore().serialize_cdr(msg, msgtype))

    def write_raw(self, topic: str, msgtype: str, log_ns: int, payload: bytes) -> None:
        """One payload already serialized (CDR) at log time ``log_ns`` [ns]."""
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=typestore())
        self.writer.write(self.conns[topic], log_ns, payload)

    def write_many(
        self,
        topics: Sequence[str],
        msgtype: str,
        stamps: Sequence[int],
        payloads: Sequence[list[bytes]],
    ) -> None:
        """``payloads[j][k]`` on ``topics[j]`` at log time ``stamps[k]`` [ns], k then j (as
        :meth:`write_raw` in that loop, the connections added first): in bulk
        (:func:`~amsfe_sym.logs.bulk_write.write_many`) where ``rosbags``' writer allows."""
        from amsfe_sym.logs.bulk_write import write_many

        for topic in topics:
            if topic not in self.conns:
                self.conns[topic] = self.writer.add_connection(
                    topic, msgtype, typestore=typestore()
                )
        conns = [self.conns[t] for t in topics]
        if write_many(self.writer, conns, np.asarray(stamps, dtype=np.int64), payloads):
            return
        for k, ns in enumerate(stamps):
            for j, c in enumerate(conns):
                self.writer.write(c, ns, payloads[j][k])

    def close(self) -> None:
        self.writer.close()


def bag_job(out: Path, fill: Callable[[Path], None], replace: bool = False) -> FolderJob:
    """The bag folder ``out`` as one job of :func:`~amsfe_sym.core.folders.write_folders`
    (complete or not at all; ``fill(path)`` writes a bag at a path that does not exist:
    rosbags' writer creates the folder itself, so it writes into a child of the temporary
    one).  ``replace``: an existing ``out`` may be replaced (the caller checked it is the
    tool's own output, :func:`amsfe_sym.core.outputs.check_output`)."""

    out = out.expanduser().resolve()

    def inner(tmp: Path) -> None:
        bag = tmp / out.name  # (the .mcap inside is named after the folder)
        fill(bag)
        for p in bag.iterdir():
            p.rename(tmp / p.name)
        bag.rmdir()

    return FolderJob(out, inner, replace)


def write_run_bag(
    res: RunResult, out: Path, urdf_text: str | None = None, replace: bool = False
) -> Path:
    """Write ``res`` as the rosbag2 folder ``out`` (an existing ``out`` is replaced only with
    ``replace``; the caller checks first that it may be)."""
    write_folders([bag_job(out, run_bag_filler(res, urdf_text), replace)])
    return out


def run_bag_filler(
    res: RunResult, urdf_text: str | None = None, images: ImageOptions | None = None
) -> Callable[[Path], None]:
    """``fill(path)``: writes ``res`` as a rosbag2 folder at ``path`` (which must not exist):
    its URDF, ``/tf`` of the true and estimated arms, sensors, torque, truth and config;
    with ``images``, the camera's images and CameraInfo instead of its pixel topic."""
    lib, sc = res.lib, res.scenario
    n, N = lib.n, lib.N
    joints = list(lib.manifest.joints)
    spec = LogSpec()
    ts = typestore().types
    F64 = ts["std_msgs/msg/Float64MultiArray"]
    layout = ts["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    String = ts["std_msgs/msg/String"]
    config = {
        "tool": "amsfe_sym",
        "robot": lib.manifest.spec or lib.manifest.urdf,
        "library": lib.manifest.name,
        "scenario_toml": dump_toml(sc.to_dict()),
        "runtime": res.runtime,
        "estimator": sc.estimator,
        "T": lib.T,
    }
    frames = sorted(res.frames.tolist(), key=lambda f: (f[1], f[0]))
    stamp_offset = sc.camera.stamp_offset  # [s] a camera whose stamps are not its exposures
    tf = _tf_frames(res, urdf_text)
    # the JointState topics, serialized in bulk (logs/encode.py: the same bytes as rosbags)
    stamps = [_ns(float(t)) for t in res.t]
    z, x_true, x_hat = (np.asarray(a, dtype=np.float64) for a in (res.z_enc, res.x_true, res.x_hat))
    enc = encode_joint_states(stamps, joints, z[:, :n], z[:, n:])
    torque = encode_joint_states(stamps, joints, effort=np.asarray(res.u, dtype=np.float64))
    true = encode_joint_states(stamps, joints, x_true[:, :n], x_true[:, n : 2 * n])
    est = encode_joint_states(stamps, joints, x_hat[:, :n], x_hat[:, n : 2 * n])

    def fill(path: Path) -> None:
        from amsfe_sym.logs.images import image_messages

        camera = None if images is None else _camera(res, images)
        bag = _Bag(path)
        try:
            bag.write(
                spec.config,
                "std_msgs/msg/String",
                0.0,
                String(data=to_json(config, indent=None).strip()),
            )
            if urdf_text is not None:
                bag.write("/robot_description", "std_msgs/msg/String", 0.0, String(data=urdf_text))
            fi = 0
            for k, t in enumerate(res.t):
                ns = stamps[k]
                bag.write_raw(spec.encoders, JOINT_STATE, ns, enc[k])
                while fi < len(frames) and frames[fi][1] <= k:
                    kappa, _, pu, pv = frames[fi]
                    if camera is not None:
                        kap = int(kappa)
                        x = res.x_true[kap]
                        msg, info, mark = image_messages(  # stamped as the pixel topic
                            camera,
                            _ns(kap * lib.T + stamp_offset),
                            x[lib.layout["q"]],
                            x[lib.layout["theta"]],
                        )
                        bag.write(camera.image_topic, camera.image_type, t, msg)
                        bag.write(_INFO, "sensor_msgs/msg/CameraInfo", t, info)
                        if mark is not None:  # Foxglove: the detected point on the image
                            bag.write(_DETECTED, "visualization_msgs/msg/ImageMarker", t, mark)
                        fi += 1
                        continue
                    pt = ts["geometry_msgs/msg/PointStamped"](
                        header=_header(kappa * lib.T + stamp_offset, "camera"),
                        point=ts["geometry_msgs/msg/Point"](x=pu, y=pv, z=0.0),
                    )
                    bag.write(spec.camera, "geometry_msgs/msg/PointStamped", t, pt)
                    fi += 1
                bag.write_raw(spec.torque, JOINT_STATE, ns, torque[k])
                bag.write_raw("/joint_states", JOINT_STATE, ns, true[k])
                bag.write_raw("/amsfe/estimate", JOINT_STATE, ns, est[k])
                x = res.x_true[k]
                truth = F64(layout=layout, data=np.asarray(x[:N], dtype=np.float64))
                bag.write(spec.truth, "std_msgs/msg/Float64MultiArray", t, truth)
                if tf is not None and k in tf:
                    bag.write("/tf", "tf2_msgs/msg/TFMessage", t, tf[k])
        finally:
            bag.close()

    return fill


_INFO = "/camera/camera_info"  # (vision.sim_images.INFO_TOPIC)
_DETECTED = "/camera/marker_detected"


def _camera(res: RunResult, images: ImageOptions) -> Any:
    """The run's true camera (:class:`~amsfe_sym.vision.sim_images.SimulatedCamera`), its
    noise drawn from the run's seed (a stream of its own: the run's draws are unchanged), the
    marker fixed to its link when the run's robot spec gives ``[tracked] orientation``."""
    from amsfe_sym.logs.sim_marker import marker_pose_of
    from amsfe_sym.vision.sim_images import SimulatedCamera

    rng = np.random.default_rng([int(res.scenario.seed), 35])
    lib = res.lib
    pose = marker_pose_of(res.scenario.robot, lib.manifest.raw.get("locked", {}))
    return SimulatedCamera(lib.manifest.camera, lib.function("tracked_point"), images, rng, pose)


def _tf_frames(res: RunResult, urdf_text: str | None) -> dict[int, Any] | None:
    """``/tf`` messages by tick (every 1 / TF_RATE_HZ s): world -> each link of the true arm
    and of the estimated one (``est/``), by Pinocchio's forward kinematics."""
    if urdf_text is None:
        return None
    lib = res.lib
    tf = tf_builder(lib)
    every = max(1, round(1.0 / (TF_RATE_HZ * lib.T)))
    n = lib.n
    return {
        k: tf(_ns(float(res.t[k])), [("", res.x_true[k, :n]), ("est/", res.x_hat[k, :n])])
        for k in range(0, len(res.t), every)
    }


def tf_builder(lib: ModelLibrary) -> Callable[[int, Sequence[tuple[str, FloatArray]]], Any]:
    """``tf(stamp_ns, arms)``: the ``tf2_msgs/TFMessage`` (rosbags type) of world -> each
    link of every arm ``(prefix, q [rad])`` stamped ``stamp_ns`` [ns], by Pinocchio's forward
    kinematics of ``lib``'s robot (loaded once, here)."""
    import pinocchio as pin

    from amsfe_sym.load import load_robot
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(lib.manifest.spec or lib.manifest.urdf)
    robot = load_robot(spec.with_locked(dict(lib.manifest.raw.get("locked", {}))))
    model = robot.model
    data = model.createData()
    ts = typestore().types
    bodies = [
        (f, frame.name) for f, frame in enumerate(model.frames) if frame.type == pin.FrameType.BODY
    ]

    def tf(stamp_ns: int, arms: Sequence[tuple[str, FloatArray]]) -> Any:
        transforms = []
        for prefix, q in arms:
            pin.framesForwardKinematics(model, data, robot.to_pin_q(q))
            for f, name in bodies:
                M = data.oMf[f]
                qx, qy, qz, qw = pin.Quaternion(M.rotation).coeffs()
                p = M.translation
                transforms.append(
                    ts["geometry_msgs/msg/TransformStamped"](
                        header=_header_ns(stamp_ns, "world"),
                        child_frame_id=prefix + name,
                        transform=ts["geometry_msgs/msg/Transform"](
                            translation=ts["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                            rotation=ts["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
                        ),
                    )
                )
        return ts["tf2_msgs/msg/TFMessage"](transforms=transforms)

    return tf


def write_estimate_bag(
    out: Path, t0: float, t: FloatArray, names: Sequence[str], x_hat: FloatArray, P_diag: FloatArray
) -> Path:
    """The estimates of ``amsfe estimate`` as a rosbag2 (MCAP): ``/amsfe/estimate``
    (JointState q, qd of x(k|k)) and ``/amsfe/estimate_std`` (JointState position/velocity =
    the standard deviations of q, qd)."""
    n = len(names)
    stamps = [_ns(t0 + float(tk)) for tk in t]
    x = np.asarray(x_hat, dtype=np.float64)
    s = np.sqrt(np.maximum(np.asarray(P_diag, dtype=np.float64), 0.0))
    est = encode_joint_states(stamps, names, x[:, :n], x[:, n : 2 * n])
    std = encode_joint_states(stamps, names, s[:, :n], s[:, n : 2 * n])

    def fill(path: Path) -> None:
        bag = _Bag(path)
        try:
            topics = ["/amsfe/estimate", "/amsfe/estimate_std"]
            bag.write_many(topics, JOINT_STATE, stamps, [est, std])
        finally:
            bag.close()

    write_folders([bag_job(out, fill, replace=False)])
    return out
