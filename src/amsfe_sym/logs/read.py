"""A recorded log -> the estimator's inputs on its tick grid (docs/logs.md, "Timing").

- The tick grid is the encoder's: t_k = t0 + k T, with t0 the first encoder stamp and T the
  robot's sampling interval.  A sample more than ``grid_tolerance`` T off the grid is
  skipped and counted; if more than 1 % of them are, the log is refused (its rate is not the
  robot's T).  Missing samples (a gap) are predicted through, up to ``max_gap_steps`` in a
  row; a longer gap refuses the log.  A second sample for the same tick is a duplicate.
- The torque is held from its stamp (zero-order hold, as the plant applies it): u(k) is the
  last torque stamped at or before t_k.
- A camera frame is taken at ``header.stamp`` (its exposure step kappa, on the grid within
  the tolerance) and reaches the estimator at the first tick at or after its log time (its
  arrival): variable delays, drops and reordering are the log's own.  Frames with a
  non-finite pixel, a second frame for an exposure step already seen, frames exposed before
  the first tick, arriving before their exposure or after the last tick are skipped and
  counted by reason; frames older than the estimator's history are counted by the replay.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.source import Message, iter_messages
from amsfe_sym.logs.spec import TORQUE_TYPES, LogSpec

__all__ = ["RobotLog", "read_config", "read_log"]

FloatArray = NDArray[np.float64]

_TYPES = {
    "encoders": ("sensor_msgs/msg/JointState",),
    "torque": TORQUE_TYPES,
    "camera": ("geometry_msgs/msg/PointStamped",),
    "truth": ("std_msgs/msg/Float64MultiArray",),
    "config": ("std_msgs/msg/String",),
}


@dataclass
class RobotLog:
    """What the estimator needs from a log, on the tick grid.

    Attributes:
        path: The log.
        T: Sampling interval [s].
        t0_ns: Time of tick 0 (the first encoder stamp) [ns].
        z: Encoder samples [qm, qmd] per tick, (K, 2n); a row of NaN: no sample (a gap).
        u: Torque applied over [t_k, t_k+1] [N m], (K, n).
        frames: Camera frames with their exposure and delivery steps, in arrival order.
        truth: The true state per tick, (K, N), if the log has it.
        config: amsfe's run config (simulated logs), or None.
        skipped: Messages skipped, by reason.
    """

    path: Path
    T: float
    t0_ns: int
    z: FloatArray
    u: FloatArray
    frames: list[CameraFrame]
    truth: FloatArray | None = None
    config: dict[str, Any] | None = None
    skipped: dict[str, int] = field(default_factory=dict)

    @property
    def K(self) -> int:
        """Ticks on the grid."""
        return int(self.z.shape[0])

    @property
    def t(self) -> FloatArray:
        """Tick times relative to t0 [s]."""
        return np.arange(self.K, dtype=np.float64) * self.T


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _by_topic(path: Path, spec: LogSpec) -> dict[str, list[Message]]:
    topics = {
        "encoders": spec.encoders,
        "torque": spec.torque,
        "camera": spec.camera,
        "truth": spec.truth,
        "config": spec.config,
    }
    wanted = {v: k for k, v in topics.items()}
    out: dict[str, list[Message]] = {k: [] for k in topics}
    for m in iter_messages(path, set(wanted)):
        role = wanted[m.topic]
        if m.msgtype not in _TYPES[role]:
            raise LogError(
                describe(
                    f"log {path}: topic {m.topic}",
                    f"messages of type {' or '.join(_TYPES[role])}",
                    m.msgtype,
                    "point the log spec's [topics] at the right topic (docs/logs.md)",
                )
            )
        out[role].append(m)
    for role in ("encoders", "torque"):
        if not out[role]:
            raise LogError(
                describe(
                    f"log {path}",
                    f"the {role} topic {topics[role]}",
                    "no message on it",
                    "record it, or name the log's topic in a log spec (--log-spec)",
                )
            )
    return out


def read_config(path: Path, spec: LogSpec | None = None) -> dict[str, Any] | None:
    """amsfe's run config stored in a log by ``amsfe simulate --bag``, or None."""
    spec = spec or LogSpec()
    for m in iter_messages(path, {spec.config}):
        if m.msgtype == "std_msgs/msg/String":
            try:
                data = json.loads(m.decode().data)
            except ValueError as exc:
                raise LogError(
                    describe(f"log {path}: {spec.config}", "a JSON document", str(exc), "")
                ) from exc
            return data if isinstance(data, dict) else None
    return None


class _Grid:
    """Stamps -> tick indices, with the tolerance of the spec."""

    def __init__(self, t0_ns: int, T: float, tolerance: float) -> None:
        self.t0, self.T, self.tol = t0_ns, T, tolerance

    def step(self, stamp_ns: int) -> int | None:
        """The tick of a stamp on the grid, or None when it is off the grid."""
        s = (stamp_ns - self.t0) * 1e-9 / self.T
        k = round(s)
        return k if abs(s - k) <= self.tol else None

    def arrival(self, log_ns: int) -> int:
        """The first tick at or after an arrival time (within the tolerance)."""
        return math.ceil((log_ns - self.t0) * 1e-9 / self.T - self.tol)


def _order(names: Sequence[str], joints: Sequence[str], where: str) -> list[int]:
    missing = [j for j in joints if j not in names]
    if missing:
        raise LogError(
            describe(
                where,
                f"JointState names including {list(joints)}",
                f"{list(names)}",
                "map the log's joint names to the robot's in the log spec's [joints] names",
            )
        )
    return [list(names).index(j) for j in joints]


