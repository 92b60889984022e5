"""The marker in an image: OpenCV's ArUco detector (AprilTag families included), its
corners refined by OpenCV or from the marker's edges (:mod:`~amsfe_sym.vision.edges`), and
the tracked point from its corners (docs/camera.md, "The marker")."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import SpecError, describe
from amsfe_sym.vision.camera_info import CameraInfo
from amsfe_sym.vision.edges import edge_corners, unbend
from amsfe_sym.vision.spec import CORNERS, REFINEMENTS, MarkerSpec

__all__ = [
    "REFINEMENTS",
    "THRESHOLD_WINDOW",
    "Detection",
    "MarkerDetector",
    "diagonals_meet",
    "diagonals_meet_many",
    "foreshortening",
    "marker_axes",
    "marker_modules",
    "raw_corners_unbent",
    "single_threaded",
    "tracked_point",
]

FloatArray = NDArray[np.float64]

#: Why a frame gave no point (counted by the log reader under these names).
NO_MARKER = "without the marker (nothing detected)"
OTHER_ID = "with another marker id only"
TOO_OBLIQUE = "with the marker too oblique (over [marker] max_foreshortening_deg)"


@dataclass(frozen=True, eq=False)
class Detection:
    """What the detector found in one image.

    Attributes:
        corners: The marker's 4 corners in raw image pixels (4, 2) [px], OpenCV's order
            (:data:`~amsfe_sym.vision.spec.CORNERS`), or None when it was not found.
        skipped: Why there is no point (None: found).
        ids: Every id seen in the image.
        region: The corners (4, 2) [px] of a marker found but not used (too oblique:
            ``MarkerSpec.max_foreshortening_deg``): where the next image is searched first;
            None otherwise.
    """

    corners: FloatArray | None
    skipped: str | None
    ids: tuple[int, ...] = ()
    region: FloatArray | None = None

    @property
    def near(self) -> FloatArray | None:
        """Where the marker was in this image (used or not): the next search's region."""
        return self.corners if self.corners is not None else self.region


#: The adaptive threshold's window [px] of the first search: one window instead of
#: OpenCV's three (3, 13, 23).  The window of 3 px turns the sensor's noise into many tiny
#: contours, which cost most of a detection (docs/camera.md, "Speed"); 7 px finds the
#: 27-213 px markers of the simulated camera's renders as the three do, as accurately; on
#: noisier or flatter images it misses some, which the three then find (the fall-back).
THRESHOLD_WINDOW = 7

#: The farthest [px] the edge fit may move a corner from ``cornerSubPix``'s (or a module,
#: when larger); farther, the edges were not found (another edge, a clipped marker) and
#: OpenCV's corner stays.
MAX_MOVE_PX = 3.0


