"""A camera's calibration as ROS publishes it (``sensor_msgs/CameraInfo``), read from a log's
info topic or from the YAML file ``camera_calibration`` writes, and the undistortion of
detected points by its model (docs/camera.md, "Undistortion").

ROS's convention (image_pipeline): ``K`` and ``D`` describe the raw (distorted) image, ``R``
rotates into the rectified frame, and ``P``'s left 3x3 is the camera matrix of the rectified
image.  :func:`undistort` maps raw pixels to rectified pixels, which a pinhole with
:attr:`CameraInfo.pinhole`'s intrinsics (the generated camera map, eq. (6)) predicts; an
all-zero ``D`` means the image is already rectified and its pixels are returned as they are.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.errors import ConfigError, LogError, describe

__all__ = [
    "MODELS",
    "CameraInfo",
    "camera_info_from_message",
    "distort",
    "make_camera_info",
    "parse_camera_info",
    "read_camera_info",
    "same_size",
    "undistort",
]

FloatArray = NDArray[np.float64]

#: Distortion models undistorted here, with how many coefficients each takes at least.
MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}


@dataclass(frozen=True, eq=False)
class CameraInfo:
    """A camera calibration.

    Attributes:
        width, height: Image size [px].
        model: Distortion model: ``plumb_bob``, ``rational_polynomial`` or ``equidistant``
            (an all-zero ``D`` of any model: already rectified).
        K: Intrinsics of the raw image, (3, 3) [px].
        D: Distortion coefficients (k1, k2, p1, p2, k3[, k4, k5, k6] for the first two,
            k1..k4 for ``equidistant``).
        R: Rectification rotation, (3, 3).
        P: Projection of the rectified image, (3, 4) [px].
    """

    width: int
    height: int
    model: str
    K: FloatArray
    D: FloatArray
    R: FloatArray
    P: FloatArray

    @property
    def rectified(self) -> bool:
        """Whether the image is already rectified (every distortion coefficient zero)."""
        return not np.any(self.D)

    @property
    def pinhole(self) -> tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)`` [px] of the pinhole that :func:`undistort`'s pixels fit: P's
        (K's when P is all zero, an uncalibrated driver's)."""
        M = self.P[:, :3] if np.any(self.P) else self.K
        return float(M[0, 0]), float(M[1, 1]), float(M[0, 2]), float(M[1, 2])

    @property
    def new_matrix(self) -> FloatArray:
        """The rectified image's camera matrix (3, 3) [px] (:attr:`pinhole` as a matrix)."""
        fx, fy, cx, cy = self.pinhole
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _matrix(values: Any, shape: tuple[int, int], where: str, error: type[Exception]) -> FloatArray:
    a = np.asarray(values, dtype=np.float64).ravel()
    if a.size != shape[0] * shape[1] or not np.isfinite(a).all():
        raise error(
            describe(where, f"{shape[0] * shape[1]} finite numbers", f"{a.size}: {a[:12]}", "fix")
        )
    return a.reshape(shape)


def make_camera_info(
    width: int,
    height: int,
    model: str,
    K: ArrayLike,
    D: ArrayLike,
    R: ArrayLike | None = None,
    P: ArrayLike | None = None,
    where: str = "CameraInfo",
    error: type[Exception] = ConfigError,
) -> CameraInfo:
    """A checked :class:`CameraInfo` (``R`` default identity, ``P`` default ``[K | 0]``).

    Raises:
        error: a size <= 0, an unknown model (with non-zero D), matrices of the wrong size
            or not finite, fewer coefficients than the model takes, K without positive focal
            lengths.
    """
    if int(width) <= 0 or int(height) <= 0:
        raise error(describe(f"{where} size", "width, height > 0", f"{width} x {height}", "fix"))
    Km = _matrix(K, (3, 3), f"{where} K", error)
    d = np.asarray(D, dtype=np.float64).ravel()
    if not np.isfinite(d).all():
        raise error(describe(f"{where} D", "finite coefficients", str(d.tolist()), "fix"))
    if np.any(d):
        if model not in MODELS:
            raise error(
                describe(
                    f"{where} distortion_model",
                    f"one of {list(MODELS)} (or all-zero D: rectified)",
                    repr(model),
                    "calibrate with one of those models, or rectify the images first",
                )
            )
        if d.size < MODELS[model]:
            raise error(
                describe(
                    f"{where} D", f"{MODELS[model]} coefficients for {model}", str(d.size), "fix"
                )
            )
    if not (Km[0, 0] > 0 and Km[1, 1] > 0):
        raise error(describe(f"{where} K", "fx, fy > 0", f"{Km[0, 0]}, {Km[1, 1]}", "fix"))
    Rm = np.eye(3) if R is None else _matrix(R, (3, 3), f"{where} R", error)
    if not np.any(Rm):  # an uncalibrated driver's all-zero R: no rectification
        Rm = np.eye(3)
    Pm = np.hstack([Km, np.zeros((3, 1))]) if P is None else _matrix(P, (3, 4), f"{where} P", error)
    return CameraInfo(int(width), int(height), str(model), Km, d, Rm, Pm)


