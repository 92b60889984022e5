"""Builders of a closed-loop run: each turns a scenario and a library into one part.

:func:`amsfe_sym.sim.loop.run` calls them in this order; ``bench`` and ``study`` call the
same ones (to check a scenario before a pool starts, or to time a part alone):

1. :func:`plant_start`: the true initial state [q, qd, qm, qmd];
2. :func:`build_sensors`: encoders, the camera with its resolved timing
   (:func:`~amsfe_sym.scenario.camera_timing`), disturbance torques;
3. :func:`filter_config` and :func:`build_estimator`: the estimator, its noise models,
   x(0|0) and P(0|0);
4. :func:`build_controller`: the desired trajectory and the controller;

and :func:`build_run` does all four (``study`` uses it to check a scenario before its
worker pool starts).

Everything here reads the library (never the code generator), so it imports no CasADi and
no Pinocchio.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.control import Controller, make_controller
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation import Estimator, FilterConfig, make_estimator
from amsfe_sym.estimation.effort import EffortSpec, MotorParams, input_noise_std
from amsfe_sym.estimation.effort_models import (
    EffortModels,
    SpringTorqueMeasurement,
    wrap_models,
)
from amsfe_sym.estimation.registry import estimator_class
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)
from amsfe_sym.scenario import CameraTiming, Scenario, camera_timing
from amsfe_sym.signals import Camera, CameraConfig, Disturbance, EncoderConfig, Encoders
from amsfe_sym.signals.trajectory import Trajectory
from amsfe_sym.signals.trajectory import from_config as trajectory_from_config

__all__ = [
    "RunParts",
    "Sensors",
    "build_controller",
    "build_estimator",
    "build_run",
    "build_sensors",
    "filter_config",
    "motor_params",
    "plant_start",
    "scenario_timing",
]

FloatArray = NDArray[np.float64]

#: Default 1-sigma of the estimator's initial covariance per block (``[estimate0] std``).
DEFAULT_P0_STD = {"q": 0.5, "qd": 0.5, "qm": 0.01, "qmd": 0.1, "theta": 0.2}


def _vec(values: tuple[float, ...], n: int, what: str) -> FloatArray:
    if len(values) != n:
        raise ConfigError(describe(what, f"{n} values", f"{len(values)}", "one per joint"))
    return np.array(values, dtype=float)


def scenario_timing(sc: Scenario, lib: ModelLibrary) -> CameraTiming:
    """:func:`~amsfe_sym.scenario.camera_timing` of ``sc`` with the robot's l and d read
    from the library's manifest (the same values as its robot spec)."""
    return camera_timing(
        sc,
        lib.manifest.camera.period,
        lib.manifest.camera.delay,
        needs_history=estimator_class(sc.estimator).needs_history,
    )


def plant_start(sc: Scenario, lib: ModelLibrary) -> FloatArray:
    """The true initial plant state [q, qd, qm, qmd] (``[plant]``; theta is the true one).

    ``motor0 = "equilibrium"`` puts the motors where the springs hold the links still
    (qm = q + Ks^-1 g(q)); ``"link"`` sets qm = q; ``"explicit"`` reads ``qm0``, ``qmd0``.
    """
    n = lib.n
    q0 = _vec(sc.plant.q0, n, "[plant] q0")
    qd0 = _vec(sc.plant.qd0, n, "[plant] qd0")
    if sc.plant.motor0 == "equilibrium":
        theta_true = lib.theta_true
        g = lib.function("gravity")(q0, theta_true)[0]
        qm0, qmd0 = q0 + g / lib.stiffness(theta_true), qd0.copy()
    elif sc.plant.motor0 == "link":
        qm0, qmd0 = q0.copy(), qd0.copy()
    else:
        qm0 = _vec(sc.plant.qm0, n, "[plant] qm0")
        qmd0 = _vec(sc.plant.qmd0, n, "[plant] qmd0")
    return np.concatenate([q0, qd0, qm0, qmd0])


@dataclass
class Sensors:
    """The simulated sensors of a run and the camera timing they use.

    Attributes:
        encoders: Motor encoders, sampled every step.
        camera: The camera: exposes every l steps, delivers d (+ jitter) steps later.
        disturbance: Torque noise on the plant [N m].
        timing: The camera's resolved timing.
    """

    encoders: Encoders
    camera: Camera
    disturbance: Disturbance
    timing: CameraTiming


