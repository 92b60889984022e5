"""Images in (docs/camera.md): ``sensor_msgs/Image`` and ``CompressedImage`` with
``CameraInfo`` in every container the log reader reads, written as drivers write them
(rosbags' serializers: ROS 1 ``.bag``, rosbag2 in MCAP and sqlite3, a plain ``.mcap``),
decoded, detected and fused as camera frames; skipped frames counted by reason; bad input
refused in one line with nothing written.

The logs come from a 1 s paper-sim run (tests/test_log_reader.py's driver-style
``/joint_states``: header stamps 203.6 s ahead of log time, jitter, latency): each camera
frame becomes the image the true camera took at its exposure (the marker rendered at the
true q through a distorted lens), stamped at exposure on the header clock and logged at its
arrival, with its CameraInfo.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError, LogError
from amsfe_sym.logs import stream
from amsfe_sym.logs.read import plan_log, read_log
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.topics.spec import parse_topic_spec
from amsfe_sym.vision.camera_info import camera_info_from_message, read_camera_info
from amsfe_sym.vision.detections import ImageDecoder
from amsfe_sym.vision.images import grey_from_message
from amsfe_sym.vision.marker import NO_MARKER, OTHER_ID
from amsfe_sym.vision.prefetch import THREADS_ENV, Prefetch
from amsfe_sym.vision.sim_images import ImageOptions, SimulatedCamera
from amsfe_sym.vision.spec import MarkerSpec
from tests.test_log_reader import OFFSET_S, Ev, _cli, _one_line, arm_events


@pytest.fixture(scope="module")
def sim():
    """A 1 s paper-sim run (compiled loop, oosm): 8 camera frames."""
    sc = load_scenario("paper-sim").with_overrides(
        estimator="oosm", controller="amsfe", duration=1.0, seed=3
    )
    return run(sc, library_for(sc), runtime="compiled")


IMG, CIMG, INFO = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/CameraInfo",
)
LENS = ("plumb_bob", (-0.12, 0.04, 0.0005, -0.0003, 0.0))


def _typestore(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _header(ts: Any, ros1: bool, stamp_s: float) -> Any:
    ns = round(stamp_s * 1e9)
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    if ros1:
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="camera")
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")


def image_msg(ts: Any, ros1: bool, stamp_s: float, grey: np.ndarray, encoding: str) -> Any:
    """The message a driver writes for ``grey`` in ``encoding`` (mono8, rgb8, bgr8 with a
    row padding of 8 bytes as some drivers have, or jpeg / png compressed)."""
    hdr = _header(ts, ros1, stamp_s)
    if encoding in ("jpeg", "png"):
        ok, buf = cv2.imencode(".jpg" if encoding == "jpeg" else ".png", grey)
        assert ok
        return ts.types[CIMG](header=hdr, format=encoding, data=buf.ravel())
    h, w = grey.shape
    if encoding == "mono8":
        px = grey[:, :, None]
    else:
        bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        bgr[..., 0] = np.clip(bgr[..., 0].astype(int) + 7, 0, 255)  # (colour: not grey x 3)
        px = bgr if encoding == "bgr8" else bgr[..., ::-1]
    ch = px.shape[2]
    rows = np.zeros((h, w * ch + 8), np.uint8)
    rows[:, : w * ch] = px.reshape(h, w * ch)
    return ts.types[IMG](
        header=hdr, height=h, width=w, encoding=encoding, is_bigendian=0, step=w * ch + 8,
        data=rows.ravel(),
    )  # fmt: skip


def info_msg(ts: Any, ros1: bool, stamp_s: float, info: Any, model: str | None = None) -> Any:
    """``info`` as the driver's CameraInfo (ROS 1: upper-case K, D, R, P)."""
    T = ts.types
    roi = T["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    f = np.float64
    mats = {"d": info.D, "k": info.K.ravel(), "r": info.R.ravel(), "p": info.P.ravel()}
    mats = {(k.upper() if ros1 else k): np.asarray(v, f) for k, v in mats.items()}
    return T[INFO](
        header=_header(ts, ros1, stamp_s), height=info.height, width=info.width,
        distortion_model=model or info.model, binning_x=0, binning_y=0, roi=roi, **mats,
    )  # fmt: skip


def write_images_log(path: Path, joints: list[Ev], frames: list[tuple], fmt: str) -> Path:
    """A log of ``joints`` (tests/test_log_reader.py's events) and camera ``frames``
    ``(log time [s], topic, msgtype, build(ts, ros1))``, in ``fmt``: ``bag`` (ROS 1),
    ``mcap`` / ``sqlite3`` (rosbag2) or ``mcapfile`` (the plain .mcap)."""
    from tests.test_log_reader import _msg

    ros1 = fmt == "bag"
    ts = _typestore(ros1)
    events = sorted(
        [(e.t, e.topic, e.msgtype, lambda ts, r, e=e: _msg(ts, r, e)) for e in joints] + frames,
        key=lambda e: e[0],
    )
    types = {e[1]: e[2] for e in events}

    def payload(e: tuple) -> bytes:
        m = e[3](ts, ros1)
        return ts.serialize_ros1(m, e[2]) if ros1 else ts.serialize_cdr(m, e[2])

    if ros1:
        from rosbags.rosbag1 import Writer as Ros1Writer

        with Ros1Writer(path) as w:
            conns = {t: w.add_connection(t, m, typestore=ts) for t, m in types.items()}
            for e in events:
                w.write(conns[e[1]], round(e[0] * 1e9), payload(e))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.SQLITE3 if fmt == "sqlite3" else StoragePlugin.MCAP
    with Writer(path, version=9, storage_plugin=plugin) as w2:
        c2 = {t: w2.add_connection(t, m, typestore=ts) for t, m in types.items()}
        for e in events:
            w2.write(c2[e[1]], round(e[0] * 1e9), payload(e))
    return path / f"{path.name}.mcap" if fmt == "mcapfile" else path


def camera_of(res: Any, seed: int = 0, marker: MarkerSpec | None = None) -> SimulatedCamera:
    lib = res.lib
    opts = ImageOptions(marker=marker or MarkerSpec(size=0.1), model=LENS[0], D=LENS[1])
    return SimulatedCamera(
        lib.manifest.camera, lib.function("tracked_point"), opts, np.random.default_rng(seed)
    )


def image_frames(
    res: Any,
    encoding: str = "mono8",
    *,
    topic: str | None = None,
    info_size: tuple[int, int] | None = None,
    model: str | None = None,
    other: dict[int, str] | None = None,
) -> tuple[list[tuple], dict[int, np.ndarray]]:
    """The camera's frames of ``res`` as image events, and the true pinhole pixel of each
    exposure step (the generated camera map at the true q).  ``other``: frame index ->
    ``"blank"`` (no marker) or ``"id"`` (another marker) in place of the true image."""
    lib = res.lib
    cam = camera_of(res)
    other_cam = camera_of(res, 1, MarkerSpec(size=0.1, id=7))
    L = lib.layout
    T = lib.T
    camera = lib.function("camera")
    rng = np.random.default_rng(5)
    events: list[tuple] = []
    truth: dict[int, np.ndarray] = {}
    topic = topic or ("/camera/image_raw/compressed" if encoding in ("jpeg", "png") else None)
    topic = topic or "/camera/image_raw"
    info = cam.info
    if info_size is not None:
        from dataclasses import replace

        info = replace(info, width=info_size[0], height=info_size[1])
    for i, (kappa, arrive, _, _) in enumerate(res.frames):
        ka, ar = int(kappa), int(arrive)
        x = res.x_true[ka]
        q, theta = x[L["q"]], x[L["theta"]]
        kind = (other or {}).get(i)
        if kind == "blank":
            grey = np.full((info.height, info.width), 110, np.uint8)
        elif kind == "id":
            grey = other_cam.image(q, theta)
        else:
            grey = cam.image(q, theta)
            truth[ka] = np.asarray(camera(q, theta)[0], dtype=np.float64).ravel()
        lat = rng.uniform(0.1, 0.6) * 1e-3
        stamp = ka * T + OFFSET_S
        msgtype = CIMG if encoding in ("jpeg", "png") else IMG
        events.append(
            (
                ar * T + lat,
                topic,
                msgtype,
                lambda ts, r, g=grey, s=stamp: image_msg(ts, r, s, g, encoding),
            )
        )
        events.append(
            (
                ar * T + lat,
                "/camera/camera_info",
                INFO,
                lambda ts, r, s=stamp: info_msg(ts, r, s, info, model),
            )
        )
    return events, truth


def _read(res: Any, log: Path, spec: LogSpec | None = None):
    lib = res.lib
    return read_log(log, spec or LogSpec(), list(lib.manifest.joints), lib.T, lib.N)


def _check_frames(res: Any, got: Any, truth: dict[int, np.ndarray], tol: float = 0.6) -> None:
    """Every frame with the marker fused at its exposure step and arrival tick, its point
    within ``tol`` px of the generated camera map at the true q."""
    frames = {f.exposure_step: f for f in got.frames}
    assert sorted(frames) == sorted(truth)
    arrive = {int(k): int(a) for k, a, _, _ in res.frames}
    for k, f in frames.items():
        assert f.delivery_step == arrive[k]
        assert np.abs(f.z - truth[k]).max() < tol, (k, f.z, truth[k])


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["bag", "mcap", "sqlite3", "mcapfile"])
def test_each_container(fmt: str, sim, tmp_path) -> None:
    """mono8 images + CameraInfo + /joint_states (no pixel topic) in every container: the
    image topic is found, its CameraInfo beside it, every frame fused at its exposure."""
    joints, _ = arm_events(sim, camera=False)
    frames, truth = image_frames(sim)
    log = write_images_log(tmp_path / ("log.bag" if fmt == "bag" else "log"), joints, frames, fmt)
    got = _read(sim, log)
    assert got.plan is not None and got.plan.roles["camera"] == "/camera/image_raw"
    assert got.plan.how["camera"] == "found" and got.plan.camera_info == "/camera/camera_info"
    _check_frames(sim, got, truth)
    use = got.usage["camera"]
    assert use.used == use.messages == len(sim.frames) and not use.skipped


