"""The simulated camera's images and CameraInfo as ROS messages (``amsfe simulate --bag
--images``; docs/camera.md, "Simulated images").

Each delivered frame of a run becomes the image the true camera took at its exposure step:
the marker centred on the true tracked point (the generated ``tracked_point`` at the true
q and theta), facing the camera, or, when the robot spec gives ``[tracked] orientation``,
fixed to its link (:mod:`amsfe_sym.vision.marker_pose`: turned with the link, seen
obliquely, not drawn when the camera does not see it), rendered through the robot's pinhole
and :class:`ImageOptions`' distortion, blur and noise (:mod:`amsfe_sym.vision.render`),
stamped with the exposure and logged at its delivery, with the CameraInfo (K = the robot's
intrinsics, the distortion, P = [K | 0]) of the same stamp (the messages:
:func:`amsfe_sym.logs.images.image_messages`).  One image is held at a time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.vision.camera_info import CameraInfo, make_camera_info
from amsfe_sym.vision.marker_pose import MarkerPose
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer, marker_corners
from amsfe_sym.vision.spec import MarkerSpec

__all__ = [
    "COMPRESSED_TOPIC",
    "IMAGE_FORMATS",
    "IMAGE_TOPIC",
    "INFO_TOPIC",
    "LENSES",
    "ImageOptions",
    "SimulatedCamera",
]

FloatArray = NDArray[np.float64]
ImageFormat = Literal["mono8", "jpeg", "png"]
#: How ``--images`` writes a frame: a raw mono8 Image, or a jpeg / png CompressedImage.
IMAGE_FORMATS: tuple[str, ...] = ("mono8", "jpeg", "png")

#: Lenses to render through (model, D): a webcam's barrel (the simulated camera's default),
#: a strong wide-angle's (plumb_bob), a rational_polynomial, a fisheye (equidistant), and an
#: already rectified image (the tests' and tools/camera_accuracy.py's lenses).
LENSES: dict[str, tuple[str, tuple[float, ...]]] = {
    "plumb_bob": ("plumb_bob", (-0.12, 0.04, 0.0005, -0.0003, 0.0)),
    "plumb_bob_strong": ("plumb_bob", (-0.3, 0.1, 0.001, -0.001, -0.02)),
    "rational_polynomial": ("rational_polynomial", (-0.2, 0.05, 0.001, -5e-4, 0.0, 0.01, 0, 0)),
    "equidistant": ("equidistant", (-0.05, 0.01, 0.0, 0.0)),
    "rectified": ("plumb_bob", (0.0, 0.0, 0.0, 0.0, 0.0)),
}

#: The topics the simulated camera writes (a usb_cam / image_proc layout).
IMAGE_TOPIC = "/camera/image_raw"
COMPRESSED_TOPIC = "/camera/image_raw/compressed"
INFO_TOPIC = "/camera/camera_info"


@dataclass(frozen=True)
class ImageOptions:
    """What the simulated camera writes.

    Attributes:
        format: ``mono8`` (sensor_msgs/Image) or ``jpeg`` / ``png`` (CompressedImage).
        marker: The marker on the tracked point (a 10 cm AprilTag 36h11 id 0 by default:
            about 27 px across at the 2-link arm's 1.5 m and f = 400 px).
        noise: Blur, pixel noise and contrast of the images.
        model: The true camera's distortion model (``plumb_bob``, ``rational_polynomial``,
            ``equidistant``).
        D: Its coefficients (all zero: a rectified camera).
        jpeg_quality: 0..100 for ``jpeg``.
    """

    format: ImageFormat = "mono8"
    marker: MarkerSpec = field(default_factory=lambda: MarkerSpec(size=0.1))
    noise: ImageNoise = field(default_factory=ImageNoise)
    model: str = LENSES["plumb_bob"][0]
    D: tuple[float, ...] = LENSES["plumb_bob"][1]
    jpeg_quality: int = 95

    def __post_init__(self) -> None:
        if self.format not in IMAGE_FORMATS:
            raise ConfigError(
                describe("--images", f"one of {list(IMAGE_FORMATS)}", repr(self.format), "fix it")
            )


class SimulatedCamera:
    """The true camera of a run: its CameraInfo and a renderer (built once).

    Args:
        manifest_camera: The library's resolved camera (``lib.manifest.camera``: K, R_cw,
            position, width, height).
        tracked_point: ``r = tracked_point(q, theta)`` [m], the generated function.
        options: What to write.
        rng: The images' noise (seeded by the run's seed).
        pose: The marker fixed to its link
            (:func:`~amsfe_sym.logs.sim_marker.marker_pose_of`); None: it faces the camera.
    """

    def __init__(
        self,
        manifest_camera: Any,
        tracked_point: Any,
        options: ImageOptions,
        rng: np.random.Generator,
        pose: MarkerPose | None = None,
    ) -> None:
        cam = manifest_camera
        self.K = np.asarray(cam.K, dtype=np.float64)
        self.R_cw = np.asarray(cam.R_cw, dtype=np.float64)
        self.position = np.asarray(cam.position, dtype=np.float64)
        self.info: CameraInfo = make_camera_info(
            cam.width, cam.height, options.model, self.K, options.D
        )
        self.options, self.rng = options, rng
        self.tracked_point, self.pose = tracked_point, pose
        self.renderer = MarkerRenderer(self.info, options.marker, options.noise)
        self._detector: Any = None

    @property
    def image_topic(self) -> str:
        """The topic the images go to."""
        return IMAGE_TOPIC if self.options.format == "mono8" else COMPRESSED_TOPIC

    @property
    def image_type(self) -> str:
        """Their message type."""
        return (
            "sensor_msgs/msg/Image"
            if self.options.format == "mono8"
            else "sensor_msgs/msg/CompressedImage"
        )

    def corners(self, q: FloatArray, theta: FloatArray) -> FloatArray | None:
        """The marker's 4 corners (4, 2) [px] in the pinhole image at (q, theta); None when
        the camera does not see the marker fixed to its link
        (:attr:`~amsfe_sym.vision.marker_pose.MarkerView.seen`)."""
        if self.pose is not None:
            view = self.pose.view(self.K, self.R_cw, self.position, q, self.options.marker.size)
            return view.corners if view.seen else None
        r = np.asarray(self.tracked_point(q, theta)[0], dtype=np.float64).ravel()
        return marker_corners(self.K, self.R_cw, self.position, r, self.options.marker.size)

    def image(self, q: FloatArray, theta: FloatArray) -> NDArray[np.uint8]:
        """The grey image (height, width) the true camera takes of the arm at (q [rad],
        theta)."""
        if self.pose is None:
            return self.renderer.render(self.corners(q, theta), self.rng)
        return self.renderer.render(self.corners(q, theta), self.rng, foreshortened=True)

    def detected(self, image: NDArray[np.uint8]) -> FloatArray | None:
        """The tracked point the camera chain finds in ``image``, in the raw image's pixels
        (undistorted to take the point, then distorted back: where to draw it on the image)
        [px], or None without the marker."""
        from amsfe_sym.vision.camera_info import distort
        from amsfe_sym.vision.detections import undistorted_corners
        from amsfe_sym.vision.marker import MarkerDetector, tracked_point

        if self._detector is None:
            self._detector = MarkerDetector(self.options.marker)
        det = self._detector.detect(image)
        if det.corners is None:
            return None
        und = undistorted_corners(self.info, det.corners, self.options.marker)[0]
        point = tracked_point(und, self.options.marker.point)
        return distort(self.info, point)[0]

    def encoded(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """``image`` compressed as :attr:`ImageOptions.format` (jpeg or png) says."""
        import cv2

        ext = ".jpg" if self.options.format == "jpeg" else ".png"
        params = [cv2.IMWRITE_JPEG_QUALITY, self.options.jpeg_quality] if ext == ".jpg" else []
        ok, buf = cv2.imencode(ext, image, params)
        if not ok:  # (OpenCV encodes any uint8 image; this is its failure flag)
            raise ConfigError(describe("--images", f"an encodable {ext}", "none", "use mono8"))
        return np.asarray(buf, np.uint8).ravel()
