"""Logs shaped like real arms' recordings, for the tests (issue 26 item 9).

Two writers, both with rosbags' own writers, so the files are what a ROS recorder makes:

* :func:`write_franka_like_bag`: a ROS 1 ``.bag`` as ``franka_ros`` records a Panda: one
  ``/joint_states`` topic (``sensor_msgs/JointState``, published by ``joint_state_publisher``)
  at 30 Hz with position, velocity and the *measured* joint torque ``tau_J`` as effort, for the
  7 arm joints plus the gripper's 2 finger joints; header stamps taken on another machine's
  clock (203.6 s ahead of the recorder's, the case of issue 26), a little stamp jitter and a
  receive latency.
* :func:`write_ur_like_rosbag2`: a rosbag2 folder (MCAP or sqlite3) as a UR driver's
  ``/joint_states``: 125 Hz (a CB3's real-time interface), joints in alphabetical order
  (``elbow_joint`` first, as ros_control's joint state publishers list them) and the *motor
  currents* [A] as effort.

Timing defaults are the ones measured on a real franka_ros recording
(docs/data/real-recording.md, ``tools/real_recording.py``): stamp period jitter 0.049 ms
(std about the 30 Hz grid), latency 0.26 ms minimum, 0.53 ms mean.

The motion comes from the caller (:class:`ArmMotion`, a uniform grid at the robot's own rate,
e.g. a simulated run's truth) or from :func:`smooth_motion`.  Each message carries the latest
grid sample at its true time (a zero-order hold, as a driver republishes its newest state);
the returned :class:`WrittenLog` says which sample and every time, so a test knows the truth.
``tools/make_real_like_logs.py`` writes the same logs from the command line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "FRANKA_ARM",
    "FRANKA_FINGERS",
    "UR_JOINTS",
    "ArmMotion",
    "FrankaLikeOptions",
    "URLikeOptions",
    "WrittenLog",
    "motion_from_run",
    "smooth_motion",
    "write_franka_like_bag",
    "write_ur_like_rosbag2",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

FRANKA_ARM = tuple(f"panda_joint{i}" for i in range(1, 8))
FRANKA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
#: The UR's joints in kinematic order (robots/ur5/robot.toml).
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: A recorder's wall clock at the first message [ns] (an epoch time, as real logs have).
EPOCH_NS = 1_691_398_864_230_487_565


@dataclass(frozen=True)
class ArmMotion:
    """Joint samples on a uniform grid starting at 0: ``q`` [rad], ``qd`` [rad/s] and
    ``effort`` (what the log's effort field should hold: [N m], or the applied torque the
    UR writer turns into currents), each of shape (K, n), sample k at ``k * period`` [s]."""

    names: tuple[str, ...]
    period: float
    q: FloatArray
    qd: FloatArray
    effort: FloatArray

    def __post_init__(self) -> None:
        k, n = self.q.shape
        if self.qd.shape != (k, n) or self.effort.shape != (k, n) or len(self.names) != n:
            raise ValueError(
                f"ArmMotion: q {self.q.shape}, qd {self.qd.shape}, effort {self.effort.shape}"
                f" and {len(self.names)} names must agree; pass (K, n) arrays and n names"
            )
        if not self.period > 0:
            raise ValueError(f"ArmMotion: period {self.period} s must be > 0")

    @property
    def duration(self) -> float:
        """Time of the last sample [s]."""
        return (self.q.shape[0] - 1) * self.period


@dataclass(frozen=True)
class WrittenLog:
    """What a writer wrote: every message's grid sample, true time and both clocks."""

    path: Path
    topic: str
    names: tuple[str, ...]  # as the messages list them
    sample_index: IntArray  # the ArmMotion row each message carries
    true_time: FloatArray  # [s] when the message was taken, on the motion's clock
    stamp_ns: IntArray  # header stamps
    log_time_ns: IntArray  # the recorder's log time
    clock_offset_s: float  # header clock - recorder clock [s]


@dataclass(frozen=True)
class FrankaLikeOptions:
    """How :func:`write_franka_like_bag` times and fills the messages.

    ``stamp_jitter`` [s] is the std of each stamp about the ``rate_hz`` grid; the latency
    (log time after the true time) is ``latency_min`` plus an exponential with mean
    ``latency_mean - latency_min`` [s]; ``clock_offset`` [s] is added to every header stamp
    (stamps ahead of the log time when > 0).  ``repeat_probability`` re-sends the previous
    sample (the real recording repeats 19 of 987: joint_state_publisher and the state
    controller both run at 30 Hz, unsynchronised)."""

    rate_hz: float = 30.0
    clock_offset: float = 203.6
    stamp_jitter: float = 4.9e-5
    latency_min: float = 2.64e-4
    latency_mean: float = 5.27e-4
    finger_position: float = 0.0  # [m] each finger (the real recording: 0.0)
    repeat_probability: float = 0.0
    topic: str = "/joint_states"
    callerid: str = "/joint_state_publisher"
    start_ns: int = EPOCH_NS


