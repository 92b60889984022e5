"""A reference that starts from the arm's state: the cascades' blended start
(docs/explanation/control.md).

When a cascade starts (``startup = "converged"``: at the first tick its estimate is trusted),
the desired trajectory q_d(t) is in general somewhere else than the arm, and moving at another
rate.  Asking the sliding law to close that gap at once is what swings the joints at start-up
(docs/explanation/control.md, "Start-up").  Instead, as an industrial controller ramps onto a path,
the
law tracks

    q_r(t) = q_d(t) + delta(t - t0),   delta(s) = d0 b0(s / Tb) + d1 Tb b1(s / Tb)   (s < Tb)

with d0 = q(t0) - q_d(t0), d1 = qd(t0) - qd_d(t0) from the state the law acts on, and
b0, b1 the degree-9 polynomials on [0, 1] with b0(0) = 1, b1'(0) = 1, every other value and
derivative up to the 4th zero at both ends: q_r starts at the arm's angle and rate with the
reference's acceleration, jerk and snap, and joins q_d after Tb with every derivative the
cascade feeds forward (up to the snap) continuous.  Tb is the shortest time whose offset
acceleration stays below ``blend_accel`` [rad/s^2] on every joint, and its jerk and snap
below ``blend_accel * blend_rate`` and ``blend_accel * blend_rate^2`` (a short blend of a
rate offset has a large snap, which the cascade feeds forward to the motor):
|delta^(r)| <= |d0| A0_r / Tb^r + |d1| A1_r / Tb^(r-1), A0_r = max|b0^(r)|, A1_r = max|b1^(r)|.

The C controller (``runtime/c/amsfe_blend.c``) evaluates the same polynomials in the same
order; tests/test_compiled_loop.py holds the two equal tick by tick.
"""

from __future__ import annotations

import math

import numpy as np

from amsfe_sym.arrays import FloatArray

__all__ = [
    "A0",
    "A1",
    "B0",
    "B1",
    "blend_offsets",
    "blend_through",
    "blend_time",
    "blend_weight",
]


#: Coefficients (power basis, t^0 .. t^9) of b0 and b1 (exact rationals).
B0 = (1.0, 0.0, 0.0, 0.0, 0.0, -126.0, 420.0, -540.0, 315.0, -70.0)
B1 = (0.0, 1.0, 0.0, 0.0, 0.0, -70.0, 224.0, -280.0, 160.0, -35.0)
#: max over [0, 1] of |b0^(r)| and |b1^(r)| for r = 2, 3, 4 (at the roots of b^(r+1),
#: rounded up).
A0 = (9.3720, 78.751, 622.54)
A1 = (6.1455, 39.860, 332.92)
#: Derivatives of the offset fed to the law: q, qd, qdd, jerk, snap.
ORDERS = 5


def _bound(a: float, b: float, tb: float, r: int) -> float:
    """|d0| A0_r / Tb^r + |d1| A1_r / Tb^(r-1), the bound on |delta^(r)| (the C computes the
    same products in the same order)."""
    p = 1.0
    for _ in range(r - 1):
        p *= tb
    return a * A0[r - 2] / (p * tb) + b * A1[r - 2] / p


def blend_time(d0: FloatArray, d1: FloatArray, accel: float, rate: float = math.inf) -> float:
    """The blend's duration Tb [s]: the least (by bisection, to ~1e-15 s) with
    |delta^(2)| <= accel, |delta^(3)| <= accel rate and |delta^(4)| <= accel rate^2 on every
    joint; 0 when there is no offset or ``accel`` is infinite.

    Args:
        d0: The angle offsets at the start [rad], per joint.
        d1: The rate offsets at the start [rad/s], per joint.
        accel: The offset's acceleration budget [rad/s^2].
        rate: The bandwidth [rad/s] that bounds its jerk and snap (inf: no bound).
    """
    if math.isinf(accel):
        return 0.0
    orders = (2,) if math.isinf(rate) else (2, 3, 4)
    tb = 0.0
    for a, b in zip(np.abs(d0), np.abs(d1), strict=True):
        if a == 0.0 and b == 0.0:
            continue
        for r in orders:
            lim = accel
            for _ in range(r - 2):
                lim *= rate
            if tb > 0.0 and not _bound(a, b, tb, r) > lim:
                continue  # already long enough
            lo, hi = tb, max(tb, 1e-3)
            for _ in range(64):  # bracket
                if not _bound(a, b, hi, r) > lim:
                    break
                lo, hi = hi, 2.0 * hi
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if _bound(a, b, mid, r) > lim:
                    lo = mid
                else:
                    hi = mid
            tb = hi
    return tb


