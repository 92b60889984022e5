"""The camera chain (docs/camera.md): image + CameraInfo -> the marker's corners -> the
undistorted tracked point at the exposure stamp -> the camera frame the estimators take.

The stage between robot I/O and estimation: :mod:`~amsfe_sym.vision.spec` (what to look
for), :mod:`~amsfe_sym.vision.camera_info` (CameraInfo, undistortion by point),
:mod:`~amsfe_sym.vision.images` (image messages -> grey), :mod:`~amsfe_sym.vision.marker`
(ArUco / AprilTag detection, the tracked point), :mod:`~amsfe_sym.vision.detections` (an
image topic's payloads, a slice at a time), :mod:`~amsfe_sym.vision.render` and
:mod:`~amsfe_sym.vision.sim_images` (the simulated camera's images).  OpenCV is imported
only when an image is handled.

May import: ``errors`` and ``core`` only.  It knows images and points, not containers or
messages' wire formats: the log reader (``logs.images``) and the live node (``ros``) call
it with decoded messages and a deserializer.
"""

from __future__ import annotations

from amsfe_sym.vision.camera_info import (
    CameraInfo,
    camera_info_from_message,
    make_camera_info,
    parse_camera_info,
    read_camera_info,
    undistort,
)
from amsfe_sym.vision.spec import MarkerSpec, parse_marker

__all__ = [
    "CameraInfo",
    "MarkerSpec",
    "camera_info_from_message",
    "make_camera_info",
    "parse_camera_info",
    "parse_marker",
    "read_camera_info",
    "undistort",
]
