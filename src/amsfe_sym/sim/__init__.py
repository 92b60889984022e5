"""Simulation: sensors (encoders, camera, torque noise) and desired trajectories.

Pure numpy; all randomness comes from a :class:`numpy.random.Generator` passed in.
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