def camera_info_from_message(msg: Any, where: str = "CameraInfo") -> CameraInfo:
    """A ``sensor_msgs/CameraInfo`` (a ``rosbags`` or an rclpy message; ROS 1's upper-case
    ``K``, ``D``, ``R``, ``P`` too) as a :class:`CameraInfo`.

    Raises:
        LogError: what :func:`make_camera_info` refuses.
    """

    def get(name: str) -> Any:
        return (
            getattr(msg, name.lower(), None) if hasattr(msg, name.lower()) else getattr(msg, name)
        )

    return make_camera_info(
        int(msg.width),
        int(msg.height),
        str(msg.distortion_model),
        get("K"),
        get("D"),
        get("R"),
        get("P"),
        where,
        LogError,
    )


def parse_camera_info(doc: dict[str, Any], where: str = "camera info") -> CameraInfo:
    """A :class:`CameraInfo` from a parsed ``camera_calibration`` YAML document
    (``image_width``, ``image_height``, ``distortion_model``, ``camera_matrix``,
    ``distortion_coefficients``, ``rectification_matrix``, ``projection_matrix``, each matrix
    a ``{rows, cols, data}`` table).

    Raises:
        ConfigError: a key missing, or what :func:`make_camera_info` refuses.
    """
    if not isinstance(doc, dict):
        raise ConfigError(describe(where, "a YAML mapping", type(doc).__name__, "fix the file"))
    need = ("image_width", "image_height", "camera_matrix", "distortion_coefficients")
    missing = [k for k in need if k not in doc]
    if missing:
        raise ConfigError(
            describe(where, f"the keys {list(need)}", f"{missing} missing", "write them")
        )

    def data(key: str) -> Any:
        v = doc.get(key)
        if v is None:
            return None
        if isinstance(v, dict):
            return v.get("data", [])
        return v

    return make_camera_info(
        doc["image_width"],
        doc["image_height"],
        str(doc.get("distortion_model", "plumb_bob")),
        data("camera_matrix"),
        data("distortion_coefficients") or [],
        data("rectification_matrix"),
        data("projection_matrix"),
        where,
    )


def read_camera_info(path: str | os.PathLike[str]) -> CameraInfo:
    """The CameraInfo YAML file at ``path`` (``camera_calibration``'s ``ost.yaml``, or what
    ``camera_info_manager`` stores).

    Raises:
        ConfigError: unreadable, not YAML, or what :func:`parse_camera_info` refuses.
    """
    import yaml

    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(
            describe(f"camera info {p}", "a readable YAML file", str(exc).splitlines()[0], "fix")
        ) from exc
    return parse_camera_info(doc, f"camera info {p}")


def undistort(info: CameraInfo, uv: ArrayLike) -> FloatArray:
    """Raw pixels ``uv`` (M, 2) [px] -> rectified pixels (M, 2) [px] of the pinhole
    :attr:`CameraInfo.pinhole` (rows of NaN stay NaN).

    plumb_bob and rational_polynomial by ``cv2.undistortPoints`` (iterated to 1e-14 or
    200 iterations), equidistant by ``cv2.fisheye.undistortPoints``, each with ``R`` and
    ``P``; an all-zero ``D``: the pixels as they are (already rectified).
    """
    import cv2

    pts = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if info.rectified or pts.size == 0:
        return pts.copy()
    out = np.full_like(pts, np.nan)
    ok = np.isfinite(pts).all(axis=1)
    src = pts[ok].reshape(-1, 1, 2)
    if src.size:
        P = info.new_matrix
        if info.model == "equidistant":
            res = cv2.fisheye.undistortPoints(src, info.K, info.D[:4], R=info.R, P=P)
        else:
            # iterated to convergence (undistortPoints' default 5 iterations leave 0.8 px at
            # the corners of a k1 = -0.3 lens: tests/test_vision_marker.py)
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
            res = cv2.undistortPoints(src, info.K, info.D, R=info.R, P=P, criteria=crit)
        out[ok] = res.reshape(-1, 2)
    return out


def distort(info: CameraInfo, uv: ArrayLike) -> FloatArray:
    """Rectified pixels ``uv`` (M, 2) [px] (of :attr:`CameraInfo.pinhole`) -> raw pixels
    (M, 2): the inverse of :func:`undistort`, by ``cv2.projectPoints`` (the renderer's
    camera and the tests' truth)."""
    import cv2

    pts = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if info.rectified or pts.size == 0:
        return pts.copy()
    fx, fy, cx, cy = info.pinhole
    rays = np.column_stack([(pts[:, 0] - cx) / fx, (pts[:, 1] - cy) / fy, np.ones(len(pts))])
    rays = rays @ info.R  # rectified frame -> raw camera frame (R^T applied to columns)
    zero = np.zeros(3)
    obj = rays.reshape(-1, 1, 3)
    if info.model == "equidistant":
        res, _ = cv2.fisheye.projectPoints(obj, zero, zero, info.K, info.D[:4])
    else:
        res, _ = cv2.projectPoints(obj, zero, zero, info.K, info.D)
    out: FloatArray = np.asarray(res, dtype=np.float64).reshape(-1, 2)
    return out


def same_size(info: CameraInfo, width: int, height: int, where: str) -> None:
    """Refuse an image whose size is not the CameraInfo's.

    Raises:
        LogError: the sizes differ.
    """
    if (info.width, info.height) != (int(width), int(height)):
        raise LogError(
            describe(
                where,
                f"images of the CameraInfo's size {info.width} x {info.height} px",
                f"{width} x {height} px",
                "record the CameraInfo of this camera mode (or rescale the calibration)",
            )
        )