def build_sensors(
    sc: Scenario, lib: ModelLibrary, rng: np.random.Generator, timing: CameraTiming
) -> Sensors:
    """Encoders, camera and disturbance of ``sc``, each with its own stream of ``rng``
    (spawned in that order, so a seed gives the same samples as before the split)."""
    n = lib.n
    rng_enc, rng_cam, rng_dist = rng.spawn(3)
    enc = Encoders(
        n,
        EncoderConfig(
            q_std=sc.encoders.q_std,
            qd_std=sc.encoders.qd_std,
            counts_per_rev=sc.encoders.counts_per_rev or None,
        ),
        rng_enc,
    )
    cam_cfg = CameraConfig(
        period=timing.period,
        delay=timing.delay,
        phase=timing.phase,
        pixel_std=sc.camera.pixel_std,
        round_to_pixel=sc.camera.round_to_pixel,
        drop_probability=sc.camera.drop_probability,
        jitter_steps=timing.jitter_steps,
        width=lib.manifest.camera.width,
        height=lib.manifest.camera.height,
    )
    cam_fn = lib.function("camera_measure")
    theta_true = lib.theta_true

    def project(q: FloatArray) -> FloatArray:
        y, _J, depth = cam_fn.call_into(q, theta_true)
        return y.copy() if depth[0] > 0 else np.full(2, np.nan)

    camera = Camera(cam_cfg, project, rng_cam)
    disturbance = Disturbance(n, sc.plant.link_torque_std, sc.plant.motor_torque_std, rng_dist)
    return Sensors(enc, camera, disturbance, timing)


def filter_config(sc: Scenario, timing: CameraTiming) -> FilterConfig:
    """The estimator's :class:`FilterConfig` from ``[filter]`` and the camera timing."""
    f = sc.filter
    return FilterConfig(
        gate_probability=f.gate_probability or None,
        camera_iterations=f.camera_iterations,
        buffer_steps=f.buffer_steps,
        camera_period=timing.period,
        camera_phase=timing.phase,
        camera_max_delay=timing.max_delay,
        backward_map=f.backward_map,
    )


def motor_params(lib: ModelLibrary) -> MotorParams:
    """The actuators of eq. (1b) and the stiffness parameters of ``lib``, for
    :mod:`amsfe_sym.estimation.effort`."""
    act = lib.manifest.actuators
    return MotorParams(
        Ks=np.array(act.Ks, dtype=float),
        Mm=np.array(act.Mm, dtype=float),
        Fm=np.array(act.Fm, dtype=float),
        T=lib.T,
        p=lib.p,
        stiffness_theta=lib.stiffness_theta_index,
        u_max=np.array(act.u_max or [np.inf] * lib.n, dtype=float),
    )