@pytest.mark.slow
@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "jpeg", "png"])
def test_each_encoding(encoding: str, sim, tmp_path) -> None:
    """rgb8, bgr8 (padded rows) and jpeg / png CompressedImage: the same frames."""
    joints, _ = arm_events(sim, camera=False)
    frames, truth = image_frames(sim, encoding)
    got = _read(sim, write_images_log(tmp_path / "log", joints, frames, "mcap"))
    _check_frames(sim, got, truth, tol=0.8 if encoding == "jpeg" else 0.6)


def test_grey_is_what_opencv_makes_of_each_encoding() -> None:
    """The decoded grey image of each encoding equals OpenCV's conversion of the source
    (bit for bit; jpeg within its loss); the colour channels are not swapped."""
    ts = _typestore(False)
    rng = np.random.default_rng(0)
    grey = rng.integers(0, 256, (48, 64), dtype=np.uint8)
    bgr = np.dstack([grey, np.roll(grey, 3), np.roll(grey, 7)]).astype(np.uint8)
    want = {
        "mono8": grey,
        "bgr8": cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY),
        "rgb8": cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY),
    }
    for enc, src in (("mono8", grey[:, :, None]), ("bgr8", bgr), ("rgb8", bgr[..., ::-1])):
        h, w, ch = src.shape
        msg = ts.types[IMG](
            header=_header(ts, False, 1.0), height=h, width=w, encoding=enc, is_bigendian=0,
            step=w * ch, data=np.ascontiguousarray(src).ravel(),
        )  # fmt: skip
        out = grey_from_message(msg, IMG)
        assert out.stamp_ns == 1_000_000_000
        assert np.array_equal(out.pixels, want[enc]), enc
    for fmt in ("png", "jpeg"):
        m = image_msg(ts, False, 2.0, grey, fmt)
        out = grey_from_message(m, CIMG).pixels
        assert (
            np.array_equal(out, grey)
            if fmt == "png"
            else np.abs(out - grey.astype(int)).mean() < 20
        )


