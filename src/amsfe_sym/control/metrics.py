"""Closed-loop metrics of a run: tracking, effort, chattering, saturation, and the paper's
stability conditions evaluated along the run (pure numpy, no model).

Sarpturk's conditions (43a) ``s(k) (s(k+1) - s(k)) < 0`` and (43b)
``s(k) (s(k+1) + s(k)) > 0`` are checked per joint on the recorded s(k); the gain bound (38)
``eps > xi_M/T |dv - lam e(k+1)^p + lam e^p| + xi_F/T + h |s|`` and the sampling-time bound
(39) ``T < 2 |s - dF| / (h |s| + eps)`` (worst case ``|dF| = xi_F``) are evaluated with the
law's own terms, per joint and tick.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray

__all__ = ["control_metrics", "sliding_conditions"]


def _per_joint(v: FloatArray) -> list[float]:
    return [float(x) for x in v]


def control_metrics(
    t: FloatArray,
    q: FloatArray,
    q_des: FloatArray,
    u: FloatArray,
    saturated: NDArray[np.bool_],
    window: slice,
) -> dict[str, Any]:
    """Tracking and effort over ``window`` of the run.

    Args:
        t: Times [s], (K,).
        q: True link angles [rad], (K, n).
        q_des: Desired link angles [rad], (K, n).
        u: Applied torques [N m], (K, n).
        saturated: Whether u(k) was clipped, (K,).
        window: The ticks the metrics cover (e.g. after the transient).

    Returns:
        ``tracking_rmse`` [rad], ``tracking_max_error`` [rad], ``u_rms`` [N m],
        ``u_total_variation_per_s`` [N m/s] (chattering), ``saturated_fraction``, per joint
        where it applies.
    """
    e = (q - q_des)[window]
    uw = u[window]
    tw = t[window]
    span = float(tw[-1] - tw[0]) if tw.size > 1 else float("nan")
    tv = np.sum(np.abs(np.diff(uw, axis=0)), axis=0) / span if tw.size > 1 else uw[0] * np.nan
    return {
        "tracking_rmse": _per_joint(np.sqrt(np.mean(e**2, axis=0))),
        "tracking_max_error": _per_joint(np.max(np.abs(e), axis=0)),
        "u_rms": _per_joint(np.sqrt(np.mean(uw**2, axis=0))),
        "u_max_abs": _per_joint(np.max(np.abs(uw), axis=0)),
        "u_total_variation_per_s": _per_joint(tv),
        "saturated_fraction": float(np.mean(saturated[window])) if tw.size else float("nan"),
    }


def sliding_conditions(
    s: FloatArray, bound: FloatArray, gains: Mapping[str, Any], T: float, window: slice
) -> dict[str, Any] | None:
    """Fractions of ticks in ``window`` where (43a), (43b), (38) and (39) hold, per joint.

    Args:
        s: Sliding variable per tick, (K, n) (NaN where the law has none).
        bound: ``|dv - lam e(k+1)^p + lam e^p|`` per tick, (K, n).
        gains: The controller's gains (``h``, ``eps``, ``xi_M``, ``xi_F``).
        T: Sampling interval [s].
        window: Ticks to cover.

    Returns:
        None when the controller has no sliding surface.
    """
    if s.size == 0 or np.all(np.isnan(s)):
        return None
    n = s.shape[1]
    sw, bw = s[window], bound[window]
    s0, s1 = sw[:-1], sw[1:]
    a = s0 * (s1 - s0) < 0  # (43a)
    b = s0 * (s1 + s0) > 0  # (43b)
    h = np.broadcast_to(np.asarray(gains.get("h", np.nan), dtype=float), (n,))
    eps = np.broadcast_to(np.asarray(gains.get("eps", np.nan), dtype=float), (n,))
    xi_m = float(gains.get("xi_M", 3.0))
    xi_f = float(gains.get("xi_F", 1.0))
    eps_bound = xi_m / T * bw + xi_f / T + h * np.abs(sw)  # (38)
    t_bound = 2.0 * np.maximum(np.abs(sw) - xi_f, 0.0) / (h * np.abs(sw) + eps)  # (39)
    return {
        "sarpturk_43a_fraction": _per_joint(np.mean(a, axis=0)),
        "sarpturk_43b_fraction": _per_joint(np.mean(b, axis=0)),
        "gain_38_holds_fraction": _per_joint(np.mean(eps > eps_bound, axis=0)),
        "gain_38_eps_bound_median": _per_joint(np.median(eps_bound, axis=0)),
        "gain_38_eps": _per_joint(eps),
        "sampling_39_holds_fraction": _per_joint(np.mean(t_bound > T, axis=0)),
        "xi_M": xi_m,
        "xi_F": xi_f,
        "s_rms": _per_joint(np.sqrt(np.mean(sw**2, axis=0))),
    }
