"""``amsfe camera-node``: the camera chain live (docs/camera.md, "Live").  It subscribes a
camera's image topic (``sensor_msgs/Image`` or ``CompressedImage``) and its CameraInfo,
detects the marker on a thread of its own and publishes the undistorted point as the
``geometry_msgs/PointStamped`` pixel topic that ``amsfe node`` already takes (stamp = the
image's exposure stamp), so the estimator's encoder path never waits for a detection.

The detection thread takes the newest image: an image still waiting when a newer one comes
is dropped and counted ("detector busy"), so a slow detection delays frames but never piles
them up.  Its diagnostics (``/amsfe/camera/diagnostics``, JSON, once a second) count frames
by outcome and report the detection latency: from the image's reception to its point's
publication, and the decode + detect + undistort time alone [ms].
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from amsfe_sym.core.interrupts import DeferredSignals
from amsfe_sym.errors import LogError
from amsfe_sym.topics.spec import TopicSpec
from amsfe_sym.vision.camera_info import CameraInfo, camera_info_from_message
from amsfe_sym.vision.detections import undistorted_corners
from amsfe_sym.vision.images import grey_from_message
from amsfe_sym.vision.marker import MarkerDetector, single_threaded, tracked_point
from amsfe_sym.vision.spec import MarkerSpec

__all__ = ["DIAGNOSTICS", "CameraNodeOptions", "DetectionWorker", "run_camera_node"]

#: The camera node's diagnostics topic.
DIAGNOSTICS = "/amsfe/camera/diagnostics"
BUSY = "dropped: detector busy (a newer image came first)"
NO_INFO = "no CameraInfo yet"


@dataclass
class _Stats:
    received: int = 0
    published: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    latency_ms: list[float] = field(default_factory=list)  # reception -> publication
    work_ms: list[float] = field(default_factory=list)  # decode + detect + undistort

    def skip(self, reason: str) -> None:
        self.skipped[reason] = self.skipped.get(reason, 0) + 1


def _spread(values: list[float]) -> dict[str, float]:
    if not values:
        return {}
    a = np.asarray(values[-1000:])
    return {
        "median": round(float(np.median(a)), 3),
        "p90": round(float(np.percentile(a, 90)), 3),
        "max": round(float(a.max()), 3),
    }


class DetectionWorker:
    """Images in from any thread (:meth:`image`), points out from its own thread.

    Args:
        marker: What to detect.
        publish: ``publish(stamp_ns, u, v)``: the undistorted point [px] of the image
            stamped ``stamp_ns`` (called on the worker's thread).
        clock: Seconds, monotonic (the latency's clock).
    """

    def __init__(
        self,
        marker: MarkerSpec,
        publish: Callable[[int, float, float], None],
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.marker, self.publish, self.clock = marker, publish, clock
        self.detector = MarkerDetector(marker)
        self.stats = _Stats()
        self._info: CameraInfo | None = None
        self._pending: tuple[Any, str, float] | None = None
        self._cv = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="amsfe-detection", daemon=True)

    def start(self) -> None:
        """Start the detection thread (OpenCV on one thread: :func:`single_threaded`)."""
        single_threaded()
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop it (the image it is on is finished first)."""
        with self._cv:
            self._stop = True
            self._cv.notify()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def info(self, msg: Any) -> None:
        """A CameraInfo message (the newest one is used)."""
        try:
            self._info = camera_info_from_message(msg)
        except LogError:
            self.stats.skip("CameraInfo refused")

    def image(self, msg: Any, msgtype: str) -> None:
        """An image message (``msgtype``: its ROS 2 type name), as it arrives: queued for
        the thread, replacing one still waiting (counted)."""
        now = self.clock()
        with self._cv:
            self.stats.received += 1
            if self._pending is not None:
                self.stats.skip(BUSY)
            self._pending = (msg, msgtype, now)
            self._cv.notify()

    def _run(self) -> None:
        while True:
            with self._cv:
                while self._pending is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                job, self._pending = self._pending, None
            assert job is not None
            self._one(*job)

    def _one(self, msg: Any, msgtype: str, received: float) -> None:
        t0 = self.clock()
        info = self._info
        if info is None:
            self.stats.skip(NO_INFO)
            return
        try:
            grey = grey_from_message(msg, msgtype, "image")
        except LogError as exc:
            self.stats.skip(f"undecodable: {str(exc).split(';')[0]}")
            return
        h, w = grey.pixels.shape
        if (w, h) != (info.width, info.height):
            self.stats.skip("image size differs from the CameraInfo's")
            return
        det = self.detector.detect(grey.pixels)
        if det.corners is None:
            self.stats.skip(det.skipped or "without the marker")
            return
        und = undistorted_corners(info, det.corners, self.marker)[0]
        u, v = tracked_point(und, self.marker.point)
        self.stats.work_ms.append((self.clock() - t0) * 1e3)
        self.publish(grey.stamp_ns, float(u), float(v))
        self.stats.published += 1
        self.stats.latency_ms.append((self.clock() - received) * 1e3)

    def diagnostics(self) -> dict[str, Any]:
        """Counts by outcome and the latency spreads [ms] (median, p90, max of the last
        1000 frames)."""
        s = self.stats
        return {
            "images": s.received,
            "points": s.published,
            "skipped": dict(s.skipped),
            "latency_ms": _spread(s.latency_ms),
            "detection_ms": _spread(s.work_ms),
        }


@dataclass(frozen=True)
class CameraNodeOptions:
    """How ``amsfe camera-node`` runs.

    Attributes:
        spec: The topic spec: its ``[marker]``, its pixel topic (``[topics] camera`` is the
            topic published; ``amsfe node`` subscribes the same) and QoS.
        image: The image topic.
        info: The CameraInfo topic.
        compressed: Whether ``image`` carries ``CompressedImage``.
        duration: Stop after this long [s] (None: until Ctrl-C).
        ros_args: ``--ros-args`` (remaps, parameters).
        domain_id: ROS_DOMAIN_ID (None: the environment's).
    """

    spec: TopicSpec
    image: str = "/camera/image_raw"
    info: str = "/camera/camera_info"
    compressed: bool = False
    duration: float | None = None
    ros_args: tuple[str, ...] = ()
    domain_id: int | None = None


def build_camera_node(ctx: Any, opts: CameraNodeOptions) -> tuple[Any, DetectionWorker]:
    """The rclpy node (subscriptions, publishers, a 1 s diagnostics timer) and its worker,
    started, on context ``ctx``."""
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo as InfoMsg
    from sensor_msgs.msg import CompressedImage, Image

    from amsfe_sym.ros import messages as m
    from amsfe_sym.ros.middleware import qos_profile

    node = Node("amsfe_camera", context=ctx)
    qos = qos_profile(opts.spec, depth=2)
    pixels = node.create_publisher(m.PointStamped, opts.spec.camera, qos_profile(opts.spec))
    diag = node.create_publisher(m.String, DIAGNOSTICS, qos_profile(opts.spec, depth=10))

    def publish(stamp_ns: int, u: float, v: float) -> None:
        pixels.publish(m.point_stamped(stamp_ns, u, v))

    worker = DetectionWorker(opts.spec.marker, publish)
    kind, mtype = (
        (CompressedImage, "sensor_msgs/msg/CompressedImage")
        if opts.compressed
        else (Image, "sensor_msgs/msg/Image")
    )
    node.create_subscription(kind, opts.image, lambda msg: worker.image(msg, mtype), qos)
    node.create_subscription(InfoMsg, opts.info, worker.info, qos_profile(opts.spec))
    node.create_timer(1.0, lambda: diag.publish(m.String(data=json.dumps(worker.diagnostics()))))
    worker.start()
    return node, worker


def run_camera_node(opts: CameraNodeOptions, say: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the camera node until ``opts.duration`` or Ctrl-C; its last diagnostics.

    Raises:
        RosError: rclpy missing or the middleware not starting.
    """
    from amsfe_sym.ros.middleware import executor, start, stop

    ctx = start(list(opts.ros_args), opts.domain_id)
    node, worker = build_camera_node(ctx, opts)
    ex = executor(ctx)
    ex.add_node(node)
    say(f"camera-node: {opts.image} + {opts.info} -> {opts.spec.camera} (marker "
        f"{opts.spec.marker.dictionary} id {opts.spec.marker.id})")  # fmt: skip
    end = None if opts.duration is None else time.monotonic() + opts.duration
    try:
        # Ctrl-C / SIGTERM held while rclpy runs the callbacks and raised between spins:
        # raised inside :meth:`DetectionWorker.image`'s ``with`` (its condition's lock taken,
        # the block not yet entered) it would leave that lock held, and the detection thread
        # would wait for it until ``stop``'s join gave up (core.interrupts).
        with DeferredSignals() as signals:
            while ctx.ok() and (end is None or time.monotonic() < end):
                ex.spin_once(timeout_sec=0.1)
                signals.check()
    except KeyboardInterrupt:
        pass
    finally:
        worker.stop()
        out = worker.diagnostics()
        say(f"camera-node: {json.dumps(out)}")
        ex.shutdown()
        stop(ctx, node)
    return out
