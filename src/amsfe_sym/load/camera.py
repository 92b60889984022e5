"""The camera of a robot: the spec's values, or defaults that frame the tracked point's
workspace."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.errors import SpecError, describe
from amsfe_sym.load.rotation import quaternion_to_matrix
from amsfe_sym.load.spec import RobotSpec
from amsfe_sym.load.types import CameraModel

__all__ = ["resolve_camera", "workspace"]


def workspace(
    model: pin.Model, frame_id: int, offset: tuple[float, float, float], count: int = 256
) -> tuple[NDArray[np.float64], float]:
    """Centre [m] and radius [m] of the tracked point's reachable set, from random q."""
    data = model.createData()
    rng = np.random.default_rng(0)  # deterministic: the default camera is part of the model
    pts = []
    for _ in range(count):
        q = pin.neutral(model)
        for jid in range(1, model.njoints):
            j = model.joints[jid]
            if j.nq == 2:  # continuous: (cos, sin)
                a = rng.uniform(-math.pi, math.pi)
                q[j.idx_q], q[j.idx_q + 1] = math.cos(a), math.sin(a)
            else:
                lo, hi = model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]
                lo = max(lo, -math.pi) if np.isfinite(lo) else -math.pi
                hi = min(hi, math.pi) if np.isfinite(hi) else math.pi
                q[j.idx_q] = rng.uniform(lo, hi) if hi > lo else 0.0
        pin.framesForwardKinematics(model, data, q)
        pts.append(data.oMf[frame_id].act(np.asarray(offset, dtype=float)))
    P = np.array(pts)
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0))
    radius = float(np.max(np.linalg.norm(P - centre, axis=1)))
    return centre, max(radius, 0.05)


def resolve_camera(spec: RobotSpec, model: pin.Model, frame_id: int) -> CameraModel:
    """Resolve the camera.

    Defaults (bare URDF, or keys left out): the camera looks at the centre of the tracked
    point's workspace (sampled at random q) from 3 workspace radii away along -y, and the
    focal length puts the whole workspace sphere inside 90 % of the shorter image side.
    ``orientation`` (a quaternion, world-from-camera) replaces ``look_at`` / ``up``: then
    ``R_cw`` is its matrix transposed (the spec reader refuses both, or one without
    ``position``).
    """
    c = spec.camera
    if c.orientation is not None and c.position is not None:
        R_wc = quaternion_to_matrix(c.orientation)
        position = np.array(c.position, dtype=float)
        return _camera(spec, model, frame_id, R_wc.T, position)
    if c.look_at is None or c.position is None:  # a default needs the workspace
        centre, radius = workspace(model, frame_id, spec.tracked.offset)
    look_at = np.array(c.look_at, dtype=float) if c.look_at is not None else centre
    up = np.array(c.up, dtype=float)
    if c.position is not None:
        position = np.array(c.position, dtype=float)
    else:
        position = look_at + np.array([0.0, -3.0 * radius, 0.0])
    fwd = look_at - position
    if np.linalg.norm(fwd) < 1e-9:
        raise SpecError(
            describe(
                f"{spec.spec_path}: [camera]", "look_at != position", "equal points", "move one"
            )
        )
    z = fwd / np.linalg.norm(fwd)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise SpecError(
            describe(
                f"{spec.spec_path}: [camera] up",
                "a direction not parallel to the optical axis",
                str(up.tolist()),
                "choose another up vector",
            )
        )
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return _camera(spec, model, frame_id, np.vstack([x, y, z]), position)


def _camera(
    spec: RobotSpec,
    model: pin.Model,
    frame_id: int,
    R_cw: NDArray[np.float64],
    position: NDArray[np.float64],
) -> CameraModel:
    """The camera at ``position`` [m] with rotation ``R_cw`` (world -> camera): intrinsics
    the spec's, else the default focal length that frames the workspace."""
    c = spec.camera
    z = R_cw[2]
    if c.fx is not None:
        fx = c.fx
    else:
        centre, radius = workspace(model, frame_id, spec.tracked.offset)
        # the sphere (centre, radius) seen from `position`: its farthest image offset is
        # f * tan(angle to centre + half-angle of the sphere)
        to_c = centre - position
        dist = float(np.linalg.norm(to_c))
        ang = math.acos(float(np.clip(np.dot(to_c / max(dist, 1e-12), z), -1.0, 1.0)))
        half_angle = math.asin(min(radius / max(dist, 1e-12), 0.99))
        fx = 0.45 * min(c.width, c.height) / math.tan(min(ang + half_angle, 1.4))
    fy = c.fy if c.fy is not None else fx
    cx = c.cx if c.cx is not None else c.width / 2.0
    cy = c.cy if c.cy is not None else c.height / 2.0
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return CameraModel(
        K=K,
        R_cw=R_cw,
        position=position,
        width=c.width,
        height=c.height,
        period=c.period,
        delay=c.delay,
    )
