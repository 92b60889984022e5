"""The public API's recordings: :class:`LogArrays` (a log held as arrays on the robot's
tick grid), :func:`read_log` (a bag, rosbag2 or MCAP into one) and
:meth:`LogArrays.from_arrays` (your own arrays into one); docs/api.md."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.errors import ConfigError, ShapeError, describe

if TYPE_CHECKING:
    from amsfe_sym.logs.read import RobotLog
    from amsfe_sym.topics.spec import TopicSpec

__all__ = ["LogArrays", "read_log"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LogArrays:
    """A recording held as arrays on the robot's tick grid t_k = k T (K ticks, F frames).

    Build one with :func:`read_log` (a ROS 1 bag, a rosbag2 folder or an MCAP file) or
    :meth:`from_arrays` (your own numpy arrays).

    Attributes:
        t: Tick times from the first sample [s], (K,).
        q_motor: Motor angles qm from the encoders [rad], (K, n); a row of NaN: no sample.
        qd_motor: Motor rates qmd [rad/s], (K, n).
        effort: The logged effort held by stamp [N m], (K, n), or None.
        effort_kind: What ``effort`` is: ``applied`` (the motor torque u), ``joint_torque``
            (a joint torque sensor's tau_J) or ``none`` (no usable torque;
            docs/explanation/effort.md).
        camera_t: Each camera frame's exposure time [s] from the first sample, (F,).
        camera_uv: Each frame's pixel [u, v] [px], (F, 2).
        camera_arrival_t: The time each frame reached the estimator [s], (F,).
        T: The sampling interval [s].
        truth: The true state per tick (eq. 2), (K, N), when the log has it, else None.
        source: The :class:`~amsfe_sym.logs.read.RobotLog` the arrays view.
        spec: The topic spec the log was read with (its ``[effort]``, ``[filter]`` and
            ``[joints]`` tables reach the estimator).
        robot: The robot the log was read for (a :func:`read_log` log), else None.
    """

    t: FloatArray
    q_motor: FloatArray
    qd_motor: FloatArray
    effort: FloatArray | None
    effort_kind: str
    camera_t: FloatArray
    camera_uv: FloatArray
    camera_arrival_t: FloatArray
    T: float
    truth: FloatArray | None
    source: RobotLog = field(repr=False)
    spec: TopicSpec = field(repr=False)
    robot: str | None = None
    derived: Any = field(default=None, repr=False)

    @classmethod
    def _of(
        cls, rl: RobotLog, spec: TopicSpec, robot: str | None, derived: Any = None
    ) -> LogArrays:
        n = rl.z.shape[1] // 2
        F = len(rl.frames)
        return cls(
            t=rl.t,
            q_motor=rl.z[:, :n],
            qd_motor=rl.z[:, n:],
            effort=rl.effort,
            effort_kind=str(rl.effort_kind),
            camera_t=np.array([f.exposure_step * rl.T for f in rl.frames], dtype=float),
            camera_uv=np.array([np.asarray(f.z, float) for f in rl.frames]).reshape(F, 2),
            camera_arrival_t=np.array([f.delivery_step * rl.T for f in rl.frames], dtype=float),
            T=rl.T,
            truth=rl.truth,
            source=rl,
            spec=spec,
            robot=robot,
            derived=derived,
        )

    @classmethod
    def from_arrays(
        cls,
        t: ArrayLike,
        q_motor: ArrayLike,
        effort: ArrayLike | None = None,
        camera_t: ArrayLike | None = None,
        camera_uv: ArrayLike | None = None,
        *,
        qd_motor: ArrayLike | None = None,
        effort_kind: str = "applied",
        camera_arrival_t: ArrayLike | None = None,
        T: float | None = None,
        truth: ArrayLike | None = None,
    ) -> LogArrays:
        """A recording from your own arrays (a notebook's, a CSV's).

        Args:
            t: Sample times [s], (K,), increasing, on a grid of T (gaps allowed: the
                missing ticks are predicted through).
            q_motor: Motor angles [rad], (K, n).
            effort: Torque per sample [N m], (K, n), of kind ``effort_kind``; the torque of
                sample k is held over [t_k, t_k+1]; None: none.
            camera_t: Exposure time of each camera frame [s], (F,), on the same clock as t.
            camera_uv: Its pixel [u, v] [px], (F, 2).
            qd_motor: Motor rates [rad/s], (K, n); None: the backward difference of
                ``q_motor`` (q_k - q_k-1) / T (the first row: zero).
            effort_kind: ``applied``, ``joint_torque`` or ``none`` (docs/explanation/effort.md).
            camera_arrival_t: When each frame reached the computer [s], (F,); a frame is
                given to the estimator with the first sample at or after it.  None: with
                the sample of its own exposure (no latency).
            T: The sampling interval [s]; None: the median of diff(t).
            truth: The true state (eq. 2) per sample, (K, N), for a simulated recording.

        Returns:
            The :class:`LogArrays`.

        Raises:
            ShapeError: arrays of mismatched shapes.
            ConfigError: times that are not finite, do not increase or are off the grid of T
                by more than T/4; an unknown ``effort_kind``.
        """
        from amsfe_sym.core.camera_frame import CameraFrame
        from amsfe_sym.logs.read import RobotLog
        from amsfe_sym.topics.spec import read_topic_spec

        ts = _vector("t", t)
        q = _matrix("q_motor", q_motor, ts.size)
        K0, n = q.shape
        if not np.all(np.isfinite(ts)) or (ts.size > 1 and not np.all(np.diff(ts) > 0)):
            raise ConfigError(
                describe("t", "finite, increasing times [s]", "times that are not", "sort t")
            )
        step = float(T) if T is not None else float(np.median(np.diff(ts))) if K0 > 1 else 0.0
        if not (math.isfinite(step) and step > 0):
            raise ConfigError(describe("T", "a sampling interval > 0 [s]", repr(step), "pass T"))
        k = np.rint((ts - ts[0]) / step).astype(np.int64)
        off = np.abs(ts - ts[0] - k * step)
        if np.any(off > 0.25 * step):
            i = int(np.argmax(off))
            raise ConfigError(
                describe(
                    f"t[{i}] = {ts[i]!r}",
                    f"times on a grid of T = {step:g} s (within T/4)",
                    f"{off[i]:.3g} s off it",
                    "pass T, or resample the recording onto a fixed rate",
                )
            )
        qd = (
            _matrix("qd_motor", qd_motor, K0, n)
            if qd_motor is not None
            else np.vstack([np.zeros((1, n)), np.diff(q, axis=0) / np.diff(ts)[:, None]])
        )
        if effort_kind not in ("applied", "joint_torque", "none"):
            raise ConfigError(
                describe(
                    "effort_kind",
                    "applied, joint_torque or none",
                    repr(effort_kind),
                    "say what the effort is (docs/explanation/effort.md)",
                )
            )
        K = int(k[-1]) + 1
        z = np.full((K, 2 * n), np.nan)
        z[k] = np.hstack([q, qd])
        eff = None
        if effort is not None:
            e = _matrix("effort", effort, K0, n)
            eff = np.zeros((K, n))
            eff[k] = e
            held = np.maximum.accumulate(np.where(np.isin(np.arange(K), k), np.arange(K), 0))
            eff = eff[held]  # held over the gaps
        u = eff if effort_kind == "applied" and eff is not None else np.zeros((K, n))
        frames: list[CameraFrame] = []
        if camera_t is not None or camera_uv is not None:
            ct = _vector("camera_t", camera_t if camera_t is not None else [])
            uv = _matrix("camera_uv", camera_uv if camera_uv is not None else [], ct.size, 2)
            kappa = np.rint((ct - ts[0]) / step).astype(np.int64)
            if camera_arrival_t is None:
                arrival = kappa
            else:
                at = _vector("camera_arrival_t", camera_arrival_t)
                if at.shape != ct.shape:
                    raise ShapeError(
                        describe(
                            "camera_arrival_t",
                            f"shape {ct.shape} (one per frame)",
                            f"shape {at.shape}",
                            "one arrival time per camera_t",
                        )
                    )
                arrival = np.ceil((at - ts[0]) / step - 1e-9).astype(np.int64)
            order = np.argsort(arrival, kind="stable")
            frames = [CameraFrame(int(kappa[i]), uv[i].copy(), int(arrival[i])) for i in order]
        tr = None if truth is None else _matrix("truth", truth, K0)
        truth_grid = None
        if tr is not None:
            truth_grid = np.full((K, tr.shape[1]), np.nan)
            truth_grid[k] = tr
        rl = RobotLog(
            Path("<arrays>"),
            step,
            round(float(ts[0]) * 1e9),
            z,
            u,
            frames,
            truth_grid,
            effort=eff,
            effort_kind=effort_kind,  # type: ignore[arg-type]
            period_s=step,
        )
        return cls._of(rl, read_topic_spec(None), None)


def _vector(what: str, value: ArrayLike) -> FloatArray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != 1:
        raise ShapeError(describe(what, "a 1-D array", f"shape {a.shape}", "pass one value each"))
    return a


def _matrix(what: str, value: ArrayLike, rows: int, cols: int | None = None) -> FloatArray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 1 and cols == 2 and a.size == 0:
        a = a.reshape(0, 2)
    if a.ndim != 2 or a.shape[0] != rows or (cols is not None and a.shape[1] != cols):
        want = f"({rows}, {cols if cols is not None else 'n'})"
        raise ShapeError(
            describe(what, f"shape {want}", f"shape {a.shape}", "one row per sample of t")
        )
    return a


def read_log(
    path: str | os.PathLike[str],
    robot: str | os.PathLike[str],
    topics: str | os.PathLike[str] | None = None,
) -> LogArrays:
    """Read a recorded log into arrays on ``robot``'s tick grid, as ``amsfe estimate``
    reads it (docs/how-to/logs.md: topics found by type and joint names, clocks, gaps).

    Args:
        path: A ROS 1 ``.bag``, a rosbag2 folder or an ``.mcap`` file.
        robot: The robot (a shipped name or a ``robot.toml``).
        topics: A topic spec TOML (the command's ``--log-spec``) for an unusual log; None:
            found by type and joint names.

    Returns:
        The :class:`LogArrays`.

    Raises:
        LogError: the log cannot be used (one line: what, found, fix).
    """
    from amsfe_sym.apps.estimate import read_robot_log
    from amsfe_sym.logs.source import log_topics
    from amsfe_sym.topics.spec import read_topic_spec

    p = Path(path)
    spec = read_topic_spec(topics)
    rl, derived = read_robot_log(p, spec, str(robot), log_topics(p))
    return LogArrays._of(rl, spec, str(robot), derived)
