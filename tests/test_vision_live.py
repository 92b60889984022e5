"""The camera chain live (docs/camera.md, "Live"): ``amsfe camera-node``'s detection worker
(its own thread, the newest image only) gives the points of the offline chain, counts what
it skips, and over real DDS publishes the pixel topic ``amsfe node`` takes, at the image's
exposure stamp, with its detection latency in its diagnostics."""

from __future__ import annotations

import itertools
import json
import os
import threading
import time
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.camera_node import BUSY, NO_INFO, DetectionWorker
from amsfe_sym.scenario import load_scenario
from amsfe_sym.vision.camera_info import undistort
from amsfe_sym.vision.marker import MarkerDetector, tracked_point
from amsfe_sym.vision.spec import MarkerSpec
from tests.test_vision import LENS, _typestore, image_msg, info_msg

MARKER = MarkerSpec(size=0.1)
_COUNTER = itertools.count()


@pytest.fixture(scope="module")
def shots():
    """Six images of the paper's arm (the simulated camera, distorted lens) with their
    stamps [ns], the camera's CameraInfo and the offline chain's point of each."""
    from amsfe_sym.vision.sim_images import ImageOptions, SimulatedCamera

    lib = library_for(load_scenario("paper-sim"))
    opts = ImageOptions(marker=MARKER, model=LENS[0], D=LENS[1])
    cam = SimulatedCamera(
        lib.manifest.camera, lib.function("tracked_point"), opts, np.random.default_rng(3)
    )
    rng = np.random.default_rng(4)
    out = []
    det = MarkerDetector(MARKER)
    while len(out) < 6:
        q = rng.uniform(-1.5, 1.5, lib.n)
        img = cam.image(q, lib.theta_true)
        d = det.detect(img)
        if d.corners is None:
            continue
        point = tracked_point(undistort(cam.info, d.corners), "centre")
        out.append((1_000_000_000 + 40_000_000 * len(out), img, point))
    return cam.info, out


def test_the_worker_gives_the_offline_points_and_counts_skips(shots) -> None:
    """Images given from this thread, points published from the worker's: the offline
    chain's points bit for bit at the images' stamps; an image before any CameraInfo
    skipped; one replaced while the worker is busy dropped and counted."""
    info, frames = shots
    ts = _typestore(False)
    got: list[tuple[int, float, float]] = []
    hold, held = threading.Event(), threading.Event()

    def publish(stamp: int, u: float, v: float) -> None:
        got.append((stamp, u, v))
        if len(got) == 1:  # the worker stops here until two more images were queued
            held.set()
            assert hold.wait(60)

    w = DetectionWorker(MARKER, publish)
    w.start()
    try:
        msgs = [image_msg(ts, False, s * 1e-9, img, "mono8") for s, img, _ in frames]
        w.image(msgs[0], "sensor_msgs/msg/Image")  # no CameraInfo yet
        deadline = time.monotonic() + 60
        while w.stats.skipped.get(NO_INFO, 0) < 1:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        w.info(info_msg(ts, False, 0.0, info))
        w.image(msgs[0], "sensor_msgs/msg/Image")
        assert held.wait(60)
        w.image(msgs[1], "sensor_msgs/msg/Image")  # replaced by the next: dropped
        w.image(msgs[2], "sensor_msgs/msg/Image")
        hold.set()
        for m in msgs[3:]:
            while len(got) < 2 + (msgs.index(m) - 3):  # one at a time: none dropped
                assert time.monotonic() < deadline
                time.sleep(0.01)
            w.image(m, "sensor_msgs/msg/Image")
        while len(got) < len(frames) - 1:
            assert time.monotonic() < deadline, (got, w.diagnostics())
            time.sleep(0.01)
    finally:
        w.stop()
    want = [f for i, f in enumerate(frames) if i != 1]
    assert [g[0] for g in got] == [f[0] for f in want]
    for (_, u, v), (_, _, p) in zip(got, want, strict=True):
        assert (u, v) == (p[0], p[1])
    diag = w.diagnostics()
    assert diag["images"] == 7 and diag["points"] == 5
    assert diag["skipped"] == {NO_INFO: 1, BUSY: 1}
    assert set(diag["latency_ms"]) == {"median", "p90", "max"}
    assert diag["detection_ms"]["max"] <= diag["latency_ms"]["max"]


