"""An estimator over a read log, tick by tick as the closed loop runs it: at tick k the
estimator goes k-1 -> k with the torque of tick k-1, the encoder sample of tick k (none in a
gap: a predict only) and the frames that arrived at tick k (docs/how-to/logs.md).

Two paths give the same numbers (tests/test_log_batch.py): a compiled estimator runs the whole
log in one C call per chunk of ticks (``amsfe_est_run``, docs/how-to/logs.md "Speed"); any other
estimator, or a log the batch cannot take, is stepped from Python tick by tick.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray, IntArray
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.estimation.base import Estimator, StepReport
from amsfe_sym.logs.read import RobotLog
from amsfe_sym.sim.result import DECISION_COUNTERS, count_decisions, refusal_kind

__all__ = ["FrameNis", "LogEstimate", "estimate_log"]


#: Logs shorter than this many ticks get no progress bar.
PROGRESS_MIN_TICKS = 5000


@dataclass
class FrameNis:
    """The camera frames given to the estimator, in arrival order (F of them).

    Attributes:
        kappa: Exposure step of each frame, (F,).
        arrival: Tick at which it reached the estimator, (F,).
        nis: Normalized innovation squared of its update (chi-square with 2 degrees of
            freedom when the model fits), (F,); NaN when it did not reach the update.
        fused: It was applied (not gated, not refused), (F,).
    """

    kappa: IntArray
    arrival: IntArray
    nis: FloatArray
    fused: NDArray[np.bool_]


@dataclass
class LogEstimate:
    """The estimates over a log.

    Attributes:
        x_hat: x(k|k) per tick, (K, N).
        P_diag: The diagonal of P(k|k), (K, N).
        nees: e^T P^-1 e against the log's true state, (K,), or None without one.
        counters: The estimator's decisions (the names of a run's ``summary.json``) and
            the reader's skipped messages by reason.
        encoder_nis: NIS of each tick's encoder innovation (eqs. 15-17; chi-square with 2n
            degrees of freedom when the model fits), (K,); NaN where no sample reached the
            update (tick 0, gaps); a sample the encoder gate refused keeps its NIS.
        frame_nis: The camera frames given to the estimator, their NIS and outcome.
    """

    x_hat: FloatArray
    P_diag: FloatArray
    nees: FloatArray | None
    counters: dict[str, int] = field(default_factory=dict)
    encoder_nis: FloatArray = field(default_factory=lambda: np.zeros(0))
    frame_nis: FrameNis = field(
        default_factory=lambda: FrameNis(
            np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.bool_)
        )
    )


def _given_frames(log: RobotLog) -> list[CameraFrame]:
    """The frames the estimator is given (arriving at ticks 1 .. K-1), by arrival (stable)."""
    frames = [fr for fr in log.frames if 1 <= fr.delivery_step < log.K]
    return sorted(frames, key=lambda fr: fr.delivery_step)


def _frame_arrays(frames: list[CameraFrame]) -> tuple[IntArray, IntArray, FloatArray]:
    kappa = np.array([fr.exposure_step for fr in frames], dtype=np.int64)
    arrival = np.array([fr.delivery_step for fr in frames], dtype=np.int64)
    z = np.array([np.asarray(fr.z, dtype=np.float64) for fr in frames]).reshape(-1, 2)
    return kappa, arrival, z


def _progress(log: RobotLog, est: Estimator, show: bool | None) -> Any:
    """A tqdm bar over the log's ticks (None: for logs of at least PROGRESS_MIN_TICKS)."""
    if show is False or (show is None and log.K < PROGRESS_MIN_TICKS):
        return None
    from tqdm import tqdm

    return tqdm(
        total=log.K,
        desc=f"estimate [{est.name}]",
        unit="tick",
        mininterval=0.5,
        leave=False,
        delay=1.0,  # shown once the run has taken 1 s
    )


def estimate_log(
    log: RobotLog,
    est: Estimator,
    *,
    batch: bool = True,
    progress: bool | None = None,
    states: int | None = None,
) -> LogEstimate:
    """Run ``est`` (at x(0|0), P(0|0) for tick 0) over ``log``.

    Args:
        log: The read log.
        est: A fresh estimator (``k == k0``).
        batch: Run a compiled estimator in one C call (``amsfe_est_run``) when it can; False:
            step it from Python tick by tick (the reference the batch is tested against).
        progress: Show a progress bar; None: for logs of at least
            :data:`PROGRESS_MIN_TICKS` ticks.
        states: The robot's state size N (eq. 2) when ``est`` carries more (the input
            states of an effort of kind ``joint_torque`` or ``none``, docs/explanation/effort.md):
            the
            estimates, their variances and the NEES are of the first N; None: all of them.
    """
    bar = _progress(log, est, progress)
    try:
        update: Callable[[int], None] | None = None if bar is None else bar.update
        if batch and _batch_ok(log, est):
            result = _batch(log, est, update)
        else:
            result = _per_tick(log, est, update, states)
    finally:
        if bar is not None:
            bar.close()
    result.counters["frames_in_log"] = len(log.frames) + sum(
        v for r, v in log.skipped.items() if r.startswith("frame")
    )
    result.counters.update(log.skipped)
    return result


