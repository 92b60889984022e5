"""Pinhole camera map y = I_m(r) (eq. 6) of the tracked point r = F_k(q) (eq. 7)."""

from __future__ import annotations

import casadi as ca

from amsfe_sym.load import CameraModel

__all__ = ["pinhole"]


def pinhole(camera: CameraModel, r_world: ca.SX) -> ca.SX:
    """Pixel coordinates [px] of the world point ``r_world`` [m] (OpenCV convention).

    ``y = [fx X/Z + cx, fy Y/Z + cy]`` with ``[X, Y, Z] = R_cw (r - c)`` the point in the
    camera frame.  Points behind the camera (Z <= 0) give meaningless pixels; the sensor
    model refuses them (the runtime checks Z through ``camera_depth``).
    """
    pc = ca.mtimes(ca.DM(camera.R_cw), r_world - ca.DM(camera.position.reshape(3, 1)))
    K = camera.K
    return ca.vertcat(K[0, 0] * pc[0] / pc[2] + K[0, 2], K[1, 1] * pc[1] / pc[2] + K[1, 2])


def depth(camera: CameraModel, r_world: ca.SX) -> ca.SX:
    """Distance [m] of ``r_world`` along the optical axis (positive in front of the camera)."""
    pc = ca.mtimes(ca.DM(camera.R_cw), r_world - ca.DM(camera.position.reshape(3, 1)))
    return pc[2]
