"""Simulation: sensors (encoders, camera, torque noise), desired trajectories, and the
closed loop.

- ``sensors``, ``trajectory``: the signals (pure numpy; all randomness comes from a
  :class:`numpy.random.Generator` passed in); re-exported here;
- ``builders``: a scenario + a library -> plant start, sensors, estimator, controller;
- ``loop``: :func:`~amsfe_sym.sim.loop.run`, the closed-loop simulation;
- ``record``: the run folder and the summary metrics.

Importing this package does not import the closed loop (``builders``, ``loop``,
``record``); import those modules by name.
"""

from amsfe_sym.sim.sensors import (
    Camera,
    CameraConfig,
    CameraFrame,
    CameraStats,
    Disturbance,
    EncoderConfig,
    Encoders,
    TorqueNoise,
)
from amsfe_sym.sim.trajectory import (
    Constant,
    PaperExperiment,
    Sinusoid,
    Trajectory,
    TrajectoryPoint,
    tip_circle,
)
from amsfe_sym.sim.trajectory import from_config as trajectory_from_config

__all__ = [
    "Camera",
    "CameraConfig",
    "CameraFrame",
    "CameraStats",
    "Constant",
    "Disturbance",
    "EncoderConfig",
    "Encoders",
    "PaperExperiment",
    "Sinusoid",
    "TorqueNoise",
    "Trajectory",
    "TrajectoryPoint",
    "tip_circle",
    "trajectory_from_config",
]
