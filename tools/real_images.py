"""Real images of a real arm (issue 35, done-when "Real images"): the numbers of
docs/camera.md, "On real images".

Data: tests/data/real_images/tabb_dataset1/ (11 of the 88 frames of Tabb & Ahmad Yousef's
dataset 1: a Denso VS-6577GM-B arm carrying a Sony XCD 640 x 480 camera, an 8 x 6 chessboard
of 28.5 mm squares fixed in the world, and the arm's flange pose per frame; see its
README.md for source, commit and licence).  It is eye-in-hand: the camera rides on the
flange and the board is fixed, the mirror of the paper's fixed camera watching a marker on
the arm; the equations (AX = ZB) are the same with the roles of camera and marker swapped.

1. Detection: OpenCV's plain chessboard detector (``findChessboardCorners`` +
   ``cornerSubPix``) on every frame; "visible" is the dataset's own statement that the
   board is whole in every one of its frames (its README: corners in the same order in every
   image), checked here by eye on the 11 frames kept.
2. Intrinsics: ``cv2.calibrateCamera`` (plumb_bob) on all 88 frames of the dataset (RMS
   0.200 px; on the 11 kept alone the lens is poorly determined and the hand-eye residual
   triples), written as a ``camera_calibration`` YAML (``camera_info.yaml``; ``--write-info
   DIR`` with DIR a copy of the whole dataset, caliban's ``datasets/1``) that the test reads
   back through ``amsfe_sym.vision.camera_info``.
3. Hand-eye (robot-world, AX = ZB): the camera's pose on the flange X and the board's pose
   in the base Z; initial guess by Park & Martin on relative motions, then a least squares
   on the reprojection error of all 48 corners of every frame (``scipy.optimize
   .least_squares``, Huber loss 1 px) through the toolkit's CameraInfo and ``distort``.
   Residuals: median / 95th percentile / max [px] over every corner of every frame.

Writes docs/data/real-images.json and prints it:

    PYTHONPATH=src .venv/bin/python tools/real_images.py [--write-info DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests/data/real_images/tabb_dataset1"
PATTERN = (8, 6)  # inner corners (columns, rows)
SQUARE_MM = 28.5

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Frames:
    """The dataset: image paths, flange poses in the base (N, 4, 4) [mm], board points (48, 3)
    [mm]."""

    images: list[Path]
    flange: FloatArray
    board: FloatArray


def load(folder: Path = DATA) -> Frames:
    """The images (sorted) and ``robot_cali.txt`` (its count, then one 4 x 4 per frame:
    Tabb's B_i, the base-to-hand transform, i.e. base coordinates to flange coordinates,
    translation in mm; inverted here into the flange's pose in the base)."""
    images = sorted(folder.glob("image*.png"))
    words = (folder / "robot_cali.txt").read_text().split()
    n = int(words[0])
    base_to_hand = np.array(words[1:], dtype=np.float64).reshape(n, 4, 4)
    flange = np.array([hom_inv(T) for T in base_to_hand])
    if n != len(images):
        raise SystemExit(f"{folder}: {n} poses for {len(images)} images")
    board = np.zeros((PATTERN[0] * PATTERN[1], 3))
    board[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * SQUARE_MM
    return Frames(images, flange, board)


def corners(path: Path) -> FloatArray | None:
    """The 48 chessboard corners (48, 2) [raw px] of one image, sub-pixel, or None."""
    import cv2

    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    found, c = cv2.findChessboardCorners(grey, PATTERN)
    if not found:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    c = cv2.cornerSubPix(grey, c, (5, 5), (-1, -1), crit)
    return np.asarray(c, dtype=np.float64).reshape(-1, 2)


def intrinsics(frames: Frames, pts: list[FloatArray]) -> tuple[float, FloatArray, FloatArray]:
    """``cv2.calibrateCamera`` (plumb_bob, 5 coefficients): RMS [px], K (3, 3), D (5,)."""
    import cv2

    obj = [frames.board.astype(np.float32)] * len(pts)
    img = [p.astype(np.float32).reshape(-1, 1, 2) for p in pts]
    rms, K, D, _, _ = cv2.calibrateCamera(obj, img, (640, 480), None, None)
    return float(rms), np.asarray(K, dtype=np.float64), np.asarray(D, dtype=np.float64).ravel()


def info_yaml(K: FloatArray, D: FloatArray) -> str:
    """``camera_calibration``'s ``ost.yaml`` for K, D (640 x 480, plumb_bob, P = K)."""

    def block(name: str, rows: int, cols: int, values: FloatArray) -> str:
        data = ", ".join(f"{v:.9g}" for v in np.asarray(values).ravel())
        return f"{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [{data}]\n"

    P = np.hstack([K, np.zeros((3, 1))])
    return (
        "image_width: 640\nimage_height: 480\ncamera_name: tabb_dataset1\n"
        + block("camera_matrix", 3, 3, K)
        + "distortion_model: plumb_bob\n"
        + block("distortion_coefficients", 1, 5, D)
        + block("rectification_matrix", 3, 3, np.eye(3))
        + block("projection_matrix", 3, 4, P)
    )


def hom(R: FloatArray, t: FloatArray) -> FloatArray:
    """The 4 x 4 transform of rotation ``R`` and translation ``t`` [m]."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.ravel(t)
    return T


def hom_inv(T: FloatArray) -> FloatArray:
    """The inverse of the 4 x 4 rigid transform ``T``."""
    return hom(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])


def board_in_camera(info: object, frames: Frames, pts: list[FloatArray]) -> list[FloatArray]:
    """The board's pose in the camera per frame (4, 4) [mm], by ``solvePnP`` on the
    toolkit-undistorted corners (pinhole of the CameraInfo, no distortion)."""
    import cv2

    from amsfe_sym.vision.camera_info import undistort

    out = []
    for p in pts:
        und = undistort(info, p)  # type: ignore[arg-type]
        _ok, rv, tv = cv2.solvePnP(frames.board, und, info.new_matrix, None)  # type: ignore[attr-defined]
        out.append(hom(cv2.Rodrigues(rv)[0], tv))
    return out


def park_martin(flange: FloatArray, cam: list[FloatArray]) -> FloatArray:
    """The camera's pose on the flange X (4, 4) [mm] from A X = X B over consecutive pairs
    (A: the flange's relative motion, B: the camera's), Park & Martin 1994."""
    from scipy.spatial.transform import Rotation

    alphas, betas, As, Bs = [], [], [], []
    for i in range(len(cam) - 1):
        A = hom_inv(flange[i]) @ flange[i + 1]
        B = cam[i] @ hom_inv(cam[i + 1])
        alphas.append(Rotation.from_matrix(A[:3, :3]).as_rotvec())
        betas.append(Rotation.from_matrix(B[:3, :3]).as_rotvec())
        As.append(A)
        Bs.append(B)
    M = sum(np.outer(b, a) for a, b in zip(alphas, betas, strict=True))
    w, V = np.linalg.eigh(M.T @ M)
    R = V @ np.diag(w**-0.5) @ V.T @ M.T
    C = np.vstack([A[:3, :3] - np.eye(3) for A in As])
    d = np.concatenate([R @ B[:3, 3] - A[:3, 3] for A, B in zip(As, Bs, strict=True)])
    t = np.linalg.lstsq(C, d, rcond=None)[0]
    return hom(R, t)


def _pose(x: FloatArray) -> FloatArray:
    from scipy.spatial.transform import Rotation

    return hom(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:])


def _vec(T: FloatArray) -> FloatArray:
    from scipy.spatial.transform import Rotation

    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])


def reprojection(
    info: object, frames: Frames, pts: list[FloatArray], X: FloatArray, Z: FloatArray
) -> FloatArray:
    """Per-corner reprojection error (N * 48,) [raw px] of the board through flange pose,
    X (camera on flange) and Z (board in base), projected by the CameraInfo's pinhole and
    distorted by the toolkit's ``distort``."""
    from amsfe_sym.vision.camera_info import distort

    fx, fy, cx, cy = info.pinhole  # type: ignore[attr-defined]
    errs = []
    for F, p in zip(frames.flange, pts, strict=True):
        T = hom_inv(F @ X) @ Z  # board in camera
        q = frames.board @ T[:3, :3].T + T[:3, 3]
        uv = np.column_stack([fx * q[:, 0] / q[:, 2] + cx, fy * q[:, 1] / q[:, 2] + cy])
        errs.append(np.linalg.norm(distort(info, uv) - p, axis=1))  # type: ignore[arg-type]
    return np.concatenate(errs)


def hand_eye(info: object, frames: Frames, pts: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """X (camera on flange) and Z (board in base) (4, 4) [mm]: Park & Martin, then the least
    squares on the reprojection error (Huber, 1 px)."""
    from scipy.optimize import least_squares

    cam = board_in_camera(info, frames, pts)
    X0 = park_martin(frames.flange, cam)
    Z0 = frames.flange[0] @ X0 @ cam[0]
    sol = least_squares(
        lambda x: reprojection(info, frames, pts, _pose(x[:6]), _pose(x[6:])),
        np.concatenate([_vec(X0), _vec(Z0)]),
        loss="huber",
        f_scale=1.0,
        x_scale="jac",
    )
    return _pose(sol.x[:6]), _pose(sol.x[6:])


def write_info(full: Path) -> float:
    """``camera_info.yaml`` from every frame of the whole dataset in ``full``; its RMS [px]."""
    frames = load(full)
    pts = [c for c in (corners(p) for p in frames.images) if c is not None]
    rms, K, D = intrinsics(frames, pts)
    (DATA / "camera_info.yaml").write_text(info_yaml(K, D))
    return rms


def measure() -> dict[str, object]:
    """Every number of docs/camera.md "On real images" (see the module's docstring)."""
    from amsfe_sym.vision.camera_info import read_camera_info

    frames = load()
    found = [corners(p) for p in frames.images]
    pts = [c for c in found if c is not None]
    info = read_camera_info(DATA / "camera_info.yaml")
    X, Z = hand_eye(info, frames, pts)
    # An 8 x 6 board looks the same turned by 180 deg: OpenCV may list a frame's corners in
    # the reverse order (the dataset's README warns of it).  The order is settled by the
    # arm: a frame whose reversed corners reproject better through the first solve is
    # reversed, then the solve is repeated.
    flipped = []
    for i, p in enumerate(pts):
        one = Frames([frames.images[i]], frames.flange[i : i + 1], frames.board)
        if np.median(reprojection(info, one, [p[::-1]], X, Z)) < np.median(
            reprojection(info, one, [p], X, Z)
        ):
            pts[i] = p[::-1].copy()
            flipped.append(frames.images[i].name)
    if flipped:
        X, Z = hand_eye(info, frames, pts)
    err = reprojection(info, frames, pts, X, Z)
    per_frame = err.reshape(len(pts), -1)
    return {
        "frames": len(frames.images),
        "detected": len(pts),
        "reversed_corner_order": flipped,
        "residual_px": {
            "median": float(np.median(err)),
            "p95": float(np.percentile(err, 95)),
            "max": float(err.max()),
        },
        "frame_median_px": [float(v) for v in np.median(per_frame, axis=1)],
        "camera_on_flange_mm": [float(v) for v in X[:3, 3]],
        "board_in_base_mm": [float(v) for v in Z[:3, 3]],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--write-info", type=Path, metavar="DIR", help="rewrite camera_info.yaml from DIR"
    )
    args = ap.parse_args(argv)
    if args.write_info is not None:
        print(f"camera_info.yaml: RMS {write_info(args.write_info):.3f} px", file=sys.stderr)
    out = measure()
    text = json.dumps(out, indent=1) + "\n"
    (ROOT / "docs/data/real-images.json").write_text(text)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
