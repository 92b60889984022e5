"""The topic spec's ``[camera] time_offset`` [s] (header stamp - exposure, what ``amsfe
calibrate`` measures; docs/calibrate.md): parsed and bounded, turned into whole ticks, applied
by the live loops of ``amsfe node`` (Python and C) as by the log reader, and written by
``amsfe calibrate`` into the topic spec it outputs.  The log reader's side, a
recording with a known camera delay estimated with and without the key, is
tests/test_calibrate.py (slow: it simulates)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.calibration.spec_out import calibrated_topic_spec
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.cnode import c_node_refusal
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.spec import TopicSpec, parse_topic_spec, read_topic_spec

EPOCH_NS = 1_700_000_000 * 10**9


def test_the_key_is_read_and_rounded_to_ticks() -> None:
    spec = parse_topic_spec({"camera": {"time_offset": 0.0123}})
    assert spec.camera_time_offset == 0.0123
    assert spec.exposure_shift(0.001) == 12  # 12.3 ticks: frames are fused at ticks
    assert spec.exposure_shift(0.01) == 1
    assert parse_topic_spec({"camera": {"time_offset": -0.0251}}).exposure_shift(0.001) == -25
    assert TopicSpec().camera_time_offset == 0.0 and TopicSpec().exposure_shift(0.001) == 0
    both = parse_topic_spec({"camera": {"info": "/cam/info", "time_offset": 0.1}})
    assert both.camera_info == "/cam/info" and both.camera_time_offset == 0.1


@pytest.mark.parametrize(
    ("value", "words"),
    [("25ms", "time_offset"), (2.0, "time_offset"), (float("nan"), "time_offset")],
)
def test_a_bad_time_offset_is_one_line(value: Any, words: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_topic_spec({"camera": {"time_offset": value}}, "topics.toml")
    msg = str(err.value)
    assert "\n" not in msg and words in msg and "topics.toml [camera]" in msg


def test_an_unknown_camera_key_names_both_keys() -> None:
    with pytest.raises(ConfigError, match=r"\['info', 'time_offset'\]"):
        parse_topic_spec({"camera": {"delay": 0.1}})


def test_the_c_node_runs_it() -> None:
    """The C node applies the key as the Python node does (tests/test_cnode.py's
    ``test_c_live_loop_is_the_python_live_loop[3]`` compares the two loops with it): no
    refusal, so ``--impl auto`` keeps the C node."""
    sc = load_scenario("paper-sim")
    spec = parse_topic_spec({"camera": {"time_offset": 0.02}})
    assert c_node_refusal(sc, spec, managed=False) is None


def _loop_with_frame(lib: Any, sc: Any, shift: int, frame_tick: int) -> list[int]:
    """A live loop fed 12 encoder samples, then a frame stamped at ``frame_tick``: the
    exposure steps it has pending."""
    loop = LiveLoop(sc, lib, controller=False, exposure_shift=shift)
    T = round(lib.T * 1e9)
    z = np.zeros(2 * loop.n)
    for k in range(12):
        loop.encoders(EPOCH_NS + k * T, z, 5 * 10**9 + k * T)
    loop.frame(EPOCH_NS + frame_tick * T, np.array([300.0, 200.0]), 5 * 10**9 + 12 * T)
    return [f.exposure_step for f in loop._frames.pending]


def test_the_live_loop_shifts_the_exposure_by_the_key() -> None:
    """``amsfe node`` (Python) takes a frame stamped at tick 10 as exposed at 10 - shift,
    as the log reader does (logs/sensors.camera_frames)."""
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    lib = library_for(sc)
    assert _loop_with_frame(lib, sc, 0, 10) == [10]
    assert _loop_with_frame(lib, sc, 3, 10) == [7]
    # the spec's key in the node's ticks (what ros/node.py passes)
    spec = parse_topic_spec({"camera": {"time_offset": 3.2 * lib.T}})
    assert _loop_with_frame(lib, sc, spec.exposure_shift(lib.T), 10) == [7]


def test_calibrate_writes_the_key_into_the_users_topic_spec(tmp_path: Path) -> None:
    """The user's topic spec with the key added (its other keys kept), read back by the topic
    spec's own reader; without one, a spec with the key alone."""
    user = tmp_path / "mine.toml"
    user.write_text(
        '[topics]\nencoders = "/arm/joint_states"\n\n[camera]\ninfo = "/cam/info"\n'
        "time_offset = 0.5\n"
    )
    out = tmp_path / "topics.toml"
    out.write_text(calibrated_topic_spec(user, 0.0251234567, "the.bag"))
    spec = read_topic_spec(out)
    assert spec.camera_time_offset == 0.025123  # to 1 us
    assert spec.encoders == "/arm/joint_states" and spec.camera_info == "/cam/info"
    assert out.read_text().startswith("# ") and "the.bag" in out.read_text()
    out.write_text(calibrated_topic_spec(None, -0.004, "the.bag"))
    spec = read_topic_spec(out)
    assert spec.camera_time_offset == -0.004 and spec.encoders == TopicSpec().encoders


def _stamps(bag: Path, topic: str) -> list[int]:
    from rosbags.highlevel import AnyReader

    from amsfe_sym.logs.decode import typestore

    with AnyReader([bag], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    return [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs]


@pytest.mark.slow
def test_simulated_images_are_stamped_as_the_pixel_topic(tmp_path: Path) -> None:
    """``amsfe simulate --bag --images`` with ``[camera] stamp_offset``: each image carries
    the pixel topic's stamp, exposure + offset (the images were stamped at the exposure, so a
    calibration from them found no time offset)."""
    from amsfe_sym.apps.cli import main

    stamps = {}
    for name, extra in (("pixels", []), ("images", ["--images", "png"])):
        argv = ["simulate", "--controller", "amsfe", "--duration", "1", "--seed", "3"]
        argv += ["--out", str(tmp_path / name), "--bag", "--no-plots", "--no-progress"]
        assert main([*argv, "--set", "camera.stamp_offset=0.005", *extra]) == 0
    stamps["pixels"] = _stamps(tmp_path / "pixels" / "bag", "/camera/marker")
    stamps["images"] = _stamps(tmp_path / "images" / "bag", "/camera/image_raw/compressed")
    assert len(stamps["pixels"]) > 5 and stamps["images"] == stamps["pixels"]


def test_the_node_s_parameters_carry_the_key_and_override_it() -> None:
    """``spec_parameters`` (what ``amsfe node`` reads back from its ROS parameters) keeps the
    file's ``[camera] time_offset`` and takes ``-p camera.time_offset:=...`` over it."""
    from types import SimpleNamespace

    from amsfe_sym.ros.middleware import spec_parameters

    class FakeNode:
        def __init__(self, overrides: dict[str, Any]) -> None:
            self.overrides = overrides

        def declare_parameter(self, name: str, value: Any, descriptor: Any = None) -> Any:
            return SimpleNamespace(value=self.overrides.get(name, value))

        def get_name(self) -> str:
            return "amsfe_node"

    spec = parse_topic_spec({"camera": {"time_offset": 0.031}})
    got = spec_parameters(FakeNode({}), spec, ("joint1", "joint2"))
    assert got.camera_time_offset == 0.031
    got = spec_parameters(FakeNode({"camera.time_offset": 0.012}), spec, ("joint1", "joint2"))
    assert got.camera_time_offset == 0.012
    with pytest.raises(ConfigError, match="time_offset"):
        spec_parameters(FakeNode({"camera.time_offset": 5.0}), spec, ("joint1", "joint2"))
