"""The camera frame: the one value that travels from the simulated (or a real) camera to the
estimators.  Its own module so that ``sim`` and ``estimation`` both import it and neither
imports the other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["MARKER_CORNERS", "CameraFrame"]

FloatArray = NDArray[np.float64]

#: The marker's 4 corners in its own frame for a side of 1 (4, 3): OpenCV's ArUco frame
#: (centre at the tracked point, x right, y up as printed, z out of the printed face) and
#: order (top left, top right, bottom right, bottom left), the order of
#: :attr:`CameraFrame.corners`.  The simulated camera draws them, the corner fit fits them.
MARKER_CORNERS = 0.5 * np.array(
    [[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]]
)


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera measurement, delivered some steps after it was taken (the one frame type of
    the toolkit: the camera model of ``amsfe_sym.sim`` produces it, the estimators consume it).

    Attributes:
        exposure_step: kappa, the step index at which the image was taken (paper Sec. 3.2).
        z: Measurement ``(dim,)``, in the camera model's units (pixels for the pinhole map).
        delivery_step: Step at which the frame reached the estimator (``kappa + d`` plus
            jitter); ``-1`` when unknown.
        corners: The marker's 4 corners (4, 2) [px], undistorted, in OpenCV's order, when
            the frame comes from an image (the calibration's corner fit); None otherwise.

    ``eq=False``: frames compare by identity (an array field has no scalar equality).
    """

    exposure_step: int
    z: FloatArray
    delivery_step: int = -1
    corners: FloatArray | None = None

    @property
    def delay(self) -> int:
        """Steps from exposure to delivery, or -1 when the delivery step is unknown."""
        return -1 if self.delivery_step < 0 else self.delivery_step - self.exposure_step
