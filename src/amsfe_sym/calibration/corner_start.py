"""The corner fit's start (docs/calibrate.md, "The method", step 1, corners): the marker's
orientation on its link and a camera pose from the marker's 4 corners per frame.

At the centre scan's time offset (:func:`~amsfe_sym.calibration.initial.initial_guess`), each
frame's marker pose in the camera comes from ``cv2.solvePnP`` (``SOLVEPNP_IPPE_SQUARE``, the
square's own solver) and the tracked frame's pose from the link angles; then

- **hand-eye**: ``cv2.calibrateRobotWorldHandEye`` (Shah's method) on those pairs, which
  solves ``T_cam<-marker,i = T_cam<-world T_world<-frame,i T_frame<-marker`` for the camera's
  pose and the marker's pose on its link at once;
- **the centre scan's camera**, with the spec's ``[tracked] orientation`` (when given) or the
  average over the frames of ``R_frame,i^T R_cw^T R_cam<-marker,i`` (a chordal mean), at the
  spec's marker offset.

The candidate whose corners reproject best (RMS over every corner) is the start.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.calibration.initial import InitialGuess
from amsfe_sym.calibration.model import ReprojectionModel, marker_corners_local
from amsfe_sym.calibration.observations import LinkAngles, Observations
from amsfe_sym.load.types import Robot

__all__ = ["CornerStart", "corner_start", "mean_rotation"]


@dataclass(frozen=True)
class CornerStart:
    """The corner fit's start: world -> camera rotation, camera centre [m], marker offset [m]
    and orientation (marker -> tracked frame) in the tracked frame, time offset [s], its
    corners' reprojection RMS [px] and which candidate it is (module docstring):
    ``"hand-eye"``, ``"spec orientation"`` or ``"mean orientation"``; ``rms`` of every
    candidate tried."""

    R_cw: FloatArray
    position: FloatArray
    offset: FloatArray
    Rm: FloatArray
    time_offset: float
    rms: float
    source: str
    tried: dict[str, float]


def mean_rotation(Rs: FloatArray) -> FloatArray:
    """The chordal mean (the rotation nearest the sum) of rotations ``Rs`` (n, 3, 3)."""
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt)))])
    return np.asarray(U @ D @ Vt)


def _marker_poses(
    obs: Observations, K: FloatArray, local: FloatArray, rows: FloatArray
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Each frame's marker pose in the camera (rotation (n, 3, 3), translation (n, 3) [m])
    from its corners by IPPE_SQUARE, and which frames gave one."""
    assert obs.corners is not None
    n = rows.size
    R = np.zeros((n, 3, 3))
    t = np.zeros((n, 3))
    ok = np.zeros(n, dtype=bool)
    for j, i in enumerate(rows):
        img = obs.corners[int(i)]
        if not np.isfinite(img).all():
            continue
        good, rvec, tvec = cv2.solvePnP(local, img, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if good:
            R[j] = np.asarray(cv2.Rodrigues(rvec)[0])
            t[j] = np.asarray(tvec, dtype=np.float64).reshape(3)
            ok[j] = True
    return R, t, ok


def _rms(
    robot: Robot,
    links: LinkAngles,
    obs: Observations,
    local: FloatArray,
    R_cw: FloatArray,
    c: FloatArray,
    o: FloatArray,
    Rm: FloatArray,
    dt: float,
) -> float:
    """The corners' reprojection RMS [px] (over the points, both axes) at a candidate."""
    model = ReprojectionModel(robot, links, obs.stamp, R_cw, local, Rm)
    x = np.concatenate([np.zeros(3), c, o, [dt], np.zeros(3)])
    pr = model.project(x)
    use = pr.valid & (pr.depth > 0)
    if not use.any():
        return float("inf")
    d = (pr.y - obs.target)[use].reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def corner_start(
    robot: Robot,
    links: LinkAngles,
    obs: Observations,
    init: InitialGuess,
    offset0: FloatArray,
    Rm_spec: FloatArray | None,
    max_frames: int = 300,
) -> CornerStart:
    """The corner fit's start (module docstring) from the centre scan's ``init``, the
    spec's marker offset ``offset0`` [m] and orientation ``Rm_spec`` (or None)."""
    local = marker_corners_local(obs.marker_size)
    K = robot.camera.K
    dt = init.time_offset
    pick = np.unique(np.linspace(0, obs.m - 1, min(obs.m, max_frames)).round().astype(int))
    q, _, valid = links.at(obs.stamp[pick] - dt)
    rows = pick[valid]
    R_cm, t_cm, ok = _marker_poses(obs, K, local, rows)
    model = ReprojectionModel(robot, links, obs.stamp, np.eye(3))
    p_f, R_f, _, _ = model.frame_kinematics(q[valid][ok])
    cands: list[tuple[str, FloatArray, FloatArray, FloatArray, FloatArray]] = []
    if ok.sum() >= 3:
        try:
            R_mf, t_mf, R_cw, t_cw = cv2.calibrateRobotWorldHandEye(
                list(R_cm[ok]),
                [t.reshape(3, 1) for t in t_cm[ok]],
                list(R_f),
                [t.reshape(3, 1) for t in p_f],
            )
            R_mf = np.asarray(R_mf, dtype=np.float64)
            R_cw = np.asarray(R_cw, dtype=np.float64)
            c = -R_cw.T @ np.asarray(t_cw, dtype=np.float64).reshape(3)
            o = -R_mf.T @ np.asarray(t_mf, dtype=np.float64).reshape(3)
            if np.isfinite(c).all() and np.isfinite(o).all():
                cands.append(("hand-eye", R_cw, c, o, R_mf.T))
        except (cv2.error, AttributeError):  # (OpenCV 5.0.0's wheel lacks the function)
            pass
    if Rm_spec is not None:
        cands.append(("spec orientation", init.R_cw, init.position, offset0, Rm_spec))
    if ok.any():
        Rs = np.transpose(R_f, (0, 2, 1)) @ init.R_cw.T @ R_cm[ok]
        cands.append(("mean orientation", init.R_cw, init.position, offset0, mean_rotation(Rs)))
    if not cands:  # (no frame's corners gave a pose: the start's orientation is a guess)
        cands.append(("mean orientation", init.R_cw, init.position, offset0, np.eye(3)))
    tried = {name: _rms(robot, links, obs, local, R, c, o, Rm, dt) for name, R, c, o, Rm in cands}
    name, R, c, o, Rm = min(cands, key=lambda cand: tried[cand[0]])
    return CornerStart(R, c, o, Rm, dt, tried[name], name, tried)