@pytest.mark.ros
@pytest.mark.slow
# rclpy in this process: its IDL parser (lark) imports the deprecated sre_parse
@pytest.mark.filterwarnings("ignore:module 'sre_parse' is deprecated:DeprecationWarning")
@pytest.mark.filterwarnings("ignore:module 'sre_constants' is deprecated:DeprecationWarning")
def test_camera_node_over_dds(shots, monkeypatch) -> None:
    """The camera node on real DDS (its own domain, localhost): a driver's Image and
    CameraInfo in, the PointStamped pixel topic out at the images' stamps with the offline
    chain's points, and diagnostics with the detection latency.  Every wait bounded."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, Image
    from std_msgs.msg import String

    from amsfe_sym.ros import messages as m
    from amsfe_sym.ros.camera_node import DIAGNOSTICS, CameraNodeOptions, build_camera_node
    from amsfe_sym.ros.middleware import executor, ns_to_stamp, qos_profile, start, stop
    from amsfe_sym.topics.spec import parse_topic_spec

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    domain = 1 + (os.getpid() * 41 + next(_COUNTER)) % 101
    prefix = f"/t{os.getpid()}_{next(_COUNTER)}"
    info, frames = shots
    spec = parse_topic_spec({"topics": {"camera": f"{prefix}/camera/marker"}})
    opts = CameraNodeOptions(
        spec=spec, image=f"{prefix}/camera/image_raw", info=f"{prefix}/camera/camera_info"
    )
    ctx = start(None, domain)
    node, worker = build_camera_node(ctx, opts)
    peer = Node("driver", context=ctx)
    got: list[Any] = []
    diags: list[dict] = []
    peer.create_subscription(m.PointStamped, spec.camera, got.append, qos_profile(spec))
    peer.create_subscription(
        String, DIAGNOSTICS, lambda d: diags.append(json.loads(d.data)), qos_profile(spec)
    )
    img_pub = peer.create_publisher(Image, opts.image, qos_profile(spec))
    info_pub = peer.create_publisher(CameraInfo, opts.info, qos_profile(spec))
    ex = executor(ctx)
    ex.add_node(node)
    ex.add_node(peer)
    try:
        deadline = time.monotonic() + 90
        while img_pub.get_subscription_count() < 1 or info_pub.get_subscription_count() < 1:
            assert time.monotonic() < deadline, "no camera node subscription"
            ex.spin_once(timeout_sec=0.05)
        for stamp, img, _ in frames:
            hdr = m.Header(stamp=ns_to_stamp(stamp), frame_id="camera")
            ci = CameraInfo(
                header=hdr, width=info.width, height=info.height,
                distortion_model=info.model, d=info.D.tolist(), k=info.K.ravel().tolist(),
                r=info.R.ravel().tolist(), p=info.P.ravel().tolist(),
            )  # fmt: skip
            info_pub.publish(ci)
            h, w = img.shape
            msg = Image(header=hdr, height=h, width=w, encoding="mono8", step=w)
            msg.data = img.tobytes()
            n = len(got)
            img_pub.publish(msg)
            while len(got) == n:  # one at a time (a slow machine drops none)
                assert time.monotonic() < deadline, worker.diagnostics()
                ex.spin_once(timeout_sec=0.05)
        while not diags or diags[-1]["points"] < len(frames):
            assert time.monotonic() < deadline, worker.diagnostics()
            ex.spin_once(timeout_sec=0.05)
    finally:
        worker.stop()
        ex.shutdown()
        stop(ctx, node, peer)
    stamps = [int(p.header.stamp.sec) * 1_000_000_000 + int(p.header.stamp.nanosec) for p in got]
    assert stamps == [f[0] for f in frames]
    for p, (_, _, want) in zip(got, frames, strict=True):
        assert (p.point.x, p.point.y) == (want[0], want[1])
    last = diags[-1]
    assert last["images"] == last["points"] == len(frames) and not last["skipped"]
    assert last["latency_ms"]["median"] > 0 and last["detection_ms"]["median"] > 0


@pytest.mark.ros
@pytest.mark.slow
def test_sim_node_images_through_camera_node_into_node(tmp_path) -> None:
    """``sim-node --images --lockstep`` (images + CameraInfo instead of the pixel topic),
    ``camera-node`` and ``node --controller amsfe`` over DDS for 2 s: every frame the arm's
    camera took reaches the camera node, and the node as a point at its exposure stamp (but
    the last, which may come after the node's end), and the node fuses them."""
    import signal

    from tests.test_node_record import _bag
    from tests.test_ros import PATIENT_ARM, PATIENT_NODE, _finish, _ros_env, _start

    env = _ros_env(tmp_path)
    p = env["AMSFE_TEST_TOPIC_PREFIX"]
    remap = ["--ros-args"]
    for t in ("/camera/image_raw", "/camera/camera_info", "/amsfe/camera/diagnostics"):
        remap += ["-r", f"{t}:={p}{t}"]
    rec = tmp_path / "rec"
    procs, cam = [], None
    try:
        cam = _start(env, "camera-node", "--duration", "600", *remap)
        procs.append(
            _start(env, "node", "paper-sim", "--controller", "amsfe", "--duration", "2",
                   "--record", str(rec), *PATIENT_NODE)
        )  # fmt: skip
        procs.append(_start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "2",
                            "--images", *PATIENT_ARM, *remap))  # fmt: skip
        results = _finish(procs, 300.0)
    finally:
        if cam is not None:
            if cam.p.poll() is None:
                cam.kill(signal.SIGINT)
            results_cam = _finish([cam], 60.0)
    for code, text in results:
        assert code == 0, text
    bag = _bag(rec)
    points = bag["/camera/marker"]
    # 2 s of an 8 Hz camera: 16 images, every one accounted for by the camera node (a point,
    # or dropped because a newer image came first).  How many points reach the node before
    # its end depends on the machine: detection is not in lockstep (it never holds the
    # loop), and a lockstep run faster than real time ends before late detections arrive
    # (1 of 16 in a run under load 12, 14-16 when the test was written): not asserted.
    assert points, "no point reached the node"
    stamps = [int(m.header.stamp.sec) * 10**9 + int(m.header.stamp.nanosec) for m in points]
    assert all(s % 125_000_000 == 0 for s in stamps), stamps  # exposure stamps, every 125 ms
    assert stamps == sorted(set(stamps))
    diag = json.loads(bag["/amsfe/diagnostics"][-1].data)
    assert diag["frames_fused"] > 0
    # Ctrl-C ends the camera node cleanly: held while rclpy runs its callbacks, raised
    # between spins, so no lock is left held and the detection thread is joined
    assert results_cam[0][0] == 0, results_cam
    last = [ln for ln in results_cam[0][1].splitlines() if ln.startswith("camera-node: {")]
    assert last, results_cam
    cam_diag = json.loads(last[-1].split(": ", 1)[1])
    assert cam_diag["images"] == 16, cam_diag
    assert cam_diag["points"] + sum(cam_diag["skipped"].values()) == 16, cam_diag