@pytest.mark.parametrize(
    ("field", "value"), [("encoding", "yuv422"), ("encoding", "16UC1"), ("format", "tiff")]
)
def test_unsupported_encodings_are_refused_in_one_line(field: str, value: str) -> None:
    ts = _typestore(False)
    grey = np.zeros((4, 4), np.uint8)
    if field == "format":
        msg = image_msg(ts, False, 0.0, grey, "png")
        msg.format = value
        t = CIMG
    else:
        msg = image_msg(ts, False, 0.0, grey, "mono8")
        msg.encoding = value
        t = IMG
    with pytest.raises(LogError) as e:
        grey_from_message(msg, t, "topic /cam")
    assert value in str(e.value) and "\n" not in str(e.value)


@pytest.mark.slow
def test_skipped_frames_are_counted_by_reason(sim, tmp_path) -> None:
    """A frame without the marker, one with another id: skipped and counted by those
    reasons; the others fused."""
    joints, _ = arm_events(sim, camera=False)
    frames, truth = image_frames(sim, other={1: "blank", 3: "id", 5: "blank"})
    got = _read(sim, write_images_log(tmp_path / "log", joints, frames, "mcap"))
    use = got.usage["camera"]
    assert use.skipped == {NO_MARKER: 2, OTHER_ID: 1}
    assert use.used == len(sim.frames) - 3
    assert got.skipped[f"frame {NO_MARKER}"] == 2
    _check_frames(sim, got, truth)


