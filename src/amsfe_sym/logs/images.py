"""An image camera topic of a log -> the camera frames the estimators take, and the
simulated camera's images as messages (docs/camera.md).

The reader decodes the image topic with :func:`decoders` (detection, a slice at a time);
:func:`image_frames` then undistorts each detected point with the log's CameraInfo and puts
it on the tick grid exactly as a pixel topic's point
(:func:`amsfe_sym.logs.sensors.camera_frames`), frames without the marker counted by reason
beside the reader's own reasons."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import IntArray
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.decode import Points, deserialize
from amsfe_sym.logs.grid import RoleUse, count_skip
from amsfe_sym.logs.image_wire import image_message
from amsfe_sym.logs.plan import LogPlan
from amsfe_sym.logs.sensors import OnGrid, camera_frames
from amsfe_sym.vision.camera_info import CameraInfo, camera_info_from_message
from amsfe_sym.vision.detections import (
    REASONS,
    Detections,
    ImageDecoder,
    image_sizes,
    tracked_points,
    undistorted_corners,
)
from amsfe_sym.vision.marker import single_threaded
from amsfe_sym.vision.prefetch import Prefetch, image_threads
from amsfe_sym.vision.sim_images import SimulatedCamera
from amsfe_sym.vision.spec import CAMERA_INFO, MarkerSpec

__all__ = ["CameraInfos", "close_decoders", "decoders", "image_frames", "image_messages"]


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
    stamps = np.zeros(len(raws), np.int64)
    infos = np.empty(len(raws), dtype=object)
    for i in range(len(raws)):
        msg = deserialize(raws[i], CAMERA_INFO, encoding, where)  # type: ignore[arg-type]
        s = msg.header.stamp
        stamps[i] = int(s.sec) * 1_000_000_000 + int(s.nanosec)
        infos[i] = camera_info_from_message(msg, where or "CameraInfo")
    return CameraInfos(stamps, infos)


def decoders(plan: LogPlan, marker: MarkerSpec, threads: int | None = None) -> dict[str, Any]:
    """The log reader's decoders of an image camera topic and its CameraInfo topic (none
    for a pixel topic): images read in place (:mod:`amsfe_sym.logs.image_wire`), each
    OpenCV call on one thread (:func:`amsfe_sym.vision.marker.single_threaded`).

    ``threads``: decoding threads beside the reading thread (:class:`~amsfe_sym.vision.
    prefetch.Prefetch`, which the caller closes: :func:`close_decoders`); 0 decodes and
    detects on the reading thread; None: :func:`~amsfe_sym.vision.prefetch.image_threads`
    (``$AMSFE_IMAGE_THREADS``, else 2 for compressed images on 2 or more cores, 0 for raw
    ones).
    """
    if plan.camera_info is None:
        return {}
    single_threaded()
    image = plan.roles["camera"]
    msgtype = plan.topics[image].msgtype
    serial = ImageDecoder(msgtype, marker, image_message)
    compressed = msgtype.endswith("CompressedImage")
    n = image_threads(compressed=compressed) if threads is None else threads
    return {
        image: Prefetch(serial, n) if n > 0 else serial,
        plan.camera_info: _decode_infos,
    }


def close_decoders(decoders: dict[str, Any]) -> None:
    """End the threads of :func:`decoders`' decoders (after the read, an error or Ctrl-C)."""
    for d in decoders.values():
        if isinstance(d, Prefetch):
            d.close()


def image_frames(log: OnGrid, use: RoleUse, marker: MarkerSpec) -> list[CameraFrame]:
    """The camera frames of an image topic (``log``: the reader's
    :class:`~amsfe_sym.logs.sensors.OnGrid`, ``use``: the camera role's
    :class:`~amsfe_sym.logs.grid.RoleUse`): each found marker's point undistorted by the
    first CameraInfo, at its image's exposure stamp and arrival.

    Raises:
        LogError: no CameraInfo message, an image of another size than the CameraInfo, or a
            log in which the marker is never found.
    """
    plan = log.plan
    topic, info_topic = plan.roles["camera"], str(plan.camera_info)
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
    corners = undistorted_corners(info, det.corners[found], marker)
    pts = tracked_points(corners, marker)
    xyz = np.column_stack([pts, np.zeros(len(pts))])
    on_grid = replace(
        log,
        times={**log.times, topic: log.times[topic][found]},
        decoded={**log.decoded, topic: Points(det.stamp_ns[found], xyz)},
    )
    return camera_frames(on_grid, use, corners)


def image_messages(
    camera: SimulatedCamera, stamp_ns: int, q: Any, theta: Any
) -> tuple[Any, Any, Any]:
    """The simulated ``camera``'s image (a ``rosbags`` Image, or CompressedImage for jpeg and
    png) of the arm at (q [rad], theta), its CameraInfo and a ``visualization_msgs/
    ImageMarker`` (a green circle where the camera chain detects the tracked point: Foxglove
    draws it over the image; None without the marker), all stamped ``stamp_ns`` [ns] (the
    exposure)."""
    from amsfe_sym.logs.source import typestore

    ts = typestore().types
    stamp = ts["builtin_interfaces/msg/Time"](
        sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
    )
    header = ts["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")
    img = camera.image(q, theta)
    h, w = img.shape
    if camera.options.format == "mono8":
        msg = ts["sensor_msgs/msg/Image"](
            header=header, height=h, width=w, encoding="mono8", is_bigendian=0, step=w,
            data=img.ravel(),
        )  # fmt: skip
    else:
        msg = ts["sensor_msgs/msg/CompressedImage"](
            header=header, format=camera.options.format, data=camera.encoded(img)
        )
    i = camera.info
    roi = ts["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    info = ts["sensor_msgs/msg/CameraInfo"](
        header=header, height=i.height, width=i.width, distortion_model=i.model,
        d=np.asarray(i.D, np.float64), k=i.K.ravel().copy(), r=i.R.ravel().copy(),
        p=i.P.ravel().copy(), binning_x=0, binning_y=0, roi=roi,
    )  # fmt: skip
    found = camera.detected(img)
    if found is None:
        return msg, info, None
    marker = ts["visualization_msgs/msg/ImageMarker"]
    green = ts["std_msgs/msg/ColorRGBA"](r=0.1, g=0.9, b=0.2, a=1.0)
    none = ts["std_msgs/msg/ColorRGBA"](r=0.0, g=0.0, b=0.0, a=0.0)
    mark = marker(
        header=header, ns="amsfe", id=0, type=marker.CIRCLE, action=marker.ADD,
        position=ts["geometry_msgs/msg/Point"](x=float(found[0]), y=float(found[1]), z=0.0),
        scale=6.0, outline_color=green, filled=0, fill_color=none,
        lifetime=ts["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), points=[],
        outline_colors=[],
    )  # fmt: skip
    return msg, info, mark
