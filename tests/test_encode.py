"""The bulk JointState encoder of logs/encode.py against ``rosbags``' ``serialize_cdr``,
message by message, byte for byte: messages made by hypothesis (random joint names incl.
non-ASCII and empty ones, every field length incl. empty fields, NaN and inf values with
random NaN payload bits, frame_ids of every length mod 8, stamps anywhere in int32 seconds
incl. negative nanoseconds, which both split as floor / rest), and stamps whose seconds
leave int32, which both refuse alike.  The reference here builds each message from rosbags'
own types, independently of the module's fallback."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amsfe_sym.logs import encode as enc
from amsfe_sym.logs.source import typestore

FAST = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])

names_st = st.lists(st.text(st.characters(exclude_categories=("Cs",)), max_size=9), max_size=5)
frame_st = st.integers(0, 17).map(lambda n: "f" * n)  # every length mod 8
value_st = st.floats(allow_nan=True, allow_infinity=True, width=64)
NS = 1_000_000_000
stamp_st = st.integers(-(2**31) * NS, (2**31 - 1) * NS + NS - 1)  # int32 seconds after the split


def _rosbags(stamp_ns: int, names: list[str], fields: list[np.ndarray], frame: str) -> bytes:
    """One message as the bag writer built it: rosbags' types and serialize_cdr."""
    ts = typestore()
    t = ts.types
    msg = t["sensor_msgs/msg/JointState"](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=stamp_ns // NS, nanosec=stamp_ns % NS),
            frame_id=frame,
        ),
        name=names,
        position=fields[0],
        velocity=fields[1],
        effort=fields[2],
    )
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


@st.composite
def messages(draw: Any) -> tuple[list[int], list[str], list[np.ndarray | None], str]:
    count = draw(st.integers(1, 6))
    names = draw(names_st)
    stamps = draw(st.lists(stamp_st, min_size=count, max_size=count))
    fields: list[np.ndarray | None] = []
    for _ in range(3):
        m = draw(st.integers(0, 4))
        if m == 0 and draw(st.booleans()):
            fields.append(None)
            continue
        values = draw(st.lists(value_st, min_size=count * m, max_size=count * m))
        a = np.array(values, dtype=np.float64).reshape(count, m)
        if a.size and draw(st.booleans()):  # NaN with payload bits: kept as they are
            bits = a.view(np.uint64)
            bits[0, 0] = np.uint64(0x7FF0000000000000) | np.uint64(draw(st.integers(1, 2**51)))
        fields.append(a)
    return stamps, names, fields, draw(frame_st)


@FAST
@given(messages())
def test_bulk_equals_rosbags(case: tuple[list[int], list[str], list[Any], str]) -> None:
    stamps, names, fields, frame = case
    count = len(stamps)
    got = enc.encode_joint_states(np.array(stamps, dtype=np.int64), names, *fields, frame=frame)
    rows = [np.zeros((count, 0)) if f is None else f for f in fields]
    want = [_rosbags(s, names, [r[k] for r in rows], frame) for k, s in enumerate(stamps)]
    assert got == want
    assert enc._reference_joint_states(stamps, names, rows, frame) == want


def test_bulk_path_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    """The messages above go through the bulk path, not the fallback (which would pass the
    comparison trivially)."""

    def refused(*_: Any, **__: Any) -> Any:
        raise AssertionError("fell back to rosbags")

    monkeypatch.setattr(enc, "_reference_joint_states", refused)
    rng = np.random.default_rng(3)
    stamps = rng.integers(-(2**31) * NS, 2**31 * NS - 1, 50)
    p, v = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    got = enc.encode_joint_states(stamps, ["a", "bé", ""], p, v, frame="base")
    want = [
        _rosbags(int(s), ["a", "bé", ""], [p[k], v[k], np.zeros(0)], "base")
        for k, s in enumerate(stamps)
    ]
    assert got == want


@pytest.mark.parametrize("stamp", [2**31 * NS, -(2**31) * NS - 1])
def test_stamp_outside_int32_refused_alike(stamp: int) -> None:
    """Seconds outside int32: the fallback gives rosbags' own error, as before."""
    p = np.zeros((2, 1))
    with pytest.raises(Exception) as ref:
        _rosbags(stamp, ["j"], [p[0], p[0], np.zeros(0)], "")
    with pytest.raises(type(ref.value)):
        enc.encode_joint_states([0, stamp], ["j"], p, p)


def test_no_messages() -> None:
    assert enc.encode_joint_states([], ["j"], np.zeros((0, 1))) == []


def test_estimate_bag_equals_rosbags_one_by_one(tmp_path) -> None:
    """write_estimate_bag (bulk) writes the payloads and log times of the message-by-message
    writer it replaced: joint_state(...) through serialize_cdr, estimate and std per tick."""
    from rosbags.rosbag2 import Reader

    from amsfe_sym.logs.write import write_estimate_bag

    rng = np.random.default_rng(5)
    K, names, t0 = 40, ["j1", "j2"], 12.345678901
    t = np.arange(K) * 1e-3
    x_hat = rng.normal(size=(K, 5))
    P = rng.normal(size=(K, 5))  # negative variances: a std of 0, as before
    P[3, 1] = np.nan
    write_estimate_bag(tmp_path / "est", t0, t, names, x_hat, P)
    want = []
    for k, tk in enumerate(t):
        tt = t0 + float(tk)
        s = np.sqrt(np.maximum(P[k], 0.0))
        for topic, v in (("/amsfe/estimate", x_hat[k]), ("/amsfe/estimate_std", s)):
            ns = round(tt * 1e9)
            want.append((topic, ns, _rosbags(ns, names, [v[:2], v[2:4], np.zeros(0)], "")))
    with Reader(tmp_path / "est") as r:
        got = [(c.topic, tm, bytes(raw)) for c, tm, raw in r.messages()]
    assert got == want