@dataclass(frozen=True)
class URLikeOptions:
    """How :func:`write_ur_like_rosbag2` times and fills the messages.

    ``newton_metres_per_ampere`` turns the motion's applied torque [N m] into the logged
    current [A] (torque constant times gear ratio; the default is a round illustrative value,
    not a UR datum); ``current_noise`` [A] is the std of white noise added to it.  Joints are
    listed in ``order`` ("alphabetical": as UR drivers publish them; "kinematic": as given)."""

    rate_hz: float = 125.0
    clock_offset: float = 0.0
    stamp_jitter: float = 2.0e-5
    latency_min: float = 1.0e-4
    latency_mean: float = 3.0e-4
    newton_metres_per_ampere: Sequence[float] = field(default_factory=lambda: [10.0] * 6)
    current_noise: float = 0.0
    order: Literal["alphabetical", "kinematic"] = "alphabetical"
    storage: Literal["mcap", "sqlite3"] = "mcap"
    topic: str = "/joint_states"
    start_ns: int = EPOCH_NS


def smooth_motion(
    names: Sequence[str],
    duration: float,
    period: float,
    rng: np.random.Generator,
    amplitude: float = 0.3,
    q0: Sequence[float] | None = None,
) -> ArmMotion:
    """A smooth motion for logs without a model: each joint ``q0 + a sin(w t + p)`` with
    random ``w`` in [0.3, 1.2] rad/s and phase, its exact derivative as ``qd`` and, as effort,
    ``5 sin(w t + p + 1)`` [N m] (a shape only: not the torque of any arm)."""
    n = len(names)
    t = np.arange(round(duration / period) + 1) * period
    w = rng.uniform(0.3, 1.2, n)
    p = rng.uniform(0.0, 2.0 * np.pi, n)
    base = np.zeros(n) if q0 is None else np.asarray(q0, dtype=np.float64)
    arg = np.outer(t, w) + p
    q = base + amplitude * np.sin(arg)
    qd = amplitude * w * np.cos(arg)
    effort = 5.0 * np.sin(arg + 1.0)
    return ArmMotion(tuple(names), period, q, qd, effort)


def motion_from_run(
    res: Any, effort: Literal["joint_torque", "applied"] = "joint_torque"
) -> ArmMotion:
    """The true link motion of a simulated run (``amsfe_sym.sim.result.RunResult``) on its
    T grid, with the effort a real arm would log: ``joint_torque``, the spring torque
    ``Ks (qm - q)`` [N m] that Franka's and KUKA's torque sensors measure (Ks at the run's true
    theta), or ``applied``, the motor torque ``u`` [N m] applied over [t_k, t_k + T] (what a
    UR's currents measure, :func:`write_ur_like_rosbag2` divides it into amperes)."""
    lib = res.lib
    lay = lib.layout
    x = np.asarray(res.x_true, dtype=np.float64)
    q, qd, qm = x[:, lay["q"]], x[:, lay["qd"]], x[:, lay["qm"]]
    if effort == "joint_torque":
        ks = lib.stiffness(x[0, lay["theta"]])
        tau = (qm - q) * ks
    elif effort == "applied":
        tau = np.asarray(res.u, dtype=np.float64)
    else:
        raise ValueError(f"motion_from_run: effort {effort!r}; pass 'joint_torque' or 'applied'")
    return ArmMotion(tuple(lib.manifest.joints), float(lib.T), q.copy(), qd.copy(), tau.copy())


def _timing(
    motion: ArmMotion,
    rate_hz: float,
    jitter: float,
    lat_min: float,
    lat_mean: float,
    offset: float,
    start_ns: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, IntArray, IntArray, IntArray]:
    """True times, grid rows (zero-order hold), header stamps and log times."""
    period = 1.0 / rate_hz
    count = int(np.floor(motion.duration / period)) + 1
    true = (
        np.arange(count) * period + rng.normal(0.0, jitter, count)
        if jitter > 0
        else (np.arange(count) * period)
    )
    true = np.clip(true, 0.0, motion.duration)
    rows = np.minimum(np.floor(true / motion.period + 1e-9).astype(np.int64), motion.q.shape[0] - 1)
    latency = lat_min + rng.exponential(max(lat_mean - lat_min, 0.0), count)
    stamp = start_ns + np.round((true + offset) * 1e9).astype(np.int64)
    log = start_ns + np.round((true + latency) * 1e9).astype(np.int64)
    # a recorder writes in arrival order: keep log times increasing
    log = np.maximum.accumulate(log)
    return true, rows, stamp, log


