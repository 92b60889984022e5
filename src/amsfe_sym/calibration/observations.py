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

Then every joint's angle is smoothed by a cubic Savitzky-Golay filter over
+-:data:`SMOOTH_HALF_WINDOW_S` (:func:`smooth_angles`).  The fit interpolates the angles
linearly between ticks and takes the time offset's derivative from that slope, ``(q_k+1 -
q_k) / T``: on raw 1 kHz encoders with 2e-4 rad of noise the slope's noise is ~0.3 rad/s,
as large as the motion, and the time offset's errors then spread 1.29 times its stated sigma
(``tools/calibrate_seeds.py --synthetic 20 --encoder-std 2e-4 --no-smooth``); smoothed, 0.95
times, as without encoder noise (docs/calibrate.md, "Intervals").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.logs.read import RobotLog

__all__ = ["LinkAngles", "Observations", "link_angles", "observations", "smooth_angles"]
__all__ += ["ACCEL_WINDOW_S", "SMOOTH_HALF_WINDOW_S"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Half-width [s] of the central difference that gives the motor acceleration (effort kind
#: ``applied``): 10 ms keeps 1e-2 rad/s of rate noise to ~0.7 rad/s^2.
ACCEL_WINDOW_S = 0.01

#: Half-width [s] of the link angles' smoothing (module docstring): a cubic over +-10 ms
#: passes the arm's motion (its -3 dB point is ~60 Hz at 1 kHz) and divides the slope's
#: noise by ~20.
SMOOTH_HALF_WINDOW_S = 0.01
#: The smoothing polynomial's order.
SMOOTH_ORDER = 3

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
        corners: The marker's 4 corners per frame (m, 4, 2) [px], undistorted, OpenCV's
            order, when every frame has them (an image topic) and the marker's side is known;
            then the calibration fits them (None: it fits ``pixel``).
        marker_size: The marker's side [m] (with ``corners``).
    """

    stamp: FloatArray
    pixel: FloatArray
    exposure_step: IntArray
    skipped: dict[str, int]
    corners: FloatArray | None = None
    marker_size: float = 0.0

    @property
    def m(self) -> int:
        return int(self.stamp.size)

    @property
    def target(self) -> FloatArray:
        """What the fit compares its map with, (m, 2P) [px]: the 4 corners' u, v in turn,
        or the pixel (P = 1)."""
        if self.corners is None:
            return self.pixel
        return self.corners.reshape(self.m, 8)


def link_angles(
    log: RobotLog,
    Ks: FloatArray,
    Mm: FloatArray,
    Fm: FloatArray,
    positions: str = "motor",
    smooth: bool = True,
) -> LinkAngles:
    """The link angles of every tick of ``log`` (module docstring) with the joints'
    stiffness ``Ks`` [N m/rad], motor inertia ``Mm`` [kg m^2] and friction ``Fm``
    [N m s/rad]; ``smooth``: through :func:`smooth_angles`."""
    q, note = _raw_link_angles(log, Ks, Mm, Fm, positions)
    if smooth:
        q, h = smooth_angles(q, log.T)
        if h:
            note += f"; smoothed over +-{h} ticks (cubic Savitzky-Golay)"
    return LinkAngles(log.T, q, note)


def _raw_link_angles(
    log: RobotLog, Ks: FloatArray, Mm: FloatArray, Fm: FloatArray, positions: str
) -> tuple[FloatArray, str]:
    """The link angles per tick before smoothing, and how the deflection was taken out."""
    n = Ks.size
    pos, rate = log.z[:, :n], log.z[:, n : 2 * n]
    if positions == "link":
        return pos.copy(), "encoder positions are link angles (topic spec)"
    kind = log.effort_kind
    if kind == "joint_torque" and log.effort is not None:
        return pos - log.effort / Ks, "q = qm - tau_J / Ks (logged joint torque)"
    if kind == "applied":
        h = max(1, round(ACCEL_WINDOW_S / log.T))
        acc = np.full_like(rate, np.nan)
        acc[h:-h] = (rate[2 * h :] - rate[: -2 * h]) / (2 * h * log.T)
        spring = log.u - Mm * acc - Fm * rate
        return (
            pos - spring / Ks,
            f"q = qm - (u - Mm qmdd - Fm qmd) / Ks (applied torque; qmdd over +-{h} ticks)",
        )
    return pos.copy(), "q = qm: the log has no effort, the spring deflection is ignored"


def smooth_angles(
    q: FloatArray, T: float, half_window_s: float = SMOOTH_HALF_WINDOW_S
) -> tuple[FloatArray, int]:
    """``q`` (K, n) [rad] smoothed by a cubic Savitzky-Golay filter over +-``half_window_s``
    [s] (ticks of ``T`` [s]): each tick's value is that of the least-squares cubic through
    the 2h + 1 ticks around it (the first and last h ticks of a run: of the run's first and
    last window's cubic, as ``scipy.signal.savgol_filter(mode="interp")``).  Each run of
    finite rows on its own (a gap's NaN rows stay NaN; a run shorter than the window stays
    as it is).  Returns the smoothed angles and the half-width h in ticks (0: the window is
    under 2 ticks, nothing smoothed)."""
    h = round(half_window_s / T)
    if h < 2:
        return q.copy(), 0
    j = np.arange(-h, h + 1, dtype=np.float64)
    fit = np.linalg.pinv(np.vander(j, SMOOTH_ORDER + 1, increasing=True))  # (p+1, 2h+1)
    head = np.vander(j[:h], SMOOTH_ORDER + 1, increasing=True) @ fit  # the first h ticks
    tail = np.vander(j[h + 1 :], SMOOTH_ORDER + 1, increasing=True) @ fit  # the last h
    out = q.copy()
    finite = np.isfinite(q).all(axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], finite.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a < 2 * h + 1:
            continue
        x = q[a:b]
        windows = np.lib.stride_tricks.sliding_window_view(x, 2 * h + 1, axis=0)
        out[a + h : b - h] = windows @ fit[0]  # (K - 2h, n, 2h+1) @ (2h+1,)
        out[a : a + h] = head @ x[: 2 * h + 1]
        out[b - h : b] = tail @ x[-(2 * h + 1) :]
    return out, h


def observations(
    log: RobotLog, marker_size: float | None = None, corners: bool = True
) -> Observations:
    """The log's camera frames at their exposure stamps, and the reader's skip counts; with
    their marker corners when every frame has them, ``marker_size`` [m] is given and
    ``corners`` (False: the centre fit on an image log)."""
    frames = sorted(log.frames, key=lambda f: f.exposure_step)
    steps = np.array([f.exposure_step for f in frames], dtype=np.int64)
    pixel = np.array([np.asarray(f.z, dtype=np.float64)[:2] for f in frames]).reshape(-1, 2)
    use = log.usage.get("camera")
    skipped = dict(use.skipped) if use is not None else {}
    stamp = steps.astype(np.float64) * log.T
    have = bool(frames) and all(f.corners is not None for f in frames)
    if not (corners and have and marker_size):
        return Observations(stamp, pixel, steps, skipped)
    c = np.array([np.asarray(f.corners, dtype=np.float64) for f in frames]).reshape(-1, 4, 2)
    return Observations(stamp, pixel, steps, skipped, c, float(marker_size))
