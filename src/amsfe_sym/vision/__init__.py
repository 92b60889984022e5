"""The camera chain (docs/camera.md): image + CameraInfo -> the marker's corners -> the
undistorted tracked point at the exposure stamp -> the camera frame the estimators take.

The stage between robot I/O and estimation: :mod:`~amsfe_sym.vision.spec` (what to look
for), :mod:`~amsfe_sym.vision.camera_info` (CameraInfo, undistortion by point),
:mod:`~amsfe_sym.vision.images` (image messages -> grey), :mod:`~amsfe_sym.vision.marker`
(ArUco / AprilTag detection, the tracked point), :mod:`~amsfe_sym.vision.detections` and
:mod:`~amsfe_sym.vision.log_frames` (a log's image topic, a slice at a time),
:mod:`~amsfe_sym.vision.render` (the simulated camera's images) and
:mod:`~amsfe_sym.vision.node` (live detection beside ``amsfe node``).  OpenCV is imported
only when an image is handled.
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