class MarkerDetector:
    """``cv2.aruco.ArucoDetector`` s for a :class:`MarkerSpec` (built once, reused).

    A search runs OpenCV's detector with one adaptive threshold window of ``threshold_window``
    px (:data:`THRESHOLD_WINDOW`); only when the marker is not found in the whole image that
    way is the image searched again with OpenCV's default windows (3, 13, 23 px), which find
    it on noisier or flatter images at ~5x the cost.  ``threshold_window=None``: the default
    windows alone.

    Sub-pixel refinement (``refinement``, else the spec's, else ``subpix``;
    :data:`~amsfe_sym.vision.spec.REFINEMENTS`): ``subpix`` is OpenCV's
    ``CORNER_REFINE_SUBPIX`` (``cornerSubPix`` on each corner, stopping at 1e-4 px or 100
    iterations, in a half-window of ``relative_window`` of the marker's module (bit) size, at
    most ``refine_window`` px); ``edges`` is that, then each of the marker's 4 outer edges
    located to sub-pixel and the corners where they meet
    (:func:`~amsfe_sym.vision.edges.edge_corners`): ``cornerSubPix`` alone places the
    corners of a blurred marker 0.1-0.45 px inside the true ones, the edges do not, at ~3x
    the detection's CPU (docs/camera.md, "The corners").  The centre, where the diagonals
    meet, is not moved by such a shrink: the tracked point uses ``subpix``; ``amsfe
    calibrate --corners`` uses ``edges``.  ``info``: the camera's lens, for a
    line per edge in the undistorted image (more accurate); None, a parabola per edge in the
    raw image.  The toolkit's chain passes none (the log reader detects before it has read
    the CameraInfo, and the camera node must give the log reader's corners bit for bit).
    The corners come back in the raw image either way; where the edges give too few points
    or move a corner more than :data:`MAX_MOVE_PX` (or a module), OpenCV's.

    OpenCV's own threads: the detector's ``parallel_for_`` splits ~1 ms of work per image, so
    the caller decides (:func:`single_threaded`): the log reader and the camera node run it
    on one thread.
    """

    def __init__(
        self,
        spec: MarkerSpec,
        refine_window: int = 5,
        relative_window: float = 0.8,
        threshold_window: int | None = THRESHOLD_WINDOW,
        refinement: str | None = None,
        info: CameraInfo | None = None,
    ) -> None:
        import cv2

        refinement = refinement or spec.refinement or "subpix"
        if refinement not in REFINEMENTS:
            raise SpecError(
                describe(
                    "MarkerDetector refinement",
                    f"one of {', '.join(REFINEMENTS)}",
                    repr(refinement),
                    "name one of those",
                )
            )
        self.spec = spec
        self.refinement = refinement
        #: The camera's lens for the edge fit (None: a parabola per edge in the raw image).
        self.info = info
        self._dictionary = cv2.aruco.getPredefinedDictionary(_dictionary_id(spec.dictionary))
        #: The marker's side in modules: its bits and a black border bit on each side.
        self.modules = marker_modules(spec.dictionary)
        self._window = (int(refine_window), float(relative_window))
        self._threshold = threshold_window
        self._params = self._parameters(None, threshold_window)
        self._detector: Any = cv2.aruco.ArucoDetector(self._dictionary, self._params)
        self._fallback: Any = None
        if threshold_window is not None:  # (OpenCV's windows, when the one window fails)
            self._fallback = cv2.aruco.ArucoDetector(self._dictionary, self._parameters(None, None))
        self._roi: dict[tuple[int, int], Any] = {}  # (crop side, image side) -> detector

    def _parameters(self, min_perimeter_rate: float | None, window: int | None) -> Any:
        """The detector's parameters: OpenCV's defaults, sub-pixel refinement, one adaptive
        threshold ``window`` [px] if given, a minimum marker perimeter rate if given."""
        import cv2

        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = {
            "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
            "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
        }.get(self.refinement, cv2.aruco.CORNER_REFINE_SUBPIX)
        params.cornerRefinementWinSize = self._window[0]
        params.relativeCornerRefinmentWinSize = self._window[1]  # (OpenCV's spelling)
        params.cornerRefinementMaxIterations = 100
        params.cornerRefinementMinAccuracy = 1e-4  # (0.01 left the result 3e-3 px on
        # where the iteration started: a region of interest's contour starts elsewhere)
        if window is not None:
            params.adaptiveThreshWinSizeMin = int(window)
            params.adaptiveThreshWinSizeMax = int(window)
        if min_perimeter_rate is not None:
            params.minMarkerPerimeterRate = min_perimeter_rate
        return params

    def detect(self, grey: NDArray[np.uint8], near: FloatArray | None = None) -> Detection:
        """The spec's marker in the grey image ``grey`` (height, width).

        ``near``: the marker's corners (4, 2) [px] in a previous image; the marker is first
        searched in a square region of interest around them (3 marker sides, at least 64 px,
        with the detector's minimum marker perimeter kept in pixels), then, if it is not
        there, in the whole image (then with OpenCV's default threshold windows if still not
        found).  Corners found in the region are those of the whole image to ~1e-4 px
        (float32 offsets; the edge fit runs on the whole image in both:
        tests/test_vision_marker.py).
        """
        if near is not None and np.isfinite(near).all():
            found = self._near(grey, np.asarray(near, dtype=np.float64).reshape(4, 2))
            if found is not None:
                return found
        return self.whole(grey)

    def whole(self, grey: NDArray[np.uint8]) -> Detection:
        """The spec's marker searched in the whole image (no region of interest)."""
        det = self._found(self._detector, grey, 0, 0)
        if det.corners is None and det.region is None and self._fallback is not None:
            return self._found(self._fallback, grey, 0, 0)
        return det

    def _found(
        self, detector: Any, grey: NDArray[np.uint8], x0: int, y0: int, crop: int = 0
    ) -> Detection:
        """``detector`` on ``grey`` (the whole image), or on its square ``crop`` px at
        (``x0``, ``y0``) px when ``crop`` > 0; corners in the whole image's pixels."""
        part = grey[y0 : y0 + crop, x0 : x0 + crop] if crop else grey
        corners, ids, _ = detector.detectMarkers(part)
        seen = () if ids is None else tuple(int(i) for i in np.asarray(ids).ravel())
        if not seen:
            return Detection(None, NO_MARKER)
        if self.spec.id not in seen:
            return Detection(None, OTHER_ID, seen)
        c = np.asarray(corners[seen.index(self.spec.id)], dtype=np.float64).reshape(4, 2)
        c = c + np.array([x0, y0], dtype=np.float64)
        if self.refinement == "edges":
            fitted = edge_corners(grey, c, self.modules, self.info)
            if fitted is not None and np.isfinite(fitted).all():
                side = float(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1).min())
                if np.abs(fitted - c).max() <= max(MAX_MOVE_PX, side / self.modules):
                    c = fitted
        limit = self.spec.max_foreshortening_deg
        if limit < 90.0 and foreshortening(c) > limit:  # (docs/camera.md, "The corners")
            return Detection(None, TOO_OBLIQUE, seen, region=c)
        return Detection(c, None, seen)

    def _near(self, grey: NDArray[np.uint8], near: FloatArray) -> Detection | None:
        import cv2

        h, w = grey.shape
        lo, hi = near.min(axis=0), near.max(axis=0)
        side = float(max(hi - lo))
        crop = max(64, 1 << int(np.ceil(np.log2(max(3.0 * side, 1.0)))))
        if crop >= 0.5 * min(w, h):
            return None  # (a region that large saves nothing)
        cx, cy = 0.5 * (lo + hi)
        x0 = int(np.clip(round(cx - crop / 2), 0, w - crop))
        y0 = int(np.clip(round(cy - crop / 2), 0, h - crop))
        key = (crop, max(w, h))
        if key not in self._roi:
            rate = self._params.minMarkerPerimeterRate * max(w, h) / crop
            params = self._parameters(min(rate, 4.0), self._threshold)
            self._roi[key] = cv2.aruco.ArucoDetector(self._dictionary, params)
        det = self._found(self._roi[key], grey, x0, y0, crop)
        return det if det.near is not None else None