def build_estimator(
    sc: Scenario,
    lib: ModelLibrary,
    sensors: Sensors,
    z0: FloatArray,
    compiled: bool = False,
    effort: EffortSpec | None = None,
) -> Estimator:
    """The estimator of ``sc`` with its models, x(0|0) and P(0|0).

    Args:
        sc: The scenario (``estimator``, ``[filter]``, ``[estimate0]``).
        lib: The library (the compiled transition and camera).
        sensors: The run's sensors: R defaults to their true noise (quantization included).
        z0: The first encoder sample [qm, qmd] (``[estimate0] motor = "encoders"``).
        compiled: Build the library's C estimator (same arguments, same numbers) instead
            of the Python reference.
        effort: What the log's effort is (docs/explanation/effort.md); ``None``: the applied torque.
            ``joint_torque``: the encoder model is
            :class:`~amsfe_sym.estimation.effort.SpringTorqueMeasurement` (``z = [qm, qmd,
            tau_J]``); ``joint_torque`` and ``none`` add the input's
            :func:`~amsfe_sym.estimation.effort.input_noise_std` to ``[filter]
            motor_torque_std`` in quadrature.  Feed the estimator with
            :func:`~amsfe_sym.estimation.effort.estimator_inputs`.

    Raises:
        ConfigError: an unknown estimator, a singular camera R, bad initial values, or the
            compiled estimator asked for what it does not compute (oosm's inverse backward
            map with input states or a net torque input; docs/explanation/effort.md).
    """
    n, p = lib.n, lib.p
    f = sc.filter
    effort = effort or EffortSpec()
    link_std, motor_std0 = f.link_torque_std, f.motor_torque_std
    if lib.manifest.integrator == "paper" and f.paper_torque_std > 0:
        link_std = motor_std0 = f.paper_torque_std  # the explicit map's model error
    enc_var = sensors.encoders.variance
    q_var = f.encoder_q_std**2 if f.encoder_q_std else enc_var[:n]
    qd_var = f.encoder_qd_std**2 if f.encoder_qd_std else enc_var[n:]
    motor = motor_params(lib)
    extra = input_noise_std(effort, motor, np.sqrt(qd_var))
    motor_std = np.sqrt(np.asarray(motor_std0, dtype=float) ** 2 + extra**2)
    compiled_model = CompiledTransition(
        lib, noise_covariance(lib, link_std, motor_std, f.theta_rate_std)
    )
    encoder_model: EncoderMeasurement | SpringTorqueMeasurement
    if effort.kind == "joint_torque":
        encoder_model = SpringTorqueMeasurement(motor, q_var, qd_var, effort.joint_torque_std**2)
    else:
        encoder_model = EncoderMeasurement(lib, q_var, qd_var)
    cam_var = f.camera_pixel_std**2 if f.camera_pixel_std else sensors.camera.config.variance
    if cam_var <= 0:
        raise ConfigError(
            describe(
                "[filter] camera_pixel_std",
                "a positive camera noise for the filter's R",
                "0, and a noise-free camera that does not round to pixels",
                "set [filter] camera_pixel_std > 0 (an exact camera makes R singular)",
            )
        )
    camera_model = CameraMeasurement(lib, cam_var)
    e0 = sc.estimate0
    th0 = np.array(e0.theta, dtype=float) if e0.theta else lib.theta_initial
    x0 = np.concatenate(
        [
            _vec(e0.q, n, "[estimate0] q"),
            _vec(e0.qd, n, "[estimate0] qd"),
            z0[:n] if e0.motor == "encoders" else _vec(e0.q, n, "q"),
            z0[n:] if e0.motor == "encoders" else _vec(e0.qd, n, "qd"),
            th0,
        ]
    )
    std = {**DEFAULT_P0_STD, **dict(e0.std)}
    P0 = np.diag(
        np.concatenate(
            [
                np.full(n, std["q"]),
                np.full(n, std["qd"]),
                np.full(n, std["qm"]),
                np.full(n, std["qmd"]),
                np.full(p, std["theta"]),
            ]
        )
        ** 2
    )
    g0 = lib.function("gravity")(x0[:n], th0)[0]  # the torque holding the arm at x0
    plain = EffortModels(compiled_model, encoder_model, camera_model, x0, P0)
    parts = wrap_models(effort, motor, plain, u0=g0 + motor.Fm * x0[3 * n : 4 * n])
    make = make_compiled_estimator if compiled else make_estimator
    return make(sc.estimator, **parts.estimator_args(), config=filter_config(sc, sensors.timing))


def build_controller(sc: Scenario, lib: ModelLibrary) -> tuple[Controller, Trajectory]:
    """The desired trajectory (``[trajectory]``) and the controller tracking it."""
    traj = trajectory_from_config(dict(sc.trajectory))
    if traj.n != lib.n:
        raise ConfigError(
            describe(
                "[trajectory]",
                f"{lib.n} joints (the robot's)",
                f"{traj.n}",
                "give one value per modelled joint in the trajectory table",
            )
        )
    return make_controller(sc.controller, lib, traj, sc.gains_for()), traj


@dataclass
class RunParts:
    """Every part of a run, built and ready for the loop.

    Attributes:
        timing: The camera's resolved timing.
        plant0: True initial plant state [q, qd, qm, qmd].
        sensors: Encoders, camera, disturbance.
        z0: The first encoder sample (taken at the plant start).
        estimator: The estimator, at x(0|0), P(0|0).
        controller: The controller.
        trajectory: The desired trajectory.
    """

    timing: CameraTiming
    plant0: FloatArray
    sensors: Sensors
    z0: FloatArray
    estimator: Estimator
    controller: Controller
    trajectory: Trajectory


def build_run(sc: Scenario, lib: ModelLibrary, compiled: bool = False) -> RunParts:
    """All parts of a run of ``sc`` on ``lib``, in the loop's order (the random streams of
    ``sc.seed`` are drawn as the loop draws them); ``compiled``: the estimator is the
    library's C one.

    Raises:
        ConfigError: whatever a builder refuses (camera timing, names, shapes, noise).
    """
    timing = scenario_timing(sc, lib)
    plant0 = plant_start(sc, lib)
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), timing)
    L = lib.layout
    z0 = sensors.encoders.measure(plant0[L["qm"]], plant0[L["qmd"]])
    estimator = build_estimator(sc, lib, sensors, z0, compiled)
    controller, trajectory = build_controller(sc, lib)
    return RunParts(timing, plant0, sensors, z0, estimator, controller, trajectory)
