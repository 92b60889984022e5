"""An image camera topic of a log -> the camera frames the estimators take (docs/camera.md):
the stage between the log reader and estimation.  The reader decodes the image topic with
:func:`decoders` (detection, a slice at a time); :func:`image_frames` then undistorts each
detected point with the log's CameraInfo and puts it on the tick grid exactly as a pixel
topic's point (:func:`amsfe_sym.logs.sensors.camera_frames`), frames without the marker
counted by reason beside the reader's own reasons."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import LogError, describe
from amsfe_sym.vision.camera_info import CameraInfo, camera_info_from_message
from amsfe_sym.vision.detections import REASONS, Detections, ImageDecoder, image_sizes, points_of
from amsfe_sym.vision.spec import CAMERA_INFO, MarkerSpec

__all__ = ["CameraInfos", "decoders", "image_frames"]

IntArray = NDArray[np.int64]


@dataclass
class CameraInfos:
    """A CameraInfo topic's messages: ``stamp_ns`` (M,) [ns] and ``infos`` (M,) objects."""

    stamp_ns: IntArray
    infos: NDArray[np.object_]

    @staticmethod
    def concat(parts: Sequence[CameraInfos]) -> CameraInfos:
        """Slices joined as if decoded at once."""
        return CameraInfos(
            np.concatenate([p.stamp_ns for p in parts]), np.concatenate([p.infos for p in parts])
        )


def _decode_infos(raws: Sequence[bytes], encoding: str = "cdr", where: str = "") -> CameraInfos:
    from amsfe_sym.logs.decode import deserialize

    stamps = np.zeros(len(raws), np.int64)
    infos = np.empty(len(raws), dtype=object)
    for i in range(len(raws)):
        msg = deserialize(raws[i], CAMERA_INFO, encoding, where)  # type: ignore[arg-type]
        s = msg.header.stamp
        stamps[i] = int(s.sec) * 1_000_000_000 + int(s.nanosec)
        infos[i] = camera_info_from_message(msg, where or "CameraInfo")
    return CameraInfos(stamps, infos)


def decoders(plan: Any, marker: MarkerSpec) -> dict[str, Any]:
    """The log reader's decoders of an image camera topic and its CameraInfo topic (none
    for a pixel topic)."""
    if plan.camera_info is None:
        return {}
    image = plan.roles["camera"]
    return {
        image: ImageDecoder(plan.topics[image].msgtype, marker),
        plan.camera_info: _decode_infos,
    }


def image_frames(log: Any, use: Any, marker: MarkerSpec) -> list[CameraFrame]:
    """The camera frames of an image topic (``log``: the reader's
    :class:`~amsfe_sym.logs.sensors.OnGrid`, ``use``: the camera role's
    :class:`~amsfe_sym.logs.grid.RoleUse`): each found marker's point undistorted by the
    first CameraInfo, at its image's exposure stamp and arrival.

    Raises:
        LogError: no CameraInfo message, an image of another size than the CameraInfo, or a
            log in which the marker is never found.
    """
    from amsfe_sym.logs.decode import Points
    from amsfe_sym.logs.grid import count_skip
    from amsfe_sym.logs.sensors import camera_frames

    plan = log.plan
    topic, info_topic = plan.roles["camera"], plan.camera_info
    det: Detections = log.decoded[topic]
    infos: CameraInfos | None = log.decoded.get(info_topic)
    where = f"log {log.path}: {info_topic} (CameraInfo of {topic})"
    if infos is None or infos.infos.size == 0:
        raise LogError(describe(where, "CameraInfo messages", "none", "record the info topic"))
    info: CameraInfo = infos.infos[0]
    for w, h in image_sizes(det):
        if (w, h) != (info.width, info.height):
            raise LogError(
                describe(
                    where,
                    f"the images' size {w} x {h} px",
                    f"a CameraInfo of {info.width} x {info.height} px",
                    "record the CameraInfo of this camera mode (or rescale the calibration)",
                )
            )
    found = det.reason == 0
    if det.reason.size and not found.any():
        counts = {REASONS[r]: int((det.reason == r).sum()) for r in np.unique(det.reason)}
        raise LogError(
            describe(
                f"log {log.path}: {topic} (camera images)",
                f"the marker {marker.dictionary} id {marker.id} in at least one image",
                f"none of {det.reason.size} images: {counts}",
                "name the marker the camera sees in the topic spec's [marker] (dictionary, id)",
            )
        )
    for r in range(1, len(REASONS)):
        count_skip(use, REASONS[r], int((det.reason == r).sum()))
    pts = points_of(det, info, marker)[found]
    xyz = np.column_stack([pts, np.zeros(len(pts))])
    on_grid = replace(
        log,
        times={**log.times, topic: log.times[topic][found]},
        decoded={**log.decoded, topic: Points(det.stamp_ns[found], xyz)},
    )
    return camera_frames(on_grid, use)
