"""An estimator over a read log, tick by tick as the closed loop runs it: at tick k the
estimator goes k-1 -> k with the torque of tick k-1, the encoder sample of tick k (none in a
gap: a predict only) and the frames that arrived at tick k (docs/logs.md)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.estimation.base import Estimator
from amsfe_sym.logs.read import RobotLog
from amsfe_sym.sim.result import DECISION_COUNTERS, count_decisions

__all__ = ["LogEstimate", "estimate_log"]

FloatArray = NDArray[np.float64]


@dataclass
class LogEstimate:
    """The estimates over a log.

    Attributes:
        x_hat: x(k|k) per tick, (K, N).
        P_diag: The diagonal of P(k|k), (K, N).
        nees: e^T P^-1 e against the log's true state, (K,), or None without one.
        counters: The estimator's decisions (the names of a run's ``summary.json``) and
            the reader's skipped messages by reason.
    """

    x_hat: FloatArray
    P_diag: FloatArray
    nees: FloatArray | None
    counters: dict[str, int] = field(default_factory=dict)


def estimate_log(log: RobotLog, est: Estimator) -> LogEstimate:
    """Run ``est`` (at x(0|0), P(0|0) for tick 0) over ``log``."""
    K, N = log.K, est.nx
    x_hat, P_diag = np.zeros((K, N)), np.zeros((K, N))
    nees = None if log.truth is None else np.full(K, np.nan)
    arrivals: dict[int, list[CameraFrame]] = defaultdict(list)
    for fr in log.frames:
        arrivals[fr.delivery_step].append(fr)
    counters = dict.fromkeys(DECISION_COUNTERS, 0)
    for k in range(K):
        if k > 0:
            z = log.z[k]
            zk = z if np.isfinite(z).all() else None
            count_decisions(counters, est.step(log.u[k - 1], zk, arrivals.get(k, [])))
        x, P = est.x, est.P
        x_hat[k], P_diag[k] = x, np.diag(P)
        if nees is not None and log.truth is not None and np.isfinite(log.truth[k]).all():
            e = log.truth[k] - x
            nees[k] = float(e @ np.linalg.solve(P, e))
    counters["frames_in_log"] = len(log.frames) + sum(
        v for r, v in log.skipped.items() if r.startswith("frame")
    )
    return LogEstimate(x_hat, P_diag, nees, {**counters, **log.skipped})
