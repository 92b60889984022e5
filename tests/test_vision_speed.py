"""The camera chain's fast paths (docs/camera.md, "Speed") against the reference paths:
image payloads read in place against ``rosbags``' deserializer (both encodings, every image
kind, bytes and a view of a chunk's buffer); bad payloads still refused in one line; a log's
centres in one pass against frame by frame; small slices joined; a log's summary parsed
once per file version.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from amsfe_sym.errors import LogError
from amsfe_sym.logs.decode import deserialize
from amsfe_sym.logs.image_wire import CompressedImageView, ImageView, image_message
from amsfe_sym.logs.layout import Payloads
from amsfe_sym.vision.images import grey_from_message

IMG, CIMG = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"
KINDS = ("mono8", "mono8 padded", "rgb8", "bgr8", "jpeg", "png")


def _typestore(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _payload(kind: str, ros1: bool, frame_id: str = "cam") -> tuple[bytes, str]:
    """A driver's payload of a 37 x 29 image (odd sizes: CDR's alignment matters) of kind
    ``kind``, serialized by rosbags."""
    ts = _typestore(ros1)
    T = ts.types
    rng = np.random.default_rng(7)
    grey = rng.integers(0, 256, (29, 37), dtype=np.uint8)
    stamp = T["builtin_interfaces/msg/Time"](sec=1_700_000_123, nanosec=987_654_321)
    if ros1:
        header = T["std_msgs/msg/Header"](seq=41, stamp=stamp, frame_id=frame_id)
    else:
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)
    if kind in ("jpeg", "png"):
        ok, buf = cv2.imencode(".jpg" if kind == "jpeg" else ".png", grey)
        assert ok
        msg: Any = T[CIMG](header=header, format=kind, data=buf.ravel())
        msgtype = CIMG
    else:
        enc = kind.split()[0]
        img = grey if enc == "mono8" else np.dstack([grey, grey[::-1], 255 - grey])
        row = img.reshape(29, -1)
        if kind.endswith("padded"):
            row = np.hstack([row, np.zeros((29, 3), np.uint8)])
        msg = T[IMG](
            header=header, height=29, width=37, encoding=enc, is_bigendian=0,
            step=row.shape[1], data=row.ravel(),
        )  # fmt: skip
        msgtype = IMG
    raw = ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)
    return bytes(raw), msgtype


@pytest.mark.parametrize("ros1", [False, True], ids=["cdr", "ros1"])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("frame_id", ["cam", "", "camera_optical_frame"])
def test_payloads_read_in_place_match_rosbags(kind: str, ros1: bool, frame_id: str) -> None:
    """Every field the chain uses equals rosbags' message's, from bytes and from a view of a
    chunk's buffer (the pixels then a view of that buffer, not a copy), and the grey images
    made of both are identical."""
    raw, msgtype = _payload(kind, ros1, frame_id)
    encoding = "ros1" if ros1 else "cdr"
    ref = deserialize(raw, msgtype, encoding)  # type: ignore[arg-type]
    chunk = Payloads.of([b"\x01" * 13, raw, b"\x02" * 5])  # (the payload mid-buffer)
    for src in (raw, chunk.view(1)):
        got = image_message(src, msgtype, encoding)  # type: ignore[arg-type]
        assert isinstance(got, CompressedImageView if msgtype == CIMG else ImageView)
        s, r = got.header.stamp, ref.header.stamp
        assert (s.sec, s.nanosec) == (r.sec, r.nanosec) == (1_700_000_123, 987_654_321)
        fields = ("format",) if msgtype == CIMG else ("height", "width", "encoding", "step")
        for f in (*fields, *(() if msgtype == CIMG else ("is_bigendian",))):
            assert getattr(got, f) == getattr(ref, f), f
        assert np.array_equal(got.data, np.asarray(ref.data, np.uint8))
        a = grey_from_message(got, msgtype)
        b = grey_from_message(ref, msgtype)
        assert a.stamp_ns == b.stamp_ns and np.array_equal(a.pixels, b.pixels)
    view = image_message(chunk.view(1), msgtype, encoding)  # type: ignore[arg-type]
    assert np.shares_memory(view.data, chunk.buffer)


@pytest.mark.parametrize("ros1", [False, True], ids=["cdr", "ros1"])
@pytest.mark.parametrize("cut", ["truncated", "trailing", "long string"])
def test_bad_payloads_go_to_the_reference_and_are_refused(ros1: bool, cut: str) -> None:
    """A payload the in-place reader does not take is the reference's: a truncated one, one
    with bytes after its data (ROS 1) or a string length past the end is refused in one
    line by rosbags' deserializer, as before."""
    raw, msgtype = _payload("mono8", ros1)
    encoding = "ros1" if ros1 else "cdr"
    if cut == "truncated":
        bad = raw[:-100]
    elif cut == "trailing":
        bad = raw + b"\x00" * (8 if not ros1 else 1)
    else:
        at = 4 + 8 if not ros1 else 12  # the frame_id's length
        bad = raw[:at] + (10**6).to_bytes(4, "little") + raw[at + 4 :]
    with pytest.raises(LogError) as err:
        image_message(bad, msgtype, encoding, "topic /cam")  # type: ignore[arg-type]
    assert "\n" not in str(err.value) and "topic /cam" in str(err.value)