def write_franka_like_bag(
    path: Path,
    motion: ArmMotion,
    rng: np.random.Generator,
    options: FrankaLikeOptions | None = None,
) -> WrittenLog:
    """Write ``motion`` (the 7 Panda arm joints) as a franka_ros ROS 1 bag at ``path``.

    The effort is written as given: for a Franka it is the measured joint torque ``tau_J``
    [N m] (franka_state_controller copies ``robot_state.tau_J`` into it).  The two finger
    joints follow the arm joints with ``finger_position``, zero velocity and effort."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    o = options or FrankaLikeOptions()
    if tuple(motion.names) != FRANKA_ARM:
        raise ValueError(f"write_franka_like_bag: joints {motion.names}; pass {FRANKA_ARM}")
    true, rows, stamp, log = _timing(
        motion,
        o.rate_hz,
        o.stamp_jitter,
        o.latency_min,
        o.latency_mean,
        o.clock_offset,
        o.start_ns,
        rng,
    )
    if o.repeat_probability > 0:
        repeat = rng.random(rows.size) < o.repeat_probability
        repeat[0] = False
        for j in np.flatnonzero(repeat):
            rows[j] = rows[j - 1]
    store = get_typestore(Stores.ROS1_NOETIC)
    names = list(FRANKA_ARM + FRANKA_FINGERS)
    fingers = np.full(2, o.finger_position)
    zeros = np.zeros(2)
    msgtype = "sensor_msgs/msg/JointState"
    with Writer(path) as w:
        conn = w.add_connection(o.topic, msgtype, typestore=store, callerid=o.callerid)
        for k, r in enumerate(rows.tolist()):
            msg = _joint_state(
                store,
                int(stamp[k]),
                k,
                names,
                np.concatenate([motion.q[r], fingers]),
                np.concatenate([motion.qd[r], zeros]),
                np.concatenate([motion.effort[r], zeros]),
            )
            w.write(conn, int(log[k]), store.serialize_ros1(msg, msgtype))
    return WrittenLog(path, o.topic, tuple(names), rows, true, stamp, log, o.clock_offset)


def write_ur_like_rosbag2(
    path: Path,
    motion: ArmMotion,
    rng: np.random.Generator,
    options: URLikeOptions | None = None,
) -> WrittenLog:
    """Write ``motion`` (the 6 UR joints, kinematic order; effort = the applied motor torque
    [N m]) as a UR driver's rosbag2 folder at ``path``: the effort field holds the motor
    currents ``effort / newton_metres_per_ampere`` [A] (plus ``current_noise``)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    o = options or URLikeOptions()
    if tuple(motion.names) != UR_JOINTS:
        raise ValueError(f"write_ur_like_rosbag2: joints {motion.names}; pass {UR_JOINTS}")
    k_nm = np.asarray(o.newton_metres_per_ampere, dtype=np.float64)
    if k_nm.shape != (6,) or not np.all(k_nm > 0):
        raise ValueError(f"URLikeOptions: newton_metres_per_ampere {k_nm}; pass 6 values > 0")
    true, rows, stamp, log = _timing(
        motion,
        o.rate_hz,
        o.stamp_jitter,
        o.latency_min,
        o.latency_mean,
        o.clock_offset,
        o.start_ns,
        rng,
    )
    perm = (
        sorted(range(6), key=lambda i: UR_JOINTS[i])
        if o.order == "alphabetical"
        else list(range(6))
    )
    names = [UR_JOINTS[i] for i in perm]
    current = motion.effort / k_nm
    if o.current_noise > 0:
        current = current + rng.normal(0.0, o.current_noise, current.shape)
    store = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if o.storage == "mcap" else StoragePlugin.SQLITE3
    msgtype = "sensor_msgs/msg/JointState"
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conn = w.add_connection(o.topic, msgtype, typestore=store)
        for k, r in enumerate(rows.tolist()):
            msg = _joint_state(
                store,
                int(stamp[k]),
                None,
                names,
                motion.q[r, perm],
                motion.qd[r, perm],
                current[r, perm],
            )
            w.write(conn, int(log[k]), store.serialize_cdr(msg, msgtype))
    return WrittenLog(path, o.topic, tuple(names), rows, true, stamp, log, o.clock_offset)


def _joint_state(
    store: Any,
    stamp_ns: int,
    seq: int | None,
    names: list[str],
    position: FloatArray,
    velocity: FloatArray,
    effort: FloatArray,
) -> Any:
    t = store.types
    time = t["builtin_interfaces/msg/Time"](
        sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
    )
    header_args: dict[str, Any] = {"stamp": time, "frame_id": ""}
    if seq is not None and "seq" in t["std_msgs/msg/Header"].__dataclass_fields__:
        header_args["seq"] = seq
    return t["sensor_msgs/msg/JointState"](
        header=t["std_msgs/msg/Header"](**header_args),
        name=names,
        position=np.ascontiguousarray(position, dtype=np.float64),
        velocity=np.ascontiguousarray(velocity, dtype=np.float64),
        effort=np.ascontiguousarray(effort, dtype=np.float64),
    )
