"""The closed loop on the compiled runtime: the same run as :func:`amsfe_sym.sim.loop.run`,
computed by the library's C loop (``runtime/c/amsfe_loop.c``).

The scenario is turned into parts by the same builders as the Python loop; the estimator is
the library's C estimator, the controller's parameter block is read off the Python
controller (so gains, limits and their checks have one home), and every random number is
drawn in one batch per sensor from the streams the Python loop draws from, in the same
order: a seed gives the same run on both paths (the tests require every recorded signal to
agree to 1e-8 and every decision to be the same).
"""

from __future__ import annotations

import logging
import time

import numpy as np

from amsfe_sym.control import Controller
from amsfe_sym.errors import ConfigError, EstimatorError, MeasurementError, describe
from amsfe_sym.runtime.compiled_estimator import CompiledEstimator
from amsfe_sym.runtime.compiled_loop import (
    CompiledController,
    CompiledSimulation,
    ControllerParams,
    SimulationInputs,
)
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.stability import NUMERICAL_FAILURES, covariance_hint
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.sim.builders import RunParts, build_run, build_sensors
from amsfe_sym.sim.result import (
    CAMERA_COUNTERS,
    DECISION_COUNTERS,
    DIVERGED_TRACKING_ERROR,
    RunResult,
    tick_bar,
)

__all__ = ["controller_params", "run_compiled", "simulation_inputs"]

log = logging.getLogger(__name__)

#: Ticks per call of the C loop when a progress bar is shown.
_CHUNK = 500


def controller_params(ctrl: Controller, lib: ModelLibrary) -> ControllerParams:
    """The C parameter block of the Python controller ``ctrl`` (its gains, already checked,
    from :meth:`~amsfe_sym.control.base.Controller.c_parameters`) and the library's actuator
    data.

    Raises:
        ConfigError: the controller has no C counterpart.
    """
    own = ctrl.c_parameters()
    if own is None:
        raise ConfigError(
            describe(
                "controller of a compiled run",
                "a controller the C runtime has (amsfe_sym.runtime.compiled_loop)",
                repr(ctrl.name),
                "use --runtime python",
            )
        )
    act = lib.manifest.actuators
    return ControllerParams(
        name=ctrl.name,
        T=lib.T,
        u_max=np.array(ctrl.u_max, dtype=float),
        Mm=np.array(act.Mm, dtype=float),
        Fm=np.array(act.Fm, dtype=float),
        Ks=np.array(act.Ks, dtype=float),
        ks_theta=lib.stiffness_theta_index,
        theta_initial=lib.theta_initial,
        **own,
    )


def simulation_inputs(
    sc: Scenario, lib: ModelLibrary, K: int, parts: RunParts
) -> tuple[SimulationInputs, np.ndarray]:
    """The inputs of a compiled run of ``K`` ticks and the desired link angles (K, n).

    The sensors are built again on fresh streams of ``sc.seed`` (as the Python loop builds
    them) and drawn in one batch each: encoders K rows (row 0 is the first sample's), the
    camera once per exposure step in [0, K), the disturbance K-1 rows (the last row is 0).
    """
    n = lib.n
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), parts.timing)
    t = np.arange(K, dtype=float) * lib.T
    ref_pt = parts.trajectory.evaluate(t)
    jerk, snap = parts.trajectory.higher(t)
    ref = np.hstack(
        [
            ref_pt.q.reshape(K, n),
            ref_pt.qd.reshape(K, n),
            ref_pt.qdd.reshape(K, n),
            jerk.reshape(K, n),
            snap.reshape(K, n),
        ]
    )
    cfg = sensors.camera.config
    exposures = int(np.count_nonzero(np.arange(K) % cfg.period == cfg.phase))
    cam_noise, cam_uniform, cam_jitter = sensors.camera.draw_batch(exposures)
    tau = np.zeros((K, 2 * n))
    tau[: K - 1] = sensors.disturbance.sample_batch(K - 1)
    res = sensors.encoders.config.resolution
    inputs = SimulationInputs(
        x_plant0=parts.plant0,
        theta_true=lib.theta_true,
        ref=ref,
        enc_noise=sensors.encoders.noise_batch(K),
        enc_resolution=0.0 if res is None else res,
        tau_d=tau,
        camera={
            "period": cfg.period,
            "phase": cfg.phase,
            "delay": cfg.delay,
            "width": cfg.width,
            "height": cfg.height,
            "pixel_std": cfg.pixel_std,
            "round_to_pixel": cfg.round_to_pixel,
            "drop_probability": cfg.drop_probability,
        },
        cam_noise=cam_noise,
        cam_uniform=cam_uniform,
        cam_jitter=cam_jitter,
        diverged_error=float(DIVERGED_TRACKING_ERROR),
    )
    return inputs, ref[:, :n].copy()