def test_the_centres_of_a_log_match_one_frame_at_a_time() -> None:
    """``points_of`` takes every frame's centre at once (:func:`diagonals_meet_many`): the
    same numbers as :func:`tracked_point` frame by frame, for the centre and a corner."""
    from amsfe_sym.vision.camera_info import make_camera_info, undistort
    from amsfe_sym.vision.detections import Detections, points_of
    from amsfe_sym.vision.marker import tracked_point
    from amsfe_sym.vision.spec import MarkerSpec

    rng = np.random.default_rng(3)
    M = 50
    centre = rng.uniform(100, 400, (M, 1, 2))
    corners = (
        centre + rng.normal(0, 3, (M, 4, 2)) + 15 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    )
    reason = np.where(rng.uniform(size=M) < 0.2, 1, 0)
    corners[reason == 1] = np.nan
    det = Detections(np.arange(M, dtype=np.int64), corners, reason, np.tile([640, 480], (M, 1)))
    K = [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]]
    info = make_camera_info(640, 480, "plumb_bob", K, (-0.12, 0.04, 0.0005, -0.0003, 0.0))
    for point in ("centre", "bottom_left"):
        got = points_of(det, info, MarkerSpec(point=point))  # type: ignore[arg-type]
        for i in range(M):
            if reason[i]:
                assert np.isnan(got[i]).all()
            else:
                want = tracked_point(undistort(info, corners[i]), point)
                assert np.abs(got[i] - want).max() < 1e-9, (point, i)


def test_small_slices_join_into_the_same_payloads() -> None:
    """``Payloads.join`` (the log reader decoding a topic's small slices together, as a log
    of images cuts them): the same payloads in order, out of buffers it no longer holds."""
    rng = np.random.default_rng(5)
    raws = [rng.integers(0, 256, rng.integers(0, 40), dtype=np.uint8).tobytes() for _ in range(30)]
    parts = []
    for a, b in ((0, 7), (7, 8), (8, 21), (21, 30)):
        pad = b"\xff" * 11
        whole = Payloads.of([pad, *raws[a:b], pad])  # (a chunk's buffer around them)
        parts.append(Payloads(whole.buffer, whole.offsets[1:-1], whole.lengths[1:-1]))
    joined = Payloads.join(parts)
    assert list(joined) == raws
    assert joined.buffer.size == sum(len(r) for r in raws)
    assert not any(np.shares_memory(joined.buffer, p.buffer) for p in parts)


def _mcap(path: Path, topic: str, count: int) -> None:
    from mcap.writer import Writer

    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel(topic, "cdr", sid)
        for i in range(count):
            w.add_message(
                cid, log_time=i, publish_time=i, data=b"\x00\x01\x00\x00\x01\x00\x00\x00\x00"
            )
        w.finish()


def test_a_log_summary_is_parsed_once_per_file_version(tmp_path: Path) -> None:
    """``summary_of`` (asked for by the first messages' search and by the read) parses a
    file once; the same path holding another file (even of the same size) is parsed again."""
    from amsfe_sym.logs.chunks import summary_of

    path = tmp_path / "log.mcap"
    _mcap(path, "/a", 3)
    first = summary_of(path)
    assert summary_of(path) is first
    _mcap(path, "/b", 3)  # (same size: another topic name of the same length)
    again = summary_of(path)
    assert again is not first
    assert [c.topic for c in again.channels.values()] == ["/b"]
