"""The marker fixed to its link (robot.toml ``[tracked] orientation``): its corners as the
camera sees them, and whether the camera sees it at all (docs/camera.md, "The simulated
camera's images").

The marker's frame is OpenCV's ArUco one (:func:`~amsfe_sym.load.rotation.
read_marker_orientation`): centred on the tracked point, x right and y up as printed, z out
of the printed face; corner k at ``size/2 c_k``, ``c_k`` = (-1, 1), (1, 1), (1, -1), (-1, -1)
(top left, top right, bottom right, bottom left: OpenCV's order).  In the world, at link
angles q::

    P_k = p_f(q) + R_f(q) (o + R_m size/2 c_k)        eq. (7) of the tracked point, per corner

with ``p_f, R_f`` the tracked frame's placement (Pinocchio's: logs/sim_marker.py), ``o`` the
tracked offset and ``R_m`` the orientation's matrix; the corners are projected by the
pinhole (K, R_cw, position).  The diagonals of the projected square meet at the pinhole's
pixel of the tracked point ``p_f + R_f o`` (a projection keeps lines), so the centre the
estimator fuses is that of the facing-the-camera drawing.

The camera does not see the marker from behind (its z axis away from the camera), nor past
:data:`MAX_VIEW_DEG` from face-on, nor when its projected area is under
:data:`MIN_AREA_PX2`: such a frame is drawn without the marker.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.core.camera_frame import MARKER_CORNERS

__all__ = ["MARKER_CORNERS", "MAX_VIEW_DEG", "MIN_AREA_PX2", "MarkerPose", "MarkerView"]
__all__ += ["marker_view"]

FloatArray = NDArray[np.float64]

#: The largest angle [deg] between the marker's z axis and its line of sight to the camera
#: at which it is drawn.
MAX_VIEW_DEG = 75.0

#: The smallest projected area [px^2] of the black square that is drawn: the detector found
#: none of 30 face-on 11 x 11 px markers (123 px^2), 9 of 30 of 14 x 14 px (204 px^2):
#: tools/marker_view_accuracy.py, docs/camera.md.
MIN_AREA_PX2 = 120.0


@dataclass(frozen=True)
class MarkerView:
    """The marker as the pinhole camera sees it.

    Attributes:
        corners: The 4 corners (4, 2) [px] in the pinhole (rectified) image, OpenCV's order.
        angle_deg: The angle [deg] between the marker's z axis and the line from its centre
            to the camera (0: face-on; over 90: seen from behind).
        area_px2: The projected square's area [px^2].
        depth: The smallest depth of a corner in the camera frame [m] (<= 0: behind it).
    """

    corners: FloatArray
    angle_deg: float
    area_px2: float
    depth: float

    @property
    def seen(self) -> bool:
        """Whether the camera sees the marker: in front of it, within :data:`MAX_VIEW_DEG`
        of face-on, and at least :data:`MIN_AREA_PX2`."""
        return self.depth > 0 and self.angle_deg <= MAX_VIEW_DEG and self.area_px2 >= MIN_AREA_PX2


def marker_view(
    K: ArrayLike,
    R_cw: ArrayLike,
    position: ArrayLike,
    p_f: ArrayLike,
    R_f: ArrayLike,
    offset: ArrayLike,
    R_m: ArrayLike,
    size: float,
) -> MarkerView:
    """The marker of side ``size`` [m] on the frame placed at ``p_f`` [m], ``R_f`` (world
    from frame), at ``offset`` [m] and turned ``R_m`` (frame from marker) in that frame, as
    the pinhole camera (K, world -> camera ``R_cw``, ``position`` [m]) sees it (module
    docstring)."""
    Km, R = np.asarray(K, dtype=np.float64), np.asarray(R_cw, dtype=np.float64)
    Rf, Rm = np.asarray(R_f, dtype=np.float64), np.asarray(R_m, dtype=np.float64)
    centre = np.asarray(p_f, dtype=np.float64) + Rf @ np.asarray(offset, dtype=np.float64)
    world = centre + (size * MARKER_CORNERS) @ (Rf @ Rm).T
    pc = (world - np.asarray(position, dtype=np.float64)) @ R.T
    Z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.column_stack(
            [Km[0, 0] * pc[:, 0] / Z + Km[0, 2], Km[1, 1] * pc[:, 1] / Z + Km[1, 2]]
        )
    sight = R @ (np.asarray(position, dtype=np.float64) - centre)  # centre -> camera
    normal = R @ Rf @ Rm[:, 2]
    cos = float(normal @ sight) / max(float(np.linalg.norm(sight)), 1e-300)
    angle = math.degrees(math.acos(min(1.0, max(-1.0, cos))))
    x, y = uv[:, 0], uv[:, 1]
    area = 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))  # shoelace
    return MarkerView(uv, angle, area if np.isfinite(area) else 0.0, float(Z.min()))


class MarkerPose:
    """The marker fixed to its link: the tracked frame's placement at link angles q and the
    marker's place on it (built from a robot spec by
    :func:`amsfe_sym.logs.sim_marker.marker_pose_of`).

    Args:
        placement: ``(p_f [m], R_f)`` of the tracked frame (world from frame) at link angles
            q [rad].
        offset: The tracked point in the tracked frame ``o`` [m].
        R_m: The marker's frame in the tracked frame (the ``[tracked] orientation``'s matrix).
    """

    def __init__(
        self,
        placement: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
        offset: ArrayLike,
        R_m: ArrayLike,
    ) -> None:
        self.placement = placement
        self.offset = np.asarray(offset, dtype=np.float64)
        self.R_m = np.asarray(R_m, dtype=np.float64)

    def view(
        self, K: ArrayLike, R_cw: ArrayLike, position: ArrayLike, q: ArrayLike, size: float
    ) -> MarkerView:
        """The marker of side ``size`` [m] at link angles ``q`` [rad] as the pinhole camera
        (K, R_cw, position) sees it."""
        p_f, R_f = self.placement(np.asarray(q, dtype=np.float64).ravel())
        return marker_view(K, R_cw, position, p_f, R_f, self.offset, self.R_m, size)
