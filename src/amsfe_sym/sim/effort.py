"""Simulated logs with each kind of effort, and the estimator run over them
(docs/explanation/effort.md).

A simulated run (:class:`~amsfe_sym.sim.result.RunResult`) holds the truth, the applied
torque ``u`` and the encoder samples.  :func:`simulated_effort` writes what an arm would log
as its effort: ``u`` (``applied``), the true spring torque ``Ks (qm - q)`` plus white sensor
noise (``joint_torque``, as a Franka or iiwa torque sensor), or nothing (``none``).
:func:`refilter` runs an estimator over the run's recorded sensors with that effort, the way
a log is estimated, and measures it against the truth (link-angle error and NEES).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.estimation import Estimator
from amsfe_sym.estimation.effort import (
    EffortSpec,
    EstimatorInputs,
    encoder_row,
    estimator_inputs,
)
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.builders import Sensors, build_estimator, build_run, motor_params
from amsfe_sym.sim.result import RunResult

__all__ = [
    "EffortEstimator",
    "Refiltered",
    "effort_estimator",
    "frames_by_delivery",
    "refilter",
    "simulated_effort",
]

FloatArray = NDArray[np.float64]


def simulated_effort(
    run: RunResult, kind: str, rng: np.random.Generator, joint_torque_std: float
) -> FloatArray | None:
    """What an arm with effort ``kind`` logs over ``run`` [N m], (K, n), or ``None``.

    ``joint_torque``: ``Ks(theta_true) (qm - q)`` of the true state (the spring torque of
    eq. (1b); this model has no spring damping) plus white noise of ``joint_torque_std``.
    """
    if kind == "none":
        return None
    if kind == "applied":
        return run.u.copy()
    lib = run.lib
    n = lib.n
    L = lib.layout
    Ks = lib.stiffness(lib.theta_true)
    tau = Ks * (run.x_true[:, L["qm"]] - run.x_true[:, L["q"]])
    return np.asarray(tau + joint_torque_std * rng.standard_normal((tau.shape[0], n)))


def frames_by_delivery(frames: FloatArray, K: int) -> list[list[CameraFrame]]:
    """The rows ``(exposure, delivery, u, v)`` of ``RunResult.frames`` grouped by delivery
    step, ``K`` lists."""
    out: list[list[CameraFrame]] = [[] for _ in range(K)]
    for kappa, k, u, v in frames:
        out[int(k)].append(CameraFrame(exposure_step=int(kappa), z=np.array([u, v])))
    return out


@dataclass(frozen=True)
class EffortEstimator:
    """An estimator built for a log's kind of effort, and what to feed it.

    Step ``k -> k+1`` is ``estimator.step(inputs.u[k], inputs.z_encoder[k+1], frames)``
    (a row of ``z_encoder`` holding NaN: pass ``None``); the robot's state is
    ``estimator.x[:N]``, its covariance ``estimator.P[:N, :N]`` (the input states, if any,
    follow).

    Attributes:
        estimator: The estimator at x(0|0), P(0|0).
        inputs: Its inputs and encoder measurements per step.
        N: The robot's state size (eq. 2).
    """

    estimator: Estimator
    inputs: EstimatorInputs
    N: int


def effort_estimator(
    sc: Scenario,
    lib: ModelLibrary,
    sensors: Sensors,
    z: FloatArray,
    effort: FloatArray | None,
    spec: EffortSpec,
    compiled: bool = False,
) -> EffortEstimator:
    """The estimator of ``sc`` for a log with effort ``spec.kind`` (docs/explanation/effort.md).

    Args:
        sc: The scenario (``estimator``, ``[filter]``, ``[estimate0]``).
        lib: The robot's library.
        sensors: The sensors (encoder and camera noise, camera timing), as for
            :func:`~amsfe_sym.sim.builders.build_estimator`.
        z: Encoder samples ``[qm, qmd]`` per step, (K, 2n) (NaN rows: no sample).
        effort: The logged effort [N m], (K, n), or ``None`` (``none``).
        spec: What the effort is.
        compiled: The library's C estimator instead of the Python reference (not oosm's
            inverse backward map with input states or a net torque input:
            :class:`~amsfe_sym.errors.ConfigError`; docs/explanation/effort.md).
    """
    n = lib.n
    e0 = None if effort is None or spec.kind != "joint_torque" else effort[0]
    z0 = encoder_row(spec, z[0], e0, motor_params(lib))[: 2 * n]
    est = build_estimator(sc, lib, sensors, z0, compiled=compiled, effort=spec)
    qd_std = np.sqrt(np.diag(est.R_encoder)[n : 2 * n])
    inputs = estimator_inputs(spec, z, effort, motor_params(lib), qd_std)
    return EffortEstimator(est, inputs, lib.N)


@dataclass(frozen=True)
class Refiltered:
    """An estimator's run over a simulated log, against the truth.

    Attributes:
        x_hat: Posterior means x(k|k), (K, N) (input states, if any, left out; NEES is of
            the robot's N states).
        e_q: Link-angle error q - q_hat [rad], (K, n).
        nees: NEES of the whole state, (K,).
        nees_q: NEES of the link angles alone (their marginal covariance), (K,).
        frames_applied: Camera frames fused.
    """

    x_hat: FloatArray
    e_q: FloatArray
    nees: FloatArray
    nees_q: FloatArray
    frames_applied: int


def refilter(
    sc: Scenario,
    run: RunResult,
    effort: FloatArray | None,
    spec: EffortSpec,
    estimator: str,
    compiled: bool = False,
) -> Refiltered:
    """Run ``estimator`` (the Python reference, or with ``compiled`` the C one) over ``run``'s
    encoders and frames with the effort ``effort`` of kind ``spec.kind``, and compare it with
    the truth.

    The estimator is built as the run's (``build_estimator`` of ``sc`` with ``estimator``),
    starting from the run's first encoder sample.
    """
    sc_e = sc.with_overrides(estimator=estimator)
    lib = run.lib
    z = run.z_enc
    sensors = build_run(sc_e, lib).sensors
    built = effort_estimator(sc_e, lib, sensors, z, effort, spec, compiled)
    est, inputs = built.estimator, built.inputs
    K = z.shape[0]
    delivered = frames_by_delivery(run.frames, K)
    N = lib.N
    x_hat = np.zeros((K, N))
    nees = np.zeros(K)
    nees_q = np.zeros(K)
    applied = 0
    Lq = lib.layout["q"]
    for k in range(K):
        if k > 0:
            applied += est.step(inputs.u[k - 1], inputs.z_encoder[k], delivered[k]).frames_applied
        x, P = est.x[:N], est.P[:N, :N]  # without the input states, if any
        x_hat[k] = x
        e = run.x_true[k] - x
        nees[k] = float(e @ np.linalg.solve(P, e))
        eq = e[Lq]
        nees_q[k] = float(eq @ np.linalg.solve(P[Lq, Lq], eq))
    return Refiltered(x_hat, run.x_true[:, Lq] - x_hat[:, Lq], nees, nees_q, applied)