def _poly(c: tuple[float, ...], r: int, s: float) -> float:
    """The r-th derivative of sum c_i s^i at s, by Horner from the top (the C does the same)."""
    acc = 0.0
    for i in range(len(c) - 1, r - 1, -1):
        f = 1.0
        for m in range(i - r + 1, i + 1):
            f *= m
        acc = acc * s + c[i] * f
    return acc


def blend_weight(tau: float) -> float:
    """b0(tau), 1 at the blend's start and 0 at its end (tau = s / Tb in [0, 1]): the weight
    of a start-up value that hands over to the steady one as the offset does."""
    return _poly(B0, 0, tau)


def blend_offsets(s: float, tb: float, d0: FloatArray, d1: FloatArray) -> FloatArray:
    """delta and its first four time derivatives at s [s] after the start, stacked like the
    law's reference input ``[q, qd, qdd, jerk, snap]`` (5n); zero once ``s >= tb``."""
    n = d0.size
    out = np.zeros(ORDERS * n)
    if not s < tb:
        return out
    tau = s / tb
    scale = 1.0
    for r in range(ORDERS):
        out[r * n : (r + 1) * n] = (d0 * _poly(B0, r, tau) + d1 * tb * _poly(B1, r, tau)) / scale
        scale *= tb
    return out


def _through(
    e0: FloatArray, e1: FloatArray, wait: float, tb: float
) -> tuple[FloatArray, FloatArray]:
    """The offsets (d0, d1) of the blend of duration ``tb`` whose offset and rate at ``wait``
    [s] after its start are (e0, e1): per joint, the 2x2 system
    ``[b0, Tb b1; b0' / Tb, b1'] (d0, d1) = (e0, e1)`` at tau = wait / Tb (the C the same)."""
    tau = wait / tb
    a, b = _poly(B0, 0, tau), tb * _poly(B1, 0, tau)
    c, d = _poly(B0, 1, tau) / tb, _poly(B1, 1, tau)
    det = a * d - b * c
    return (d * e0 - b * e1) / det, (a * e1 - c * e0) / det


def blend_through(
    e0: FloatArray, e1: FloatArray, wait: float, accel: float, rate: float = math.inf
) -> tuple[float, FloatArray, FloatArray]:
    """The blend that started ``wait`` [s] ago and passes through the offsets (e0, e1) now:
    its duration Tb [s] and its offsets at its start (d0, d1), for a start-up that trusted
    its estimate ``wait`` after the loop began (``blend_lead``).

    Tb is the least (by bisection) with Tb > wait whose blend, solved to pass through
    (e0, e1) at ``wait`` (:func:`_through`), keeps the budgets of :func:`blend_time`:
    ``blend_time(d0, d1) <= Tb``.  Because b0 and b1 are flat to the 4th order at the start,
    d0 ~ e0 - e1 wait and d1 ~ e1 when ``wait << Tb``: the plan is the one the oracle would
    have made at the first tick from the state the arm then had, had it moved on at its rate,
    so the wait spends the polynomial's flat start instead of adding e1 wait to the offset
    the blend must return.  ``wait = 0`` (or no offset, or ``accel`` infinite) is
    :func:`blend_time` on (e0, e1) itself.

    Args:
        e0: The angle offsets now [rad], per joint.
        e1: The rate offsets now [rad/s], per joint.
        wait: Time since the blend's start [s], >= 0.
        accel: The offset's acceleration budget [rad/s^2].
        rate: The bandwidth [rad/s] bounding its jerk and snap (inf: no bound).
    """
    tb0 = blend_time(e0, e1, accel, rate)
    if not wait > 0.0 or tb0 == 0.0:
        return tb0, e0.copy(), e1.copy()

    def fits(tb: float) -> bool:
        d0, d1 = _through(e0, e1, wait, tb)
        ok = bool(np.all(np.isfinite(d0)) and np.all(np.isfinite(d1)))
        return ok and not blend_time(d0, d1, accel, rate) > tb

    lo, step = wait, tb0
    hi = wait + step
    for _ in range(64):  # bracket: a blend long enough always fits
        if fits(hi):
            break
        lo, step = hi, 2.0 * step
        hi = wait + step
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if fits(mid):
            hi = mid
        else:
            lo = mid
    d0, d1 = _through(e0, e1, wait, hi)
    return hi, d0, d1
