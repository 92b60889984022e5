"""The simulated camera's marker fixed to its link, from a robot spec with ``[tracked]
orientation`` (docs/camera.md, "The marker fixed to its link"): the tracked frame's
placement by Pinocchio and the marker's rotation on it, for
:class:`~amsfe_sym.vision.marker_pose.MarkerPose`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.load.rotation import quaternion_to_matrix
from amsfe_sym.load.types import Robot
from amsfe_sym.vision.marker_pose import MarkerPose

__all__ = ["marker_pose_of", "robot_marker_pose"]


def robot_marker_pose(robot: Robot, orientation: tuple[float, float, float, float]) -> MarkerPose:
    """The marker on ``robot``'s tracked frame (at its tracked offset), its frame turned by
    the unit quaternion ``orientation`` ``[qx, qy, qz, qw]`` in the tracked frame."""
    import pinocchio as pin

    data = robot.model.createData()
    fid = robot.tracked_frame_id

    def placement(q: FloatArray) -> tuple[FloatArray, FloatArray]:
        pin.framesForwardKinematics(robot.model, data, robot.to_pin_q(q))
        M = data.oMf[fid]
        return np.array(M.translation, dtype=np.float64), np.array(M.rotation, dtype=np.float64)

    return MarkerPose(placement, robot.tracked_offset, quaternion_to_matrix(orientation))


def marker_pose_of(
    spec_path: str | Path | None, locked: Mapping[str, float] | None = None
) -> MarkerPose | None:
    """The marker of the robot spec ``spec_path`` (a name, folder or file; its joints in
    ``locked`` locked, as its library's manifest says), or None when the spec gives no
    ``[tracked] orientation`` (or there is no spec): the marker then faces the camera."""
    if spec_path is None:
        return None
    from amsfe_sym.load import load_robot
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(spec_path)
    if spec.tracked.orientation is None:
        return None
    robot = load_robot(spec.with_locked(dict(locked or {})))
    return robot_marker_pose(robot, spec.tracked.orientation)