def single_threaded() -> None:
    """OpenCV on one thread in this process (``cv2.setNumThreads(1)``).

    OpenCV's part of a detection is ~0.3 ms of CPU in a region of interest and ~1-2 ms in a
    whole 640 x 480 image; its ``parallel_for_`` over so little work adds a thread hand-off, and a
    second thread would take the core of the estimator or the encoder path (docs/camera.md,
    "Speed").
    """
    import cv2

    cv2.setNumThreads(1)


@functools.cache
def marker_modules(dictionary: str) -> int:
    """The side of a marker of ``dictionary`` (a cv2.aruco name) in modules: its bits and a
    black border bit on each side."""
    import cv2

    return int(cv2.aruco.getPredefinedDictionary(_dictionary_id(dictionary)).markerSize) + 2


def raw_corners_unbent(info: CameraInfo, corners: FloatArray, spec: MarkerSpec) -> FloatArray:
    """Detected corners (M, 4, 2) [px, raw image] with the error of the edge fit's straight
    lines in the raw image taken off when ``spec`` refines them from the edges without the
    lens (:func:`~amsfe_sym.vision.edges.unbend`; the log reader's and the camera node's
    detector); otherwise as they are.  Frames without a marker (NaN) stay NaN."""
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    if spec.refinement != "edges":
        return c
    out = c.copy()
    ok = np.isfinite(c).all(axis=(1, 2))
    if ok.any():
        out[ok] = unbend(info, c[ok], marker_modules(spec.dictionary))
    return out


def _dictionary_id(name: str) -> int:
    import cv2

    for attr in (name, name.upper()):
        if hasattr(cv2.aruco, attr):
            return int(getattr(cv2.aruco, attr))
    raise KeyError(name)  # (parse_marker checked the name against DICTIONARIES)


def foreshortening(corners: FloatArray) -> float:
    """How foreshortened a square marker looks [deg], from its 4 corners (4, 2) [px]
    (OpenCV's order): ``arccos(s2 / s1)``, ``s1 >= s2`` the singular values of the
    quadrilateral's affine part (:func:`marker_axes`).
    The pinhole's jacobian at the marker's centre times its axes, for a small marker; near
    the image's centre, the angle between its normal and its line of sight (off the axis a
    marker facing the camera looks stretched along the radius).  The compression is what the
    detector sees: a module of ``cos`` its width across the foreshortened direction."""
    s = np.linalg.svd(marker_axes(corners), compute_uv=False)
    return float(np.degrees(np.arccos(min(1.0, s[1] / s[0])))) if s[0] > 0 else 90.0


def marker_axes(corners: FloatArray) -> FloatArray:
    """The marker's x and y sides in the image (2, 2) [px], as columns: the means of its
    opposite edges, from its 4 corners (4, 2) [px] (OpenCV's order); the quadrilateral's
    affine part."""
    c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    return 0.5 * np.column_stack([(c[1] - c[0]) + (c[2] - c[3]), (c[3] - c[0]) + (c[2] - c[1])])


def diagonals_meet(corners: FloatArray) -> FloatArray:
    """The intersection of the diagonals 0-2 and 1-3 of a quadrilateral (4, 2) [px]: the
    image of the square's centre under any homography (perspective keeps lines and
    incidence), so on undistorted corners it is the projection of the marker's centre."""
    a, b, c, d = (np.append(p, 1.0) for p in np.asarray(corners, dtype=np.float64))
    x = np.cross(np.cross(a, c), np.cross(b, d))
    out: FloatArray = x[:2] / x[2]
    return out


def diagonals_meet_many(corners: FloatArray) -> FloatArray:
    """:func:`diagonals_meet` of many quadrilaterals (M, 4, 2) [px] at once -> (M, 2) [px]
    (the same homogeneous cross products, written out: a log's frames in one pass)."""
    c = np.asarray(corners, dtype=np.float64)
    a, b, cc, d = (np.concatenate([c[:, k], np.ones((len(c), 1))], axis=1) for k in range(4))
    x = np.cross(np.cross(a, cc), np.cross(b, d))
    out: FloatArray = x[:, :2] / x[:, 2:]
    return out


def tracked_point(corners: FloatArray, point: str) -> FloatArray:
    """The tracked point of undistorted ``corners`` (4, 2) [px]: ``centre`` or a named corner."""
    if point == "centre":
        return diagonals_meet(corners)
    return np.asarray(corners[CORNERS.index(point)], dtype=np.float64).copy()
