"""What the calibration fits: each camera frame's pixel at its exposure stamp, and the link
angles around it from the encoders (the spring's deflection taken out where the log has
effort), read from a log by the same reader as ``amsfe estimate`` (docs/calibrate.md).

Link angles (``q``, one row per encoder tick, NaN where the log has no sample):

- effort kind ``joint_torque`` (a torque sensor behind the spring): ``q = qm - tau_J / Ks``,
  the estimator's spring-torque model (``effort_models.SpringTorqueMeasurement``);
- ``applied`` (the motor torque ``u``): the spring torque from the motor rows of eq. (1b),
  ``Ks (qm - q) = u - Mm qmdd - Fm qmd``, with ``qmdd`` a central difference of the logged
  ``qmd`` over +-:data:`ACCEL_WINDOW_S` (the estimator's ``reconstruct_input`` uses one step;
  a wider one keeps the encoder rate noise out of the angle);
- ``none``: ``q = qm`` (the deflection is not known; :attr:`LinkAngles.note` says so);
- a topic spec with ``[joints] positions = "link"``: the positions are the link angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.logs.read import RobotLog

__all__ = ["ACCEL_WINDOW_S", "LinkAngles", "Observations", "link_angles", "observations"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Half-width [s] of the central difference that gives the motor acceleration (effort kind
#: ``applied``): 10 ms keeps 1e-2 rad/s of rate noise to ~0.7 rad/s^2.
ACCEL_WINDOW_S = 0.01

#: Why a frame is not used (before the fit): no encoder sample on both sides of its time.
NO_ENCODER = "no encoder sample around the stamp (+ time offset)"


@dataclass(frozen=True)
class LinkAngles:
    """Link angles per encoder tick.

    Attributes:
        T: Tick interval [s]; tick k is at ``k T`` after the log's t0.
        q: Link angles (K, n) [rad]; a row of NaN where the log has no encoder sample.
        note: How the spring deflection was accounted for (one line).
    """

    T: float
    q: FloatArray
    note: str

    def at(self, t: FloatArray) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Angles [rad] and rates [rad/s] at times ``t`` [s] (m,), linear between ticks (the
        rate is the segment's slope: the exact derivative of the angle returned), and
        whether both ticks around each time have a sample."""
        K = self.q.shape[0]
        s = np.asarray(t, dtype=np.float64) / self.T
        k = np.floor(s).astype(np.int64)
        ok = (k >= 0) & (k + 1 < K)
        kc = np.clip(k, 0, max(K - 2, 0))
        a, b = self.q[kc], self.q[np.minimum(kc + 1, K - 1)]
        ok &= np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        f = (s - kc)[:, None]
        return a + f * (b - a), (b - a) / self.T, ok


@dataclass(frozen=True)
class Observations:
    """The camera frames of a log, in exposure order.

    Attributes:
        stamp: Exposure stamps relative to the log's t0 [s] (m,): the frames' header stamps on
            the tick grid (the reader puts each on its tick).
        pixel: Measured pixels (m, 2) [px].
        exposure_step: The frames' exposure ticks (m,).
        skipped: Frames the reader did not pass on, by reason (its counts).
    """

    stamp: FloatArray
    pixel: FloatArray
    exposure_step: IntArray
    skipped: dict[str, int]

    @property
    def m(self) -> int:
        return int(self.stamp.size)


def link_angles(
    log: RobotLog,
    Ks: FloatArray,
    Mm: FloatArray,
    Fm: FloatArray,
    positions: str = "motor",
) -> LinkAngles:
    """The link angles of every tick of ``log`` (module docstring) with the joints'
    stiffness ``Ks`` [N m/rad], motor inertia ``Mm`` [kg m^2] and friction ``Fm``
    [N m s/rad]."""
    n = Ks.size
    pos, rate = log.z[:, :n], log.z[:, n : 2 * n]
    if positions == "link":
        return LinkAngles(log.T, pos.copy(), "encoder positions are link angles (topic spec)")
    kind = log.effort_kind
    if kind == "joint_torque" and log.effort is not None:
        q = pos - log.effort / Ks
        return LinkAngles(log.T, q, "q = qm - tau_J / Ks (logged joint torque)")
    if kind == "applied":
        h = max(1, round(ACCEL_WINDOW_S / log.T))
        acc = np.full_like(rate, np.nan)
        acc[h:-h] = (rate[2 * h :] - rate[: -2 * h]) / (2 * h * log.T)
        spring = log.u - Mm * acc - Fm * rate
        q = pos - spring / Ks
        return LinkAngles(
            log.T,
            q,
            f"q = qm - (u - Mm qmdd - Fm qmd) / Ks (applied torque; qmdd over +-{h} ticks)",
        )
    return LinkAngles(
        log.T, pos.copy(), "q = qm: the log has no effort, the spring deflection is ignored"
    )


def observations(log: RobotLog) -> Observations:
    """The log's camera frames at their exposure stamps, and the reader's skip counts."""
    frames = sorted(log.frames, key=lambda f: f.exposure_step)
    steps = np.array([f.exposure_step for f in frames], dtype=np.int64)
    pixel = np.array([np.asarray(f.z, dtype=np.float64)[:2] for f in frames]).reshape(-1, 2)
    use = log.usage.get("camera")
    skipped = dict(use.skipped) if use is not None else {}
    return Observations(steps.astype(np.float64) * log.T, pixel, steps, skipped)