def _batch_ok(log: RobotLog, est: Estimator) -> bool:
    """The C batch takes a fresh compiled estimator of one of the five kinds and frames that
    are never from the future (the per-tick path raises on those)."""
    from amsfe_sym.runtime.compiled_estimator import COMPILED_ESTIMATORS

    if type(est) not in COMPILED_ESTIMATORS.values() or est.k != est.k0:
        return False
    return all(fr.exposure_step <= fr.delivery_step for fr in log.frames)


def _per_tick(
    log: RobotLog,
    est: Estimator,
    progress: Callable[[int], None] | None,
    states: int | None = None,
) -> LogEstimate:
    K, N = log.K, est.nx if states is None else states
    x_hat, P_diag = np.zeros((K, N)), np.zeros((K, N))
    nees = None if log.truth is None else np.full(K, np.nan)
    enc_nis = np.full(K, np.nan)
    arrivals: dict[int, list[CameraFrame]] = defaultdict(list)
    for fr in _given_frames(log):
        arrivals[fr.delivery_step].append(fr)
    counters = dict.fromkeys(DECISION_COUNTERS, 0)
    rows: list[tuple[int, int, float, bool]] = []
    for k in range(K):
        if k > 0:
            z = log.z[k]
            zk = z if np.isfinite(z).all() else None
            frames = arrivals.get(k, [])
            rep = est.step(log.u[k - 1], zk, frames)
            count_decisions(counters, rep)
            if rep.encoder_nis is not None:
                enc_nis[k] = rep.encoder_nis
            rows.extend(_frame_rows(rep, frames, k))
        x, P = est.x[:N], est.P[:N, :N]  # the input states, if any, left out
        x_hat[k], P_diag[k] = x, np.diag(P)
        if nees is not None and log.truth is not None and np.isfinite(log.truth[k]).all():
            e = log.truth[k] - x
            nees[k] = float(e @ np.linalg.solve(P, e))
        if progress is not None and (k + 1) % 1000 == 0:
            progress(1000)
    frame_nis = FrameNis(
        np.array([r[0] for r in rows], np.int64),
        np.array([r[1] for r in rows], np.int64),
        np.array([r[2] for r in rows], np.float64),
        np.array([r[3] for r in rows], np.bool_),
    )
    return LogEstimate(x_hat, P_diag, nees, counters, enc_nis, frame_nis)


def _frame_rows(
    rep: StepReport, frames: list[CameraFrame], k: int
) -> list[tuple[int, int, float, bool]]:
    """Each delivered frame's (kappa, arrival, NIS, fused) from a step's report: the frames
    that reached an update are ``rep.used`` with ``rep.frame_nis``; gated ones are named in
    ``rep.rejections`` (``StepReport.frame_result``)."""
    nis = dict(zip(rep.used, rep.frame_nis, strict=True))
    gated = {
        kappa
        for kappa in nis
        if any(r.startswith(f"camera frame kappa={kappa} gated out") for r in rep.rejections)
    }
    rows = []
    for fr in frames:
        kappa = int(fr.exposure_step)
        finite = bool(np.isfinite(np.asarray(fr.z, dtype=np.float64)).all())
        value = (
            nis.pop(kappa, None) if finite else None
        )  # a second frame of the same exposure: a duplicate
        rows.append(
            (
                kappa,
                k,
                np.nan if value is None else float(value),
                value is not None and kappa not in gated,
            )
        )
    return rows


def _batch(log: RobotLog, est: Estimator, progress: Callable[[int], None] | None) -> LogEstimate:
    from amsfe_sym.runtime.compiled_estimator import STATUS, CompiledEstimator, frame_reason
    from amsfe_sym.runtime.estimator_batch import run_log

    est = cast(CompiledEstimator, est)  # _batch_ok checked it
    kappa, arrival, fz = _frame_arrays(_given_frames(log))
    res = run_log(est, log.u, log.z, kappa, arrival, fz, log.truth, progress)
    K = log.K
    counters = dict.fromkeys(DECISION_COUNTERS, 0)
    has_z = np.asarray(np.isfinite(log.z).all(axis=1), dtype=np.bool_)
    has_z[:1] = False
    rejected = ~res.encoder_accepted[1:]
    counters["encoder_rejected"] = int(rejected.sum()) if K > 1 else 0
    counters["refused_gated"] += int((has_z & ~res.encoder_accepted).sum())
    for status, kap in zip(res.frame_status.tolist(), kappa.tolist(), strict=True):
        if status == STATUS["ok"]:
            counters["frames_applied"] += 1
        elif status != STATUS["ignored"]:
            counters["frames_rejected"] += 1
            counters[f"refused_{refusal_kind(frame_reason(est, status, kap))}"] += 1
    fused = res.frame_status == STATUS["ok"]
    frame_nis = FrameNis(kappa, arrival, res.frame_nis, fused)
    return LogEstimate(res.x_hat, res.P_diag, res.nees, counters, res.encoder_nis, frame_nis)
