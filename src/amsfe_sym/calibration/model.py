"""The reprojection map the calibration fits, with the camera pose, the marker's offset (and,
fitting its corners, its orientation) and the camera's time offset as parameters, and its exact
jacobian (docs/calibrate.md).

For frame i with exposure stamp ``s_i`` [s] and measured pixel ``z_i`` [px]::

    q_i   = q(s_i - dt)                          link angles at the exposure (dt: time offset)
    r_i   = p_f(q_i) + R_f(q_i) o                the tracked point, eq. (7), o: marker offset
    pc_i  = Rod(w) R0 (r_i - c)                  the point in the camera frame
    y_i   = [fx X/Z + cx, fy Y/Z + cy]           the pinhole map of eq. (6)

Fitting the marker's 4 corners (a detector's, undistorted) each frame has 4 points: corner
``k`` at ``o + Rod(wm) Rm0 c_k`` in the tracked frame, ``c_k`` its place in the marker's
frame (OpenCV's ArUco one: ``size/2 (-1, 1, 0), (1, 1, 0), (1, -1, 0), (-1, -1, 0)``), ``Rm0``
the start's marker orientation in the tracked frame and ``wm`` [rad] a rotation vector about
the tracked frame's axes: 8 residuals a frame, 3 more parameters (:data:`CORNER_PARAMETERS`).

``dt`` is how much later the stamps are than the exposures (stamp = exposure + dt), ``c`` the
camera centre in the world [m], ``Rod(w) R0`` its world -> camera rotation: a rotation vector
``w`` [rad] (OpenCV's Rodrigues) applied on the camera side of the initial rotation ``R0``.
The tracked frame's placement ``p_f, R_f`` and its jacobian come from Pinocchio, the loader and
oracle of the generated functions (the generated ``tracked_point`` and ``camera`` have the
spec's offset and pose baked in; tests/test_calibrate_model.py compares this map with them
at the spec's pose to 1e-9 px and every column of the jacobian with finite differences).

Jacobian, chained: ``dy/dpc`` (pinhole) times ``dpc/dw = dRod/dw R0 (r - c)``,
``dpc/dc = -R``, ``dpc/dr = R``; ``dr/do = R_f``; ``dr/dq = Jv - [R_f o]x Jw`` (the frame
jacobian at the point, world-aligned); ``dq/d(dt) = -qdot`` (the interpolation's slope);
for a corner ``dr/dwm = R_f dRod/dwm (Rm0 c_k)`` and ``a = R_f (o + Rod(wm) Rm0 c_k)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.calibration.observations import LinkAngles
from amsfe_sym.core.camera_frame import MARKER_CORNERS
from amsfe_sym.load.types import Robot

__all__ = ["CORNER_PARAMETERS", "NP", "PARAMETERS", "Projection", "ReprojectionModel"]
__all__ += ["marker_corners_local"]


#: The parameter vector's entries, in order: camera rotation (rotation vector about the
#: camera's axes) [rad], camera position in the world [m], marker offset in the tracked
#: frame [m], time offset [s].
PARAMETERS: tuple[str, ...] = (
    "rot_x",
    "rot_y",
    "rot_z",
    "camera_x",
    "camera_y",
    "camera_z",
    "offset_x",
    "offset_y",
    "offset_z",
    "time_offset",
)
NP = len(PARAMETERS)
#: The corner fit's parameters: :data:`PARAMETERS`, then the marker's orientation (a rotation
#: vector about the tracked frame's axes, on the start's orientation) [rad].
CORNER_PARAMETERS: tuple[str, ...] = (*PARAMETERS, "marker_rot_x", "marker_rot_y", "marker_rot_z")


def marker_corners_local(size: float) -> FloatArray:
    """The marker's 4 corners (4, 3) [m] in its own frame (OpenCV's ArUco order and frame:
    top left, top right, bottom right, bottom left; x right, y up), ``size`` its side [m]."""
    return float(size) * MARKER_CORNERS


@dataclass(frozen=True)
class Projection:
    """The map at one parameter vector (P: points a frame, 1 or the 4 corners).

    Attributes:
        y: Predicted pixels (m, 2P) [px]: u, v of each point in turn.
        J: d y / d params (m, 2P, number of parameters).
        depth: Z of each point in the camera frame [m] (<= 0: behind the camera).
        valid: Frames whose link angles could be interpolated (an encoder sample on both
            sides of ``stamp - dt``); y and J are 0 elsewhere.
        r: The tracked point in the world (m, 3) [m].
    """

    y: FloatArray
    J: FloatArray
    depth: FloatArray
    valid: NDArray[np.bool_]
    r: FloatArray


class ReprojectionModel:
    """The calibration's camera map over a log's frames (module docstring).

    Args:
        robot: The loaded robot (Pinocchio model, tracked frame, intrinsics ``camera.K``).
        links: Link angles per encoder tick.
        stamp: Exposure stamps of the frames [s] (m,), on the links' clock.
        R0: The rotation the rotation vector is applied to (world -> camera).
        corners: The marker's corners in its frame (4, 3) [m] (:func:`marker_corners_local`)
            to fit them (the parameters :data:`CORNER_PARAMETERS`), or None: one point a
            frame, the tracked point (:data:`PARAMETERS`).
        Rm0: The start's marker orientation in the tracked frame (marker -> tracked frame)
            the marker's rotation vector is applied to (identity when None).
    """

    def __init__(
        self,
        robot: Robot,
        links: LinkAngles,
        stamp: FloatArray,
        R0: FloatArray,
        corners: FloatArray | None = None,
        Rm0: FloatArray | None = None,
    ) -> None:
        self.robot = robot
        self.local = np.zeros((1, 3)) if corners is None else np.asarray(corners, dtype=np.float64)
        self.names = PARAMETERS if corners is None else CORNER_PARAMETERS
        self.np = len(self.names)
        self.Rm0 = np.eye(3) if Rm0 is None else np.asarray(Rm0, dtype=np.float64)
        self._last: tuple[bytes, Projection] | None = None
        self.links = links
        self.stamp = np.asarray(stamp, dtype=np.float64)
        self.R0 = np.asarray(R0, dtype=np.float64)
        self.K = robot.camera.K
        self._data = robot.model.createData()
        self._cols = [j.idx_v for j in robot.joints]

    def rotation(self, w: FloatArray) -> FloatArray:
        """World -> camera rotation ``Rod(w) R0``."""
        R, _ = cv2.Rodrigues(np.asarray(w, dtype=np.float64).reshape(3, 1))
        return np.asarray(R) @ self.R0

    def marker_rotation(self, x: FloatArray) -> FloatArray:
        """Marker -> tracked frame rotation ``Rod(wm) Rm0`` at parameters ``x`` (``Rm0``
        in the centre fit)."""
        if self.np == NP:
            return self.Rm0.copy()
        R, _ = cv2.Rodrigues(np.asarray(x[NP : NP + 3], dtype=np.float64).reshape(3, 1))
        return np.asarray(R) @ self.Rm0

    def frame_kinematics(
        self, q: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Placement of the tracked frame and its world-aligned jacobian at link angles
        ``q`` (m, n): position (m, 3) [m], rotation (m, 3, 3), Jv and Jw (m, 3, n)."""
        robot, model, data = self.robot, self.robot.model, self._data
        fid = robot.tracked_frame_id
        m = q.shape[0]
        n = len(self._cols)
        p = np.zeros((m, 3))
        R = np.zeros((m, 3, 3))
        Jv = np.zeros((m, 3, n))
        Jw = np.zeros((m, 3, n))
        world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        for i in range(m):
            qp = robot.to_pin_q(q[i])
            pin.framesForwardKinematics(model, data, qp)
            J = pin.computeFrameJacobian(model, data, qp, fid, world)[:, self._cols]
            M = data.oMf[fid]
            p[i], R[i] = M.translation, M.rotation
            Jv[i], Jw[i] = J[:3], J[3:]
        return p, R, Jv, Jw

    def project(self, x: FloatArray) -> Projection:
        """Pixels and their jacobian at parameters ``x`` (:attr:`names` order); the last
        one is kept (``least_squares`` asks for the residuals, then the jacobian, at the
        same ``x``: one evaluation of the kinematics instead of two)."""
        x = np.asarray(x, dtype=np.float64)
        key = x.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        pr = self._project(x)
        self._last = (key, pr)
        return pr

    def _project(self, x: FloatArray) -> Projection:
        """:meth:`project` without the cache."""
        w, c, o, dt = x[0:3], x[3:6], x[6:9], float(x[9])
        q, qdot, valid = self.links.at(self.stamp - dt)
        m, P, npar = self.stamp.size, self.local.shape[0], self.np
        y = np.zeros((m, 2 * P))
        J = np.zeros((m, 2 * P, npar))
        depth = np.zeros(m)
        r = np.zeros((m, 3))
        idx = np.flatnonzero(valid)
        if idx.size == 0:
            return Projection(y, J, depth, valid, r)
        p_f, R_f, Jv, Jw = self.frame_kinematics(q[idx])
        Rod, dRod = cv2.Rodrigues(w.reshape(3, 1))
        R = np.asarray(Rod) @ self.R0
        dR = np.asarray(dRod).reshape(3, 3, 3)  # dR[j] = d Rod / d w_j
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        if npar > NP:
            Rm_rod, dRm = cv2.Rodrigues(x[NP : NP + 3].reshape(3, 1))
            dRm = np.asarray(dRm).reshape(3, 3, 3)
            Rm = np.asarray(Rm_rod) @ self.Rm0
        else:
            Rm = self.Rm0
        Zmin = np.full(idx.size, np.inf)
        for k in range(P):
            ck = self.local[k]
            a = R_f @ (o + Rm @ ck)  # (n, 3) the point's offset in the world
            rr = p_f + a
            v = (rr - c) @ self.R0.T  # R0 (r - c)
            pc = v @ np.asarray(Rod).T
            X, Y, Z = pc[:, 0], pc[:, 1], pc[:, 2]
            cols = slice(2 * k, 2 * k + 2)
            y[idx, cols] = np.stack([fx * X / Z + cx, fy * Y / Z + cy], axis=1)
            dy_dpc = np.zeros((idx.size, 2, 3))
            dy_dpc[:, 0, 0] = fx / Z
            dy_dpc[:, 0, 2] = -fx * X / Z**2
            dy_dpc[:, 1, 1] = fy / Z
            dy_dpc[:, 1, 2] = -fy * Y / Z**2
            dpc_dw = np.einsum("jab,kb->kaj", dR, v)  # (n, 3, 3)
            dy_dr = dy_dpc @ R  # (n, 2, 3)
            dr_dq = Jv - _skew(a) @ Jw  # (n, 3, joints)
            Jk = np.zeros((idx.size, 2, npar))
            Jk[:, :, 0:3] = dy_dpc @ dpc_dw
            Jk[:, :, 3:6] = -dy_dr
            Jk[:, :, 6:9] = dy_dr @ R_f
            Jk[:, :, 9] = -np.einsum("kan,kn->ka", dy_dr @ dr_dq, qdot[idx])
            if npar > NP:
                b = self.Rm0 @ ck
                dRm_b = np.einsum("jab,b->aj", dRm, b)  # (3, 3): d (Rod(wm) b) / d wm
                Jk[:, :, NP : NP + 3] = dy_dr @ R_f @ dRm_b
            J[idx, cols] = Jk
            Zmin = np.minimum(Zmin, Z)
        depth[idx] = Zmin
        r[idx] = p_f + R_f @ o
        return Projection(y, J, depth, valid, r)


def _skew(a: FloatArray) -> FloatArray:
    """Cross-product matrices [a]x of the rows of ``a`` (k, 3) -> (k, 3, 3)."""
    S = np.zeros((a.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -a[:, 2], a[:, 1]
    S[:, 1, 0], S[:, 1, 2] = a[:, 2], -a[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -a[:, 1], a[:, 0]
    return S
