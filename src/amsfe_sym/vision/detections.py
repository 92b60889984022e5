"""Image payloads of a log -> the marker's corners, a slice at a time (docs/camera.md,
"Images in"); then, with the CameraInfo, the undistorted tracked point of each frame.

The log reader (:func:`amsfe_sym.logs.stream.read_topics`) hands each slice of an image
topic's payloads (one MCAP or bag chunk, or a bounded slice of messages) to an
:class:`ImageDecoder`: each image is decoded, searched for the marker and dropped, so memory
holds the corners of every frame and one slice of images, never every image.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.vision.camera_info import CameraInfo, undistort
from amsfe_sym.vision.images import GreyImage, UndecodableImageError, grey_from_message
from amsfe_sym.vision.marker import (
    NO_MARKER,
    OTHER_ID,
    TOO_OBLIQUE,
    MarkerDetector,
    diagonals_meet_many,
    raw_corners_unbent,
)
from amsfe_sym.vision.spec import CORNERS, MarkerSpec

__all__ = [
    "REASONS",
    "UNDECODABLE",
    "Detections",
    "FrameColumns",
    "ImageDecoder",
    "image_sizes",
    "points_of",
    "tracked_points",
    "undistorted_corners",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: The pixels of an image that did not decode.
_NOTHING = np.zeros((0, 0), np.uint8)

#: A frame whose compressed bytes do not decode (a corrupt jpeg or png): skipped, counted.
UNDECODABLE = "whose image bytes do not decode (corrupt)"
#: Why a frame has no point, by code (0: found); the log reader counts them by these names.
REASONS = ("", NO_MARKER, OTHER_ID, UNDECODABLE, TOO_OBLIQUE)


@dataclass
class Detections:
    """An image topic's frames as columns (one row per message, in the order given).

    Attributes:
        stamp_ns: ``header.stamp`` [ns]: the exposure, (M,).
        corners: The marker's corners in raw pixels (M, 4, 2) [px]; NaN where not found.
        reason: Index into :data:`REASONS` (0: found), (M,).
        size: Each image's width and height (M, 2) [px].
    """

    stamp_ns: IntArray
    corners: FloatArray
    reason: IntArray
    size: IntArray

    @staticmethod
    def concat(parts: Sequence[Detections]) -> Detections:
        """Slices of one topic joined as if decoded at once."""
        return Detections(
            np.concatenate([p.stamp_ns for p in parts]),
            np.concatenate([p.corners for p in parts]),
            np.concatenate([p.reason for p in parts]),
            np.concatenate([p.size for p in parts]),
        )


class ImageDecoder:
    """``decode(payloads, encoding, where)`` of an image topic (the log reader's decoder
    contract, :func:`amsfe_sym.logs.decode.decode_payloads`): every image decoded to grey
    and searched for ``spec``'s marker.

    Args:
        msgtype: ``sensor_msgs/msg/Image`` or ``sensor_msgs/msg/CompressedImage``.
        spec: The marker.
        deserialize: ``deserialize(raw, msgtype, encoding, where)`` -> a message (the log
            reader's, :func:`amsfe_sym.logs.image_wire.image_message`); ``raw`` is a
            payload's bytes, or a uint8 view of them when the payloads have a ``view(i)``
            (the log reader's :class:`~amsfe_sym.logs.layout.Payloads`: no copy).

    Attributes:
        frames: Images decoded so far (for a progress line).
    """

    def __init__(self, msgtype: str, spec: MarkerSpec, deserialize: Callable[..., Any]) -> None:
        self.msgtype, self.spec, self.deserialize = msgtype, spec, deserialize
        self.detector = MarkerDetector(spec)
        self.frames = 0
        self._last: FloatArray | None = None  # the previous image's corners: the region

    def __call__(self, raws: Sequence[bytes], encoding: str = "cdr", where: str = "") -> Detections:
        M = len(raws)
        cols = FrameColumns(M)
        view = getattr(raws, "view", raws.__getitem__)
        for i in range(M):
            self.detect_into(cols, i, self.grey(view(i), encoding, where))
        return cols.detections()

    def grey(self, raw: Any, encoding: str = "cdr", where: str = "") -> GreyImage:
        """One payload (``raw``: bytes or a uint8 view) decoded to grey; no pixels (an empty
        array) when its image bytes do not decode (a corrupt jpeg or png: the frame is
        skipped and counted).

        Raises:
            LogError: a payload that is not such a message, an encoding not supported.
        """
        msg = self.deserialize(raw, self.msgtype, encoding, where)
        try:
            return grey_from_message(msg, self.msgtype, where or self.msgtype)
        except UndecodableImageError as exc:
            return GreyImage(exc.stamp_ns, _NOTHING)

    def detect_into(self, cols: FrameColumns, i: int, img: GreyImage) -> None:
        """Row ``i`` of ``cols``: ``img`` searched for the marker, around the previous
        frame's corners first (so frames must come in the log's order: the region of
        interest makes each detection depend on the one before)."""
        cols.stamp_ns[i] = img.stamp_ns
        if img.pixels is _NOTHING:
            cols.reason[i] = REASONS.index(UNDECODABLE)
            self.frames += 1
            return  # (the next frame is searched around the last corners found before)
        cols.size[i] = img.pixels.shape[1], img.pixels.shape[0]
        det = self.detector.detect(img.pixels, self._last)  # (around the last first)
        self._last = det.near
        if det.corners is None:
            cols.reason[i] = REASONS.index(det.skipped or NO_MARKER)
        else:
            cols.corners[i] = det.corners
        self.frames += 1


class FrameColumns:
    """The rows of one slice of frames, filled frame by frame (:class:`Detections`'s
    columns, preallocated for ``M`` frames)."""

    def __init__(self, M: int) -> None:
        self.stamp_ns = np.zeros(M, np.int64)
        self.corners = np.full((M, 4, 2), np.nan)
        self.reason = np.zeros(M, np.int64)
        self.size = np.zeros((M, 2), np.int64)

    def detections(self) -> Detections:
        """The slice's :class:`Detections`."""
        return Detections(self.stamp_ns, self.corners, self.reason, self.size)


def undistorted_corners(info: CameraInfo, corners: FloatArray, spec: MarkerSpec) -> FloatArray:
    """Detected corners (M, 4, 2) [px, raw image] undistorted by ``info`` into its pinhole's
    pixels, the edge fit's raw-image lines' error taken off first
    (:func:`~amsfe_sym.vision.marker.raw_corners_unbent`); NaN rows stay NaN."""
    c = raw_corners_unbent(info, corners, spec)
    out: FloatArray = undistort(info, c.reshape(-1, 2)).reshape(-1, 4, 2)
    return out


def points_of(det: Detections, info: CameraInfo, spec: MarkerSpec) -> FloatArray:
    """The tracked point of each frame (M, 2) [px], undistorted by ``info`` into its
    pinhole's pixels (NaN where the marker was not found): the corners are undistorted
    first, then the centre is where their diagonals meet (which is the projection of the
    marker's centre only in an undistorted image)."""
    out = np.full((det.stamp_ns.size, 2), np.nan)
    found = np.flatnonzero(det.reason == 0)
    out[found] = tracked_points(undistorted_corners(info, det.corners[found], spec), spec)
    return out


def tracked_points(und: FloatArray, spec: MarkerSpec) -> FloatArray:
    """The tracked point (M, 2) [px] of each frame's undistorted corners ``und`` (M, 4, 2):
    :func:`~amsfe_sym.vision.marker.tracked_point` of all frames at once."""
    if spec.point == "centre":
        return diagonals_meet_many(und)
    return np.array(und[:, CORNERS.index(spec.point)], dtype=np.float64)


def image_sizes(det: Detections) -> list[tuple[int, int]]:
    """The distinct image sizes (width, height) of a topic, in order of first appearance
    (of the images that decoded)."""
    seen: list[tuple[int, int]] = []
    for w, h in det.size[det.reason != REASONS.index(UNDECODABLE)].tolist():
        if (w, h) not in seen:
            seen.append((w, h))
    return seen
