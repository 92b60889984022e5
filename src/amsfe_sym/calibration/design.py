"""What a calibration motion can determine, before it is recorded (docs/calibrate.md, "What
the motion must do").

For link angles over time (a planned motion), the camera's frame stamps and a pixel noise
``sigma`` [px]: the frames whose marker falls inside the image, and the covariance the fit of
:mod:`.solve` would state for its ten parameters, ``sigma^2 (J^T J)^-1`` with ``J`` the exact
jacobian of the same reprojection map (:class:`~amsfe_sym.calibration.model.ReprojectionModel`)
at the spec's camera pose and marker offset over the frames seen.  That is the linearised
covariance of step 6 of :mod:`.solve` without the noise that a recording adds to the link
angles: on frames the map makes itself the fit states these half-widths to a few %
(tests/test_calibrate_model.py), and on simulated recordings its errors follow them
(docs/calibrate.md, "Accuracy").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.calibration.model import NP, ReprojectionModel
from amsfe_sym.calibration.observations import LinkAngles
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.load.types import Robot

__all__ = ["MotionInformation", "motion_information"]

#: The 95 % two-sided normal quantile.
Z95 = 1.959963984540054


@dataclass(frozen=True)
class MotionInformation:
    """What a motion's frames pin down.

    Attributes:
        seen: Frames whose marker is in front of the camera and inside the image (m,).
        depth: The marker's distance along the optical axis at each frame (m,) [m].
        marker: The marker in the world at each frame (m, 3) [m].
        covariance: Of the ten parameters (:data:`~amsfe_sym.calibration.model.PARAMETERS`:
            rotation vector [rad], camera centre [m], marker offset [m], time offset [s]).
    """

    seen: NDArray[np.bool_]
    depth: FloatArray
    marker: FloatArray
    covariance: FloatArray

    @property
    def std(self) -> FloatArray:
        """1-sigma of each parameter, units of :attr:`covariance`."""
        return np.asarray(np.sqrt(np.diag(self.covariance)))

    def half_width95(self) -> FloatArray:
        """The 95 % half-width ``1.96 sigma`` of each parameter."""
        return Z95 * self.std

    def correlation(self) -> FloatArray:
        """The parameters' correlation matrix (NP, NP)."""
        sd = self.std
        return np.asarray(self.covariance / np.outer(sd, sd))

    def beyond(
        self,
        position: float,
        rotation: float,
        offset: float,
        rng: np.random.Generator,
        draws: int = 200_000,
    ) -> tuple[float, float, float]:
        """The share of recordings whose camera position error [m], rotation error [rad]
        (the rotation vector's norm) and marker offset error [m] exceed ``position``,
        ``rotation`` and ``offset``, ``draws`` errors drawn from ``rng`` as Gaussian with
        :attr:`covariance`."""
        e = rng.multivariate_normal(np.zeros(NP), self.covariance, draws)
        return (
            float(np.mean(np.linalg.norm(e[:, 3:6], axis=1) > position)),
            float(np.mean(np.linalg.norm(e[:, 0:3], axis=1) > rotation)),
            float(np.mean(np.linalg.norm(e[:, 6:9], axis=1) > offset)),
        )


def motion_information(
    robot: Robot, links: LinkAngles, stamp: FloatArray, pixel_std: float
) -> MotionInformation:
    """The frames a motion shows and the covariance they give (module docstring).

    Args:
        robot: The robot with its camera (intrinsics, image size, pose) and marker offset.
        links: Link angles per tick of the motion [rad].
        stamp: Exposure times of the frames [s], on the links' clock.
        pixel_std: Pixel noise per axis [px], > 0.

    Raises:
        ConfigError: fewer than 6 frames see the marker, or a direction of the parameters
            that the frames do not determine at all (a singular ``J^T J``).
    """
    cam = robot.camera
    x = np.zeros(NP)
    x[3:6], x[6:9] = cam.position, robot.tracked_offset
    pr = ReprojectionModel(robot, links, np.asarray(stamp, dtype=np.float64), cam.R_cw).project(x)
    seen = (
        pr.valid
        & (pr.depth > 0)
        & (pr.y[:, 0] >= 0)
        & (pr.y[:, 0] < cam.width)
        & (pr.y[:, 1] >= 0)
        & (pr.y[:, 1] < cam.height)
    )
    J = pr.J[seen].reshape(-1, NP)
    norms = np.linalg.norm(J, axis=0)  # (a column of zeros: a parameter no pixel sees)
    if seen.sum() < 6 or not norms.all() or np.linalg.matrix_rank(J / norms) < NP:
        raise ConfigError(
            describe(
                "calibration motion",
                "frames that see the marker and determine all ten parameters",
                f"{int(seen.sum())} of {pr.valid.size} frames in the image, "
                "the parameters not all determined",
                "move the marker through the camera's view, its link turning",
            )
        )
    cov = pixel_std**2 * np.linalg.inv(J.T @ J)
    return MotionInformation(seen, pr.depth, pr.r, np.asarray(cov))
