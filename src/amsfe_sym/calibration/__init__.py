"""Camera calibration from a recording (docs/calibrate.md): the camera's
pose in the base, the marker's offset on its link and the camera's time offset, in one batch
over the reprojection error of the frames against the encoders' link angles.

Flow: a log read as ``amsfe estimate`` reads it -> :mod:`.observations` (frames, link angles)
-> :mod:`.model` (the reprojection map with those parameters, its exact jacobian) ->
:mod:`.solve` (OpenCV's initial guess, robust least squares, intervals, what the motion
cannot determine) -> :mod:`.spec_out` (the calibrated ``robot.toml``).  Before a recording,
:mod:`.design` predicts from a planned motion the intervals the fit would state.

It may import ``errors``, ``core``, ``load`` (the robot, its camera) and ``logs`` (the log
reader of ``amsfe estimate``); the applications import it (``apps.calibrate``).
"""

from amsfe_sym.calibration.design import MotionInformation, motion_information
from amsfe_sym.calibration.model import NP, PARAMETERS, Projection, ReprojectionModel
from amsfe_sym.calibration.observations import (
    LinkAngles,
    Observations,
    link_angles,
    observations,
    smooth_angles,
)
from amsfe_sym.calibration.solve import Calibration, InitialGuess, calibrate, initial_guess

__all__ = [
    "NP",
    "PARAMETERS",
    "Calibration",
    "InitialGuess",
    "LinkAngles",
    "MotionInformation",
    "Observations",
    "Projection",
    "ReprojectionModel",
    "calibrate",
    "initial_guess",
    "link_angles",
    "motion_information",
    "observations",
    "smooth_angles",
]
