"""A whole recorded log through a compiled estimator in one C call per chunk of ticks
(``amsfe_est_run`` of ``runtime/c/amsfe_runtime.h``; docs/how-to/logs.md, "Speed"): the numbers of
:meth:`CompiledEstimator.step` called tick by tick (tests/test_log_batch.py), without a
Python step per tick."""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, ShapeError, describe
from amsfe_sym.runtime.cheader import c_struct
from amsfe_sym.runtime.compiled_estimator import STATUS, CompiledEstimator

__all__ = ["BatchResult", "run_log"]


_Log = c_struct("_Log", "amsfe_runtime.h", "amsfe_est_log")
_LogOut = c_struct("_LogOut", "amsfe_runtime.h", "amsfe_est_log_out")


@dataclass
class BatchResult:
    """What :func:`run_log` computed (K ticks, F frames).

    Attributes:
        x_hat: x(k|k) per tick, (K, N) (the robot's states; input states, if any, in
            ``input_hat``).
        P_diag: The diagonal of P(k|k), (K, N).
        encoder_nis: NIS of each tick's encoder innovation (eqs. 15-17), (K,); NaN where no
            sample reached the update (a gated one keeps its NIS).
        encoder_accepted: The encoder update was applied, (K,).
        nees: e^T P^-1 e against the truth, (K,), or None without one.
        frame_nis: NIS of each frame that reached its update, (F,); NaN otherwise.
        frame_status: Each frame's status (:data:`STATUS`), (F,).
    """

    x_hat: FloatArray
    P_diag: FloatArray
    encoder_nis: FloatArray
    encoder_accepted: NDArray[np.bool_]
    nees: FloatArray | None
    frame_nis: FloatArray
    frame_status: NDArray[np.int32]
    input_hat: FloatArray | None = None
    """The input states' estimate [N m], (K, n), with the input carried as states."""


def run_log(
    est: CompiledEstimator,
    u: FloatArray,
    z: FloatArray,
    frame_exposure: NDArray[np.int64],
    frame_arrival: NDArray[np.int64],
    frame_z: FloatArray,
    truth: FloatArray | None = None,
    progress: Callable[[int], None] | None = None,
    chunk: int = 2000,
) -> BatchResult:
    """A whole log in C (``amsfe_est_run``): the numbers of ``est.step`` called per tick.

    Tick 0 records the current posterior; tick k >= 1 is ``est.step(u[k-1], z[k] or None,
    frames arriving at k)``.  The estimator must be fresh (``k == k0``, as built or
    reset); it is left at the last tick (its ``x``, ``P``, ``k`` and the exposures used).

    Args:
        est: A compiled estimator (its C object runs the log; this module is its friend
            and reads its handle).
        u: (K, n) input over [k, k+1] [N m] (ignored with the input carried as states).
        z: (K, 2n) encoder samples [rad, rad/s], (K, 3n) ``[qm, qmd, tau_J]`` [.., N m] with
            joint torque sensors; a row holding NaN: none.
        frame_exposure, frame_arrival: (F,) exposure and arrival ticks, arrival sorted.
        frame_z: (F, 2) pixels [px].
        truth: (K, N) true robot state for the NEES (of the N robot states), or None.
        progress: Called with the ticks done after each ``chunk`` of them.
        chunk: Ticks per C call.

    Raises:
        ConfigError: the estimator is not fresh, or the frames are not sorted by arrival.
        ShapeError: an array of another shape than one row per tick or per frame.
        EstimatorError: the runtime failed at a tick (its step named).
    """
    if est.k != est.k0:
        raise ConfigError(
            describe(
                f"compiled {est.name}.run_log",
                f"a fresh estimator (k = k0 = {est.k0})",
                f"k = {est.k}",
                "call reset() first",
            )
        )
    u, z = np.asarray(u, dtype=np.float64), np.asarray(z, dtype=np.float64)
    K, M, n = int(u.shape[0]) if u.ndim else 0, est.nx, int(est.dims.n)
    N, ne = int(est.dims.N), int(est.R_encoder.shape[0])
    F = int(np.size(frame_arrival))
    shapes = {
        "u": (u.shape, (K, n)),
        "z": (z.shape, (K, ne)),
        "frame_exposure": (np.shape(frame_exposure), (F,)),
        "frame_z": (np.shape(frame_z), (F, 2)),
    }
    if truth is not None:
        shapes["truth"] = (np.shape(truth), (K, N))
    for name, (found, expected) in shapes.items():
        if tuple(found) != expected:  # the C call reads these sizes: never guess
            raise ShapeError(
                describe(f"run_log {name}", f"shape {expected}", f"shape {found}", "pass "
                         "one row per tick (u, z, truth) and one per frame")
            )  # fmt: skip
    arrival = np.ascontiguousarray(frame_arrival, dtype=np.int64)
    if arrival.size and np.any(np.diff(arrival) < 0):
        raise ConfigError(
            describe("run_log frames", "sorted by arrival", "out of order", "sort them")
        )
    keep = [
        np.ascontiguousarray(u, dtype=np.float64),
        np.ascontiguousarray(z, dtype=np.float64),
        np.ascontiguousarray(frame_exposure, dtype=np.int64),
        arrival,
        np.ascontiguousarray(frame_z, dtype=np.float64).reshape(-1, 2),
    ]
    tr = None if truth is None else np.ascontiguousarray(truth, dtype=np.float64)
    out = BatchResult(
        np.zeros((K, M)),
        np.zeros((K, M)),
        np.full(K, np.nan),
        np.zeros(K, dtype=np.bool_),
        None if tr is None else np.full(K, np.nan),
        np.full(F, np.nan),
        np.full(F, -1000, dtype=np.int32),
    )
    acc = np.zeros(K, dtype=np.uint8)

    def ptr(a: Any) -> int | None:
        return None if a is None else int(a.ctypes.data)

    log = _Log(K, *(ptr(a) for a in keep[:2]), ptr(tr), F, *(ptr(a) for a in keep[2:]))
    rec = _LogOut(
        ptr(out.x_hat),
        ptr(out.P_diag),
        ptr(out.encoder_nis),
        ptr(acc),
        ptr(out.nees),
        ptr(out.frame_nis),
        ptr(out.frame_status),
        -1,
    )
    run = est._c["amsfe_est_run"]
    for start in range(0, K, max(1, chunk)):
        end = min(K, start + max(1, chunk))
        status = run(est._h, ctypes.byref(log), start, end, ctypes.byref(rec))
        if status != 0:
            est.k = est.k0 + int(rec.failed_step) - 1
            raise est._error("a log's tick", status)
        if progress is not None:
            progress(end - start)
    out.encoder_accepted = acc.astype(np.bool_)
    if M > N:  # the input states: out of the robot's state
        out.input_hat = out.x_hat[:, N:].copy()
        out.x_hat, out.P_diag = out.x_hat[:, :N].copy(), out.P_diag[:, :N].copy()
    est.k = est.k0 + max(K - 1, 0)
    used = (out.frame_status == STATUS["ok"]) | (out.frame_status == STATUS["gated"])
    est._seen.update(int(s) for s in keep[2][used])
    est._fetch()
    return out
