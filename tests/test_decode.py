"""The bulk decoders of logs/decode.py against the reference (``rosbags``' deserializers,
message by message), bit for bit: messages made by hypothesis (random joint names, lengths,
empty fields, NaN and inf values, frame_ids of every length mod 8, several layouts in one
topic), serialized by ``rosbags`` as CDR (little- and big-endian) and as ROS 1 (a uint32 seq
in the header, no alignment), plus damaged payloads, which both refuse with the same line."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amsfe_sym.errors import LogError
from amsfe_sym.logs import decode as dec

ENCODINGS = ("cdr", "ros1")
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

names_st = st.lists(st.text(st.characters(exclude_categories=("Cs",)), max_size=9), max_size=5)
value_st = st.floats(allow_nan=True, allow_infinity=True, width=64)
frame_id_st = st.integers(0, 17).map(lambda n: "f" * n)  # every length mod 8
stamp_st = st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1))


def _header(ts: Any, stamp: tuple[int, int], frame_id: str, encoding: str, seq: int = 7) -> Any:
    t = ts.types["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1])
    if encoding == "ros1":
        return ts.types["std_msgs/msg/Header"](seq=seq, stamp=t, frame_id=frame_id)
    return ts.types["std_msgs/msg/Header"](stamp=t, frame_id=frame_id)


def _serialize(ts: Any, msg: Any, encoding: str, big: bool = False) -> bytes:
    if encoding == "ros1":
        return bytes(ts.serialize_ros1(msg, msg.__msgtype__))
    return bytes(ts.serialize_cdr(msg, msg.__msgtype__, little_endian=not big))


def _same(a: Any, b: Any) -> None:
    """Equal dataclasses, arrays compared by dtype, shape and bytes (NaN payloads too)."""
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert x.tobytes() == y.tobytes(), f.name
        else:
            assert x == y, f.name


def _bulk(name: str, *args: Any) -> Any:
    """``decode_<name>(*args)`` with its reference replaced by a failure: the bulk path only."""
    ref = getattr(dec, f"_reference_{name}")

    def refused(*_: Any) -> Any:
        raise AssertionError(f"decode_{name} fell back to the reference")

    setattr(dec, f"_reference_{name}", refused)
    try:
        return getattr(dec, f"decode_{name}")(*args)
    finally:
        setattr(dec, f"_reference_{name}", ref)


@st.composite
def joint_states(draw: Any, encoding: str) -> list[bytes]:
    """A topic: one to three layouts, each repeated with fresh stamps and values."""
    ts = dec.typestore(encoding)
    out = []
    for _ in range(draw(st.integers(1, 3))):
        names = draw(names_st)
        frame_id = draw(frame_id_st)
        sizes = [draw(st.sampled_from([0, len(names), len(names) + 1])) for _ in range(3)]
        for _ in range(draw(st.integers(1, 4))):
            fields = [np.array(draw(st.lists(value_st, min_size=s, max_size=s))) for s in sizes]
            msg = ts.types["sensor_msgs/msg/JointState"](
                header=_header(ts, draw(stamp_st), frame_id, encoding, draw(st.integers(0, 99))),
                name=names,
                position=fields[0],
                velocity=fields[1],
                effort=fields[2],
            )
            out.append(_serialize(ts, msg, encoding))
    return draw(st.permutations(out))


@pytest.mark.parametrize("encoding", ENCODINGS)
@FAST
@given(data=st.data())
def test_joint_states_equal_the_reference(encoding: str, data: Any) -> None:
    raws = data.draw(joint_states(encoding))
    _same(_bulk("joint_states", raws, encoding), dec._reference_joint_states(raws, encoding))


@pytest.mark.parametrize("encoding", ENCODINGS)
@FAST
@given(
    rows=st.lists(
        st.tuples(stamp_st, frame_id_st, st.lists(value_st, min_size=3, max_size=3)),
        max_size=6,
    )
)
def test_points_equal_the_reference(encoding: str, rows: Any) -> None:
    ts = dec.typestore(encoding)
    raws = []
    for stamp, frame_id, v in rows:
        point = ts.types["geometry_msgs/msg/Point"](x=v[0], y=v[1], z=v[2])
        msg = ts.types["geometry_msgs/msg/PointStamped"](
            header=_header(ts, stamp, frame_id, encoding), point=point
        )
        raws.append(_serialize(ts, msg, encoding))
    _same(_bulk("points", raws, encoding), dec._reference_points(raws, encoding))


@pytest.mark.parametrize("encoding", ENCODINGS)
@FAST
@given(
    rows=st.lists(
        st.tuples(
            st.lists(st.tuples(frame_id_st, st.integers(0, 9)), max_size=2),
            st.lists(value_st, max_size=5),
        ),
        max_size=6,
    )
)
def test_float64_arrays_and_strings_equal_the_reference(encoding: str, rows: Any) -> None:
    ts = dec.typestore(encoding)
    raws, texts = [], []
    for dims, values in rows:
        layout = ts.types["std_msgs/msg/MultiArrayLayout"](
            dim=[
                ts.types["std_msgs/msg/MultiArrayDimension"](label=lab, size=n, stride=2 * n)
                for lab, n in dims
            ],
            data_offset=len(dims),
        )
        msg = ts.types["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.array(values))
        raws.append(_serialize(ts, msg, encoding))
        text = "".join(lab for lab, _ in dims) + "é\x00" * len(values)
        texts.append(_serialize(ts, ts.types["std_msgs/msg/String"](data=text), encoding))
    _same(_bulk("float64_arrays", raws, encoding), dec._reference_float64_arrays(raws, encoding))
    _same(_bulk("strings", texts, encoding), dec._reference_strings(texts, encoding))


def _js(encoding: str, big: bool = False, frame_id: str = "base", k: int = 0) -> bytes:
    ts = dec.typestore(encoding)
    msg = ts.types["sensor_msgs/msg/JointState"](
        header=_header(ts, (k, 5 * k), frame_id, encoding),
        name=["j1", "j2"],
        position=np.array([0.1 * k, math.nan]),
        velocity=np.array([]),
        effort=np.array([1.0, -math.inf]),
    )
    return _serialize(ts, msg, encoding, big)


def test_unusual_payloads_go_to_the_reference() -> None:
    """Big-endian CDR, more layouts than the bulk path keeps, a non-UTF-8 name: the same."""
    raws = [_js("cdr", k=k) for k in range(5)] + [_js("cdr", big=True, k=9)]
    _same(dec.decode_joint_states(raws), dec._reference_joint_states(raws))
    many = [_js("cdr", frame_id="x" * (k % 40), k=k) for k in range(80)]  # 40 layouts
    _same(dec.decode_joint_states(many), dec._reference_joint_states(many))
    ros1 = [_js("ros1", k=k) for k in range(4)]
    _same(dec.decode_joint_states(ros1, "ros1"), dec._reference_joint_states(ros1, "ros1"))
    bad = bytearray(_js("cdr", k=1))
    bad[bad.index(b"j1")] = 0xFF  # not UTF-8: the reference refuses it
    with pytest.raises(LogError) as ref:
        dec._reference_joint_states([_js("cdr"), bytes(bad)], where="topic /j")
    with pytest.raises(LogError) as bulk:
        dec.decode_joint_states([_js("cdr"), bytes(bad)], where="topic /j")
    assert str(bulk.value) == str(ref.value)


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("cut", [1, 3, 9, 30])
def test_truncated_or_padded_payloads_are_refused_as_the_reference_does(
    encoding: str, cut: int
) -> None:
    good = _js(encoding, k=2)
    for broken in (good[:-cut], good + b"\x00" * cut):
        raws = [good, broken, good]
        try:
            expected = dec._reference_joint_states(raws, encoding, "topic /j")
        except LogError as exc:
            with pytest.raises(LogError) as got:
                dec.decode_joint_states(raws, encoding, "topic /j")
            assert str(got.value) == str(exc)
        else:  # CDR accepts up to 3 trailing bytes
            _same(dec.decode_joint_states(raws, encoding, "topic /j"), expected)


def test_ros1_payloads_carry_the_seq() -> None:
    """A ROS 1 JointState: seq, stamp, frame_id with no NUL and no alignment."""
    raw = _js("ros1", frame_id="ab", k=3)
    assert raw[:4] == (7).to_bytes(4, "little")  # seq
    assert raw[4:8] == (3).to_bytes(4, "little") and raw[12:18] == b"\x02\x00\x00\x00ab"
    js = _bulk("joint_states", [raw], "ros1")
    assert js.stamp_ns.tolist() == [3 * 10**9 + 15] and js.names == [("j1", "j2")]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_nan_payload_bits_are_kept(encoding: str) -> None:
    """A quiet NaN with a payload and a signalling NaN come out with their bits."""
    raw = bytearray(_js(encoding, k=4))
    nan_at = raw.index(np.float64(np.nan).tobytes())  # position[1]
    raws = []
    for bits in (0x7FF8000000000001, 0x7FF0000000000001, 0xFFF8000000000000):
        raw[nan_at : nan_at + 8] = bits.to_bytes(8, "little")
        raws.append(bytes(raw))
    got = _bulk("joint_states", raws, encoding)
    _same(got, dec._reference_joint_states(raws, encoding))
    assert got.position[0, 1].tobytes() == (0x7FF8000000000001).to_bytes(8, "little")