def run_compiled(scenario: Scenario, lib: ModelLibrary, progress: bool = False) -> RunResult:
    """Simulate ``scenario`` on the compiled runtime (see the module docstring).

    Raises:
        ConfigError: what the builders refuse, or what the C runtime cannot run (a full
            covariance: use ``runtime="python"``).
        EstimatorError: the estimator failed (its covariance lost positive definiteness...).
        MeasurementError: the plant state became NaN or inf.
    """
    sc = scenario
    n, N, T = lib.n, lib.N, lib.T
    K = run_ticks(sc, T, n, N)
    parts = build_run(sc, lib, compiled=True)
    est = parts.estimator
    assert isinstance(est, CompiledEstimator)
    ctrl = CompiledController(str(lib.library_path), controller_params(parts.controller, lib), n)
    inputs, q_des = simulation_inputs(sc, lib, K, parts)
    sim = CompiledSimulation(str(lib.library_path), est._h, ctrl, inputs, N)

    bar = tick_bar(sc, K, "compiled") if progress else None
    t0 = time.perf_counter()
    while True:
        state = sim.run(_CHUNK if bar is not None else K)
        if bar is not None:
            bar.update(state.ticks_done - bar.n)
        if state.status < 0 or state.diverged or state.k >= K:
            break
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    if state.status < 0:
        what = sim.status_string(state.status)
        cls = MeasurementError if state.plant_nonfinite else EstimatorError
        fix = "run with --runtime python to see where the reference fails"
        stiff = cls is EstimatorError and state.status in NUMERICAL_FAILURES
        hint = covariance_hint(lib.manifest.raw) if stiff else None
        if hint is not None:
            fix = hint
        elif cls is EstimatorError and not sc.filter.gate_probability:
            fix += (
                " (the camera gate is off, gate_probability = 0: an outlier fused unchecked is "
                "a likely cause; turn the gate on)"
            )
        raise cls(
            describe(
                f"compiled run of {sc.name} at step {state.k}",
                "a usable numerical result",
                f"status {state.status}: {what}",
                fix,
            )
        )
    last = int(state.ticks_done)
    rec = sim.rec
    c = state.counters()
    counters = {k: c[k] for k in (*DECISION_COUNTERS, *CAMERA_COUNTERS)}
    diverged_at = None
    tau_d = inputs.tau_d[:last].copy()
    if state.diverged:  # the Python loop stops before the plant step: no torque recorded
        tau_d[last - 1] = 0.0
        diverged_at = float(last - 1) * T
        log.warning("%s: the closed loop diverged at t = %.3f s", sc.name, diverged_at)
    cut = slice(0, last)
    return RunResult(
        scenario=sc,
        lib=lib,
        t=(np.arange(K, dtype=float) * T)[cut],
        x_true=rec.x_true[cut],
        x_hat=rec.x_hat[cut],
        P_diag=rec.P_diag[cut],
        nees=rec.nees[cut],
        q_des=q_des[cut],
        u=rec.u[cut],
        z_enc=rec.z_enc[cut],
        frames=rec.frames[: int(state.frames_recorded)].copy(),
        wall_time_s=wall,
        counters=counters,
        s=rec.s[cut],
        bound=rec.bound[cut],
        saturated=rec.saturated[cut],
        diverged_at=diverged_at,
        tau_d=tau_d,
        runtime="compiled",
    )
