"""Closed-loop simulation: plant (truth) -> sensors -> estimator -> controller.

One tick k (t_k = k T):

1. the sensors read the true plant state x_k: encoders every step, the camera exposes
   every l steps and delivers frames d steps later (``amsfe_sym.signals``);
2. the estimator advances from k-1 to k with u_{k-1}, the encoder sample and the frames
   delivered at k (``amsfe_sym.estimation``);
3. the controller computes u_k (``amsfe_sym.control``);
4. the plant integrates over [t_k, t_k + T] with u_k held (compiled RK4, ``plant_step``),
   with the true theta and optional disturbance torques.

The plant is the continuous-time Spong model, deliberately not the estimator's discrete
map, so the estimator meets model error as on a real arm.  The parts are built by
:mod:`amsfe_sym.sim.builders`; the library comes from the caller
(:func:`amsfe_sym.codegen.library_for` builds the one of a scenario).
"""

from __future__ import annotations

import logging
import time

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.control import LawInputs
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.sim.builders import build_run
from amsfe_sym.sim.result import (
    CAMERA_COUNTERS,
    DECISION_COUNTERS,
    DIVERGED_TRACKING_ERROR,
    RUNTIMES,
    RunResult,
    count_decisions,
    tick_bar,
)

__all__ = ["run"]

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


def run(
    scenario: Scenario,
    lib: ModelLibrary,
    progress: bool = False,
    runtime: str = "python",
    compiled_estimator: bool = False,
) -> RunResult:
    """Simulate ``scenario`` on the library ``lib`` and return the recorded signals
    (nothing is written; :func:`amsfe_sym.sim.record.write_run` writes a run folder).

    Args:
        scenario: The scenario.
        lib: Its library (:func:`amsfe_sym.codegen.library_for`).
        progress: Show a progress bar.
        runtime: ``"python"``: the readable reference loop below; ``"compiled"``: the same
            loop in the library's C runtime (:func:`amsfe_sym.sim.compiled.run_compiled`),
            which reproduces it (docs/how-to/runtime-c.md says how closely).
        compiled_estimator: Python loop only: use the library's C estimator (isolates the
            loop from the estimators' arithmetic when comparing the two runtimes).

    Raises:
        ConfigError: a setting the builders refuse, a duration shorter than one period or
            whose records would not fit :data:`~amsfe_sym.scenario.MAX_RECORD_BYTES`.  A
            diverging closed loop is not an error: the run stops there and
            ``RunResult.diverged_at`` says when.
    """
    if runtime not in RUNTIMES:
        raise ConfigError(
            describe("runtime", f"one of {list(RUNTIMES)}", repr(runtime), "use 'compiled'")
        )
    if runtime == "compiled":
        from amsfe_sym.sim.compiled import run_compiled  # the same run in C

        return run_compiled(scenario, lib, progress)
    sc = scenario
    n, N, T = lib.n, lib.N, lib.T
    L = lib.layout
    K = run_ticks(sc, T, n, N)
    theta_true = lib.theta_true

    parts = build_run(sc, lib, compiled=True) if compiled_estimator else build_run(sc, lib)
    xp, z0, est, ctrl, traj = (
        parts.plant0,
        parts.z0,
        parts.estimator,
        parts.controller,
        parts.trajectory,
    )
    enc, camera = parts.sensors.encoders, parts.sensors.camera
    disturbance = parts.sensors.disturbance
    plant = lib.function("plant_step")

    # ---------------------------------------------------------------- records
    t: FloatArray = np.arange(K, dtype=float) * T
    x_true = np.zeros((K, N))
    x_hat = np.zeros((K, N))
    P_diag = np.zeros((K, N))
    nees = np.zeros(K)
    q_des = traj.evaluate(t).q.reshape(K, n)
    ctrl.prepare(t)
    u_rec = np.zeros((K, n))
    z_rec = np.zeros((K, 2 * n))
    s_rec = np.full((K, n), np.nan)
    bound_rec = np.full((K, n), np.nan)
    saturated = np.zeros(K, dtype=bool)
    frames_rec: list[tuple[float, float, float, float]] = []
    counters = dict.fromkeys(DECISION_COUNTERS, 0)
    diverged_at: float | None = None
    tau_rec = np.zeros((K, 2 * n))

    bar = tick_bar(sc, K, "python") if progress else None
    u = np.zeros(n)
    x_t = np.zeros(N)
    x_t[4 * n :] = theta_true
    t0 = time.perf_counter()
    last = K
    for k in range(K):
        x_t[: 4 * n] = xp
        # 1. sensors at t_k
        z = z0 if k == 0 else enc.measure(xp[L["qm"]], xp[L["qmd"]])
        delivered = camera.tick(k, xp[L["q"]])
        for fr in delivered:
            frames_rec.append((fr.exposure_step, k, float(fr.z[0]), float(fr.z[1])))
        # 2. estimator k-1 -> k
        nis: float | None = None
        if k > 0:
            rep = est.step(u, z, delivered)
            count_decisions(counters, rep)
            nis = rep.encoder_nis
        xh, P = est.x, est.P
        # 3. controller, then the actuator limit
        u, saturated[k] = ctrl.saturate(
            ctrl.torque(LawInputs(k, float(t[k]), xp, theta_true, xh, z, np.diag(P), nis))
        )
        # record
        x_true[k] = x_t
        x_hat[k] = xh
        P_diag[k] = np.diag(P)
        err = x_t - xh
        nees[k] = float(err @ np.linalg.solve(P, err))
        u_rec[k] = u
        z_rec[k] = z
        s_rec[k] = ctrl.s
        bound_rec[k] = ctrl.bound
        if _diverged(xp, q_des[k], u):
            diverged_at, last = float(t[k]), k + 1
            log.warning("%s: the closed loop diverged at t = %.3f s", sc.name, t[k])
            break
        # 4. plant over [t_k, t_k + T]
        if k + 1 < K:
            dist = disturbance.sample()
            tau = np.concatenate([dist.link, dist.motor])
            tau_rec[k] = tau
            xp = plant.call_into(xp, u, theta_true, tau)[0].copy()
        if bar is not None and k % 250 == 0:
            bar.update(min(250, K - bar.n))
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.update(last - bar.n)  # a diverged run ends early, and so does its bar
        bar.close()
    stats = camera.stats
    counters.update(
        {name: int(getattr(stats, name.removeprefix("frames_"))) for name in CAMERA_COUNTERS}
    )
    cut = slice(0, last)
    return RunResult(
        scenario=sc,
        lib=lib,
        t=t[cut],
        x_true=x_true[cut],
        x_hat=x_hat[cut],
        P_diag=P_diag[cut],
        nees=nees[cut],
        q_des=q_des[cut],
        u=u_rec[cut],
        z_enc=z_rec[cut],
        frames=np.array(frames_rec, dtype=float).reshape(-1, 4),
        wall_time_s=wall,
        counters=counters,
        s=s_rec[cut],
        bound=bound_rec[cut],
        saturated=saturated[cut],
        diverged_at=diverged_at,
        tau_d=tau_rec[cut],
    )


def _diverged(xp: FloatArray, q_des: FloatArray, u: FloatArray) -> bool:
    """True when the plant state or the torque is not finite, or the link tracking error
    exceeds :data:`DIVERGED_TRACKING_ERROR`: the run stops there and says so."""
    n = q_des.size
    if not (np.all(np.isfinite(xp)) and np.all(np.isfinite(u))):
        return True
    return bool(np.max(np.abs(xp[:n] - q_des)) > DIVERGED_TRACKING_ERROR)