def read_log(path: Path, spec: LogSpec, joints: Sequence[str], T: float, N: int) -> RobotLog:
    """Read ``path`` for a robot with ``joints`` (q order), sampling interval ``T`` [s] and
    ``N`` states.

    Raises:
        LogError: unreadable, a required topic missing or of the wrong type, joint names not
            found, samples off the robot's grid, a gap longer than ``max_gap_steps``.
    """
    n = len(joints)
    names = spec.joint_names or tuple(joints)
    if len(names) != n:
        raise LogError(
            describe("log spec [joints] names", f"{n} names (the robot's joints)", f"{names}", "")
        )
    msgs = _by_topic(path, spec)
    skipped: dict[str, int] = {}

    def skip(reason: str) -> None:
        skipped[reason] = skipped.get(reason, 0) + 1

    # ------------------------------------------------------------------ encoders: the grid
    enc = [(m, m.decode()) for m in msgs["encoders"]]
    enc.sort(key=lambda e: _stamp_ns(e[1]))
    grid = _Grid(_stamp_ns(enc[0][1]), T, spec.grid_tolerance)
    samples: dict[int, FloatArray] = {}
    for m, msg in enc:
        k = grid.step(_stamp_ns(msg))
        if k is None:
            skip("encoder sample off the tick grid")
            continue
        if k in samples:
            skip("encoder sample duplicated")
            continue
        idx = _order(msg.name, names, f"log {path}: {m.topic}")
        pos, vel = np.asarray(msg.position, float), np.asarray(msg.velocity, float)
        if pos.size != len(msg.name) or vel.size != len(msg.name):
            skip("encoder sample without position and velocity per joint")
            continue
        samples[k] = np.concatenate([pos[idx], vel[idx]])
    off = skipped.get("encoder sample off the tick grid", 0)
    if off > 0.01 * len(enc):
        raise LogError(
            describe(
                f"log {path}: {spec.encoders}",
                f"samples every T = {T:g} s (the robot's sampling interval)",
                f"{off} of {len(enc)} stamps off that grid",
                "record at the robot's rate, or generate the robot with the log's T",
            )
        )
    K = max(samples) + 1
    z = np.full((K, 2 * n), np.nan)
    for k, v in samples.items():
        z[k] = v
    missing = np.flatnonzero(np.isnan(z).any(axis=1))
    if missing.size:
        runs = np.split(missing, np.flatnonzero(np.diff(missing) > 1) + 1)
        longest = max(runs, key=len)
        if len(longest) > spec.max_gap_steps:
            raise LogError(
                describe(
                    f"log {path}: {spec.encoders}",
                    f"gaps of at most {spec.max_gap_steps} samples (predicted through)",
                    f"{len(longest)} missing from t = {longest[0] * T:.4f} s",
                    "raise [timing] max_gap_steps in a log spec, or cut the log there",
                )
            )
        skipped["encoder samples missing (predicted through)"] = int(missing.size)
    if not np.isfinite(z[0]).all():
        raise LogError(describe(f"log {path}", "a finite first encoder sample", "NaN", ""))

    # ------------------------------------------------------------------ torque: zero-order hold
    u = np.full((K, n), np.nan)
    for m in msgs["torque"]:
        msg = m.decode()
        if m.msgtype == "sensor_msgs/msg/JointState":
            k = grid.step(_stamp_ns(msg))
            values = np.asarray(msg.effort, float)
            idx = _order(msg.name, names, f"log {path}: {m.topic}")
            values = values[idx] if values.size == len(msg.name) else np.full(n, np.nan)
        else:  # Float64MultiArray: no header, stamped by its log time
            k = grid.step(m.log_time_ns)
            values = np.asarray(msg.data, float)
        if k is None:
            skip("torque sample off the tick grid")
        elif values.size != n or not np.isfinite(values).all():
            skip("torque sample not n finite values")
        elif 0 <= k < K:
            u[k] = values
    if np.isnan(u[0]).any():
        raise LogError(
            describe(f"log {path}: {spec.torque}", "a torque at the first tick", "none", "")
        )
    held = 0
    for k in range(1, K):
        if np.isnan(u[k]).any():
            u[k], held = u[k - 1], held + 1
    if held:
        skipped["torque held from the previous tick"] = held

    # ------------------------------------------------------------------ camera frames
    frames: list[CameraFrame] = []
    seen: set[int] = set()
    for m in sorted(msgs["camera"], key=lambda m: m.log_time_ns):
        msg = m.decode()
        kappa = grid.step(_stamp_ns(msg))
        pix = np.array([msg.point.x, msg.point.y], dtype=float)
        arrive = grid.arrival(m.log_time_ns)
        if kappa is None:
            skip("frame exposure off the tick grid")
        elif not np.isfinite(pix).all():
            skip("frame with a non-finite pixel")
        elif kappa in seen:
            skip("frame duplicated (an exposure already seen)")
        elif kappa < 0:
            skip("frame exposed before the first encoder sample")
        elif arrive < kappa:
            skip("frame arrived before its exposure")
        elif arrive >= K:
            skip("frame arrived after the last tick")
        else:
            seen.add(kappa)
            frames.append(CameraFrame(kappa, pix, arrive))

    # ------------------------------------------------------------------ truth and config
    truth = None
    if msgs["truth"]:
        truth = np.full((K, N), np.nan)
        for m in msgs["truth"]:
            k = grid.step(m.log_time_ns)
            data = np.asarray(m.decode().data, float)
            if k is not None and 0 <= k < K and data.size == N:
                truth[k] = data
    config = None
    if msgs["config"]:
        try:
            config = json.loads(msgs["config"][0].decode().data)
        except ValueError:
            skip("config not JSON")
    return RobotLog(path, T, grid.t0, z, u, frames, truth, config, skipped)