def test_the_camera_info_yaml_and_message_agree(sim, tmp_path) -> None:
    """camera_calibration's YAML (ost.yaml) and the CameraInfo message (ROS 2 and ROS 1
    spellings) give the same calibration."""
    info = camera_of(sim).info
    K, D, P = info.K.ravel().tolist(), info.D.tolist(), info.P.ravel().tolist()
    yaml_text = (
        f"image_width: {info.width}\nimage_height: {info.height}\ncamera_name: narrow_stereo\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: {K}\n"
        f"distortion_model: {info.model}\n"
        f"distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: {D}\n"
        "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
        f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: {P}\n"
    )
    (tmp_path / "ost.yaml").write_text(yaml_text)
    a = read_camera_info(tmp_path / "ost.yaml")
    for ros1 in (False, True):
        b = camera_info_from_message(info_msg(_typestore(ros1), ros1, 0.0, info))
        for f in ("K", "D", "R", "P"):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
        assert (a.width, a.height, a.model, a.pinhole) == (b.width, b.height, b.model, b.pinhole)
    assert a.pinhole == (info.K[0, 0], info.K[1, 1], info.K[0, 2], info.K[1, 2])
    (tmp_path / "bad.yaml").write_text("image_width: 640\n")
    with pytest.raises(ConfigError) as e:
        read_camera_info(tmp_path / "bad.yaml")
    assert "image_height" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.slow
