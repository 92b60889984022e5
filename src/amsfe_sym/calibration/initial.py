"""The calibration's start (docs/calibrate.md, "The method", step 1): the marker's world
positions from the link angles, the ``solvePnP`` scan over trial time offsets (or the spec's
own camera pose when it reprojects better), and the refusal of a log whose marker does not
move.  :mod:`amsfe_sym.calibration.solve` fits from here."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amsfe_sym.calibration.model import ReprojectionModel
from amsfe_sym.calibration.observations import LinkAngles, Observations
from amsfe_sym.errors import LogError, describe
from amsfe_sym.load.types import Robot

__all__ = [
    "MIN_SPREAD_M",
    "SCAN_STEP_S",
    "InitialGuess",
    "initial_guess",
    "marker_points",
    "spread_check",
]

FloatArray = NDArray[np.float64]

#: Step of the initial guess's time-offset scan [s].
SCAN_STEP_S = 0.005
#: The tracked point must move at least this far [m] over the frames to fit anything.
MIN_SPREAD_M = 0.01


@dataclass(frozen=True)
class InitialGuess:
    """The ``solvePnP`` scan's best trial: world -> camera rotation, camera centre [m], time
    offset [s], its reprojection RMS [px], and the number of frames it used; ``source``:
    ``"solvePnP"``, or ``"spec"`` when the spec's camera pose reprojected better (then
    ``pnp_rms`` is the scan's best RMS [px])."""

    R_cw: FloatArray
    position: FloatArray
    time_offset: float
    rms: float
    frames: int
    source: str = "solvePnP"
    pnp_rms: float = float("nan")


def marker_points(
    robot: Robot, links: LinkAngles, t: FloatArray, offset: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """World positions [m] of the marker at ``offset`` at times ``t``; which could be
    interpolated."""
    model = ReprojectionModel(robot, links, t, np.eye(3))
    q, _, ok = links.at(t)
    pts = np.zeros((t.size, 3))
    if ok.any():
        p, R, _, _ = model.frame_kinematics(q[ok])
        pts[ok] = p + R @ offset
    return pts, ok


def initial_guess(
    robot: Robot,
    links: LinkAngles,
    obs: Observations,
    offset: FloatArray,
    max_offset: float,
    max_frames: int = 300,
) -> InitialGuess:
    """The ``solvePnP`` scan (:mod:`amsfe_sym.calibration.solve`, step 1) over at most
    ``max_frames`` frames."""
    K = robot.camera.K
    pick = np.unique(np.linspace(0, obs.m - 1, min(obs.m, max_frames)).round().astype(int))
    trials = np.arange(-max_offset, max_offset + 0.5 * SCAN_STEP_S, SCAN_STEP_S)
    best: InitialGuess | None = None
    for dt in trials:
        pts, ok = marker_points(robot, links, obs.stamp[pick] - dt, offset)
        if ok.sum() < 6:
            continue
        obj, img = pts[ok], obs.pixel[pick][ok]
        good, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_SQPNP)
        if not good:
            continue
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        if best is None or rms < best.rms:
            R = np.asarray(cv2.Rodrigues(rvec)[0], dtype=np.float64)
            centre = -R.T @ np.asarray(tvec, dtype=np.float64).reshape(3)
            best = InitialGuess(R, centre, float(dt), rms, int(ok.sum()))
    if best is None:
        raise LogError(
            describe(
                "calibration",
                "at least 6 camera frames with encoder samples around them",
                f"{obs.m} frames, none usable at any time offset within +-{max_offset:g} s",
                "record the encoders and the camera together",
            )
        )
    # the spec's own pose, at dt = 0, when it reprojects better (solve's step 1)
    pts, ok = marker_points(robot, links, obs.stamp[pick], offset)
    cam = robot.camera
    rvec = cv2.Rodrigues(np.asarray(cam.R_cw, dtype=np.float64))[0]
    tvec = -np.asarray(cam.R_cw, dtype=np.float64) @ np.asarray(cam.position, dtype=np.float64)
    if ok.sum() >= 6:
        proj, _ = cv2.projectPoints(pts[ok], rvec, tvec, K, None)
        img = obs.pixel[pick][ok]
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        if rms < best.rms:
            R = np.asarray(cam.R_cw, dtype=np.float64).copy()
            pos = np.asarray(cam.position, dtype=np.float64).copy()
            return InitialGuess(R, pos, 0.0, rms, int(ok.sum()), "spec", best.rms)
    return best


def spread_check(robot: Robot, links: LinkAngles, obs: Observations, offset: FloatArray) -> None:
    """Refuse a log whose tracked point does not move: nothing can be determined."""
    pts, ok = marker_points(robot, links, obs.stamp, offset)
    if ok.sum() == 0:
        raise LogError(
            describe(
                "calibration",
                "camera frames with encoder samples around their stamps",
                f"none of {obs.m} frames",
                "record the encoders and the camera over the same time",
            )
        )
    p = pts[ok]
    spread = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
    if spread < MIN_SPREAD_M:
        raise LogError(
            describe(
                "calibration",
                f"the tracked point moving (>= {MIN_SPREAD_M * 1000:g} mm) over the frames",
                f"it stays within {spread * 1000:.2f} mm of one place over {int(ok.sum())} "
                "frames: the arm is at rest, so the camera pose, the marker offset and the "
                "time offset cannot be determined",
                "record the arm moving through its workspace",
            )
        )