def test_the_topic_spec_names_image_info_and_marker(sim, tmp_path) -> None:
    """``[topics] camera`` names the image topic, ``[camera] info`` its CameraInfo and
    ``[marker]`` the marker; bad values are refused in one line."""
    spec = parse_topic_spec(
        {
            "topics": {"camera": "/cam/image"},
            "camera": {"info": "/cam/info"},
            "marker": {"dictionary": "DICT_4X4_50", "id": 3, "size": 0.04, "point": "top_left"},
        }
    )
    assert spec.camera == "/cam/image" and spec.camera_info == "/cam/info"
    assert spec.marker == MarkerSpec("DICT_4X4_50", 3, 0.04, "top_left")
    for bad in (
        {"marker": {"dictionary": "DICT_9X9_1"}},
        {"marker": {"id": -1}},
        {"marker": {"size": 0}},
        {"marker": {"point": "middle"}},
        {"marker": {"colour": 1}},
        {"camera": {"info": "cam/info"}},
    ):
        with pytest.raises(ConfigError) as e:
            parse_topic_spec(bad)
        assert "\n" not in str(e.value)
    # named in a log: the spec's topics are taken, a missing CameraInfo topic refused
    joints, _ = arm_events(sim, camera=False)
    frames, _ = image_frames(sim, topic="/cam/image")
    log = write_images_log(tmp_path / "log", joints, frames, "mcap")
    lib = sim.lib
    plan = plan_log(
        log, parse_topic_spec({"topics": {"camera": "/cam/image"}}), lib.manifest.joints
    )
    assert plan.roles["camera"] == "/cam/image" and plan.how["camera"] == "named"
    assert plan.camera_info == "/camera/camera_info"  # the log's one CameraInfo topic
    with pytest.raises(LogError) as e:
        plan_log(log, spec, lib.manifest.joints)
    assert "/cam/info" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("case", "needle"),
    [
        ("size", "640 x 512"),
        ("model", "'kannala'"),
        ("never", "id 4"),
        ("encoding", "'yuv422'"),
    ],
)
def test_bad_image_logs_are_refused_in_one_line(
    case: str, needle: str, sim, tmp_path, capsys
) -> None:
    """``amsfe estimate``: a CameraInfo of another size than the images, an unknown
    distortion model, a marker never seen, an encoding not supported: one line, exit 2,
    no run folder."""
    joints, _ = arm_events(sim, camera=False)
    kw: dict[str, Any] = {}
    if case == "size":
        kw["info_size"] = (800, 600)
    if case == "model":
        kw["model"] = "kannala"
    frames, _ = image_frames(sim, **kw)
    if case == "encoding":
        frames = [
            (t, topic, m, (lambda ts, r, b=b: _recode(b(ts, r))) if m == IMG else b)
            for t, topic, m, b in frames
        ]
    log = write_images_log(tmp_path / "log", joints, frames, "mcap")
    args = ["estimate", str(log), "--robot", "paper_2link", "--out", str(tmp_path / "o")]
    if case == "never":
        (tmp_path / "spec.toml").write_text("[marker]\nid = 4\n")
        args += ["--log-spec", str(tmp_path / "spec.toml")]
    code, _, err = _cli([*args, "--no-plots"], capsys)
    _one_line(code, err, tmp_path / "o")
    assert needle in err, err


def _recode(msg: Any) -> Any:
    msg.encoding = "yuv422"
    return msg


@pytest.mark.slow
def test_images_are_detected_a_slice_at_a_time(sim, tmp_path, monkeypatch) -> None:
    """Memory holds one slice of images: on the message path (sqlite3) a slice is cut at
    SLICE_BYTES, on the MCAP path at each chunk; the decoder never sees the whole topic."""
    joints, _ = arm_events(sim, camera=False)
    frames, truth = image_frames(sim)
    seen: list[int] = []
    calls = {c: c.__call__ for c in (ImageDecoder, Prefetch)}

    def spied(cls: type) -> Any:
        def spy(self: Any, raws: Any, *a: Any) -> Any:
            seen.append(len(raws))
            return calls[cls](self, raws, *a)

        return spy

    for cls in calls:
        monkeypatch.setattr(cls, "__call__", spied(cls))
    monkeypatch.setattr(stream, "SLICE_BYTES", 700_000)  # two 640 x 512 mono8 images
    for threads in ("0", "1"):  # (serial, and decoded ahead: vision.prefetch)
        monkeypatch.setenv(THREADS_ENV, threads)
        for fmt in ("sqlite3", "mcap"):
            seen.clear()
            got = _read(sim, write_images_log(tmp_path / f"{fmt}{threads}", joints, frames, fmt))
            _check_frames(sim, got, truth)
            assert sum(seen) == len(sim.frames) and max(seen) <= 3 and len(seen) >= 3, (fmt, seen)


def test_images_without_a_bag_are_refused_in_one_line(tmp_path, capsys) -> None:
    """``amsfe simulate --images`` without ``--bag``: one line, exit 2, no run folder."""
    out = tmp_path / "run"
    code, _, err = _cli(["simulate", "--images", "--out", str(out), "--no-plots"], capsys)
    _one_line(code, err, out)
    assert "--bag" in err
