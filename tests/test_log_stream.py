"""logs/stream.py's read_topics against the reference (``iter_messages``, then each payload
decoded by ``rosbags``): the same log times and columns, bit for bit, for a simulated log
rewritten as MCAP with zstd, lz4 and no compression, small chunks, unchunked, without message
indexes, with messages out of log-time order in the file, and as sqlite3; a damaged file is
refused with one line."""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import LogError
from amsfe_sym.logs import decode as dec
from amsfe_sym.logs.source import iter_messages
from amsfe_sym.logs.stream import read_topics
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run

TOPICS = {"/motor_encoders", "/motor_torque", "/camera/marker", "/amsfe/truth", "/amsfe/config"}
REFERENCE = {
    "sensor_msgs/msg/JointState": dec._reference_joint_states,
    "geometry_msgs/msg/PointStamped": dec._reference_points,
    "std_msgs/msg/Float64MultiArray": dec._reference_float64_arrays,
    "std_msgs/msg/String": dec._reference_strings,
}


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    """A 1 s paper-sim run written by ``amsfe simulate --bag``'s writer (rosbag2, MCAP)."""
    sc = load_scenario("paper-sim").with_overrides(controller="amsfe", duration=1.0, seed=2)
    res = run(sc, library_for(sc), runtime="compiled")
    return write_run_bag(res, tmp_path_factory.mktemp("stream") / "bag")


def _check(path: Path) -> None:
    got = read_topics(path, TOPICS)
    by: dict[str, tuple[str, list[bytes], list[int]]] = {}
    for m in iter_messages(path, TOPICS):
        entry = by.setdefault(m.topic, (m.msgtype, [], []))
        entry[1].append(m.raw)
        entry[2].append(m.log_time_ns)
    assert set(got) == set(by)
    for topic, (msgtype, raws, times) in by.items():
        g = got[topic]
        assert g.msgtype == msgtype and g.log_time_ns.tolist() == sorted(times)
        order = np.argsort(np.array(times), kind="stable")
        ref = REFERENCE[msgtype]([raws[i] for i in order])
        for f in dataclasses.fields(ref):
            x, y = getattr(ref, f.name), getattr(g.decoded, f.name)
            if isinstance(x, np.ndarray):
                assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
            else:
                assert x == y, (topic, f.name)


def _rewrite(src: Path, out: Path, shuffle: bool = False, **options: Any) -> Path:
    """The messages of ``src`` written again with mcap's own writer and ``options``."""
    from mcap.writer import Writer

    msgs = list(iter_messages(src, TOPICS | {"/joint_states", "/tf"}))
    if shuffle:  # the recorder's order is not log-time order (late frames written late)
        rng = np.random.default_rng(0)
        msgs = [msgs[i] for i in rng.permutation(len(msgs))]
    with out.open("wb") as fh:
        w = Writer(fh, **options)
        w.start()
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for m in msgs:
            if m.msgtype not in schemas:
                schemas[m.msgtype] = w.register_schema(m.msgtype, "ros2msg", b"")
            if m.topic not in channels:
                channels[m.topic] = w.register_channel(m.topic, "cdr", schemas[m.msgtype])
            w.add_message(channels[m.topic], m.log_time_ns, m.raw, m.log_time_ns)
        w.finish()
    return out


def test_the_simulated_bag_and_its_mcap_file(bag: Path) -> None:
    _check(bag)
    _check(next(bag.glob("*.mcap")))


def _variant(bag: Path, tmp_path: Path, options: dict[str, Any]) -> Path:
    """The bag's MCAP rewritten with the writer ``options`` (enum names as strings;
    ``shuffle``: messages out of log-time order)."""
    from mcap.writer import CompressionType, IndexType

    opts = dict(options)
    shuffle = bool(opts.pop("shuffle", False))
    if "compression" in opts:
        opts["compression"] = CompressionType[opts["compression"]]
    if "index_types" in opts:
        opts["index_types"] = IndexType[opts["index_types"]]
    return _rewrite(next(bag.glob("*.mcap")), tmp_path / "log.mcap", shuffle, **opts)


@pytest.mark.parametrize(
    "options",
    [
        {"compression": "ZSTD", "chunk_size": 4096},
        {"compression": "LZ4", "chunk_size": 20000},
        {"compression": "NONE"},
        {"use_chunking": False},
        {"index_types": "NONE", "chunk_size": 8192},
        {"compression": "ZSTD", "chunk_size": 3000, "shuffle": True},
    ],
    ids=["zstd-small", "lz4", "none", "unchunked", "no-index", "shuffled"],
)
def test_mcap_variants(bag: Path, tmp_path: Path, options: dict[str, Any]) -> None:
    _check(_variant(bag, tmp_path, options))


def test_sqlite3_goes_through_the_messages(bag: Path, tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from amsfe_sym.logs.source import typestore

    out = tmp_path / "sql"
    with Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns: dict[str, Any] = {}
        for m in iter_messages(bag, TOPICS):
            if m.topic not in conns:
                conns[m.topic] = w.add_connection(m.topic, m.msgtype, typestore=typestore())
            w.write(conns[m.topic], m.log_time_ns, m.raw)
    _check(out)


def test_a_damaged_file_is_refused_in_one_line(bag: Path, tmp_path: Path) -> None:
    data = next(bag.glob("*.mcap")).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])  # no summary: the message path, which refuses
    with pytest.raises(LogError) as exc:
        read_topics(cut, TOPICS)
    assert "\n" not in str(exc.value)
    broken = bytearray(data)
    chunk_at = data.index(b"\x06", 8)  # the first chunk's records: garbage in place
    broken[chunk_at + 60 : chunk_at + 400] = b"\xff" * 340
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(broken))
    with pytest.raises(LogError) as exc2:
        read_topics(bad, TOPICS)
    assert "\n" not in str(exc2.value)


def test_progress_reports_every_byte(bag: Path) -> None:
    calls: list[tuple[int, int]] = []
    read_topics(bag, TOPICS, progress=lambda done, total: calls.append((done, total)))
    size = next(bag.glob("*.mcap")).stat().st_size
    assert calls and calls[-1][0] == calls[-1][1] and 0 < calls[-1][1] <= size
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(calls))
    quiet = read_topics(bag, TOPICS, progress=False)
    assert quiet.keys() == read_topics(bag, TOPICS, progress=True).keys()


def test_a_type_without_decoder_keeps_its_payloads(tmp_path: Path) -> None:
    """A type with no decoder: no columns, its payloads in log-time order; no topic: absent."""
    from mcap.writer import Writer

    path = tmp_path / "odd.mcap"
    payloads = [(30, b"\x00\x01\x00\x00c"), (10, b"\x00\x01\x00\x00a"), (20, b"\x00\x01\x00\x00bb")]
    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        channel = w.register_channel(
            "/odd", "cdr", w.register_schema("foo_msgs/msg/Bar", "ros2msg", b"")
        )
        for t, raw in payloads:
            w.add_message(channel, t, raw, t)
        w.finish()
    odd = read_topics(path, {"/odd"})["/odd"]
    assert odd.decoded is None and odd.msgtype == "foo_msgs/msg/Bar"
    assert (
        odd.raw
        == [raw for _, raw in sorted(payloads)]
        == [m.raw for m in iter_messages(path, {"/odd"})]
    )
    assert odd.log_time_ns.tolist() == [10, 20, 30]
    assert read_topics(path, {"/no/such/topic"}) == {}


def _ros1_bag(path: Path, compression: str, threshold: int) -> Path:
    """A ROS 1 bag as a robot's recorder writes it: JointStates with a seq in the header,
    9 names (7 joints + 2 fingers), a camera topic, a String; written out of time order."""
    from rosbags.rosbag1 import Writer

    ts = dec.typestore("ros1")
    T = ts.types
    rng = np.random.default_rng(1)
    names = [f"panda_joint{i}" for i in range(1, 8)] + ["finger1", "finger2"]

    def header(seq: int, t: int) -> Any:
        stamp = T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id="")

    events = []
    for k in range(700):
        t = 1_700_000_000 * 10**9 + k * 33_000_000
        js = T["sensor_msgs/msg/JointState"](
            header=header(k, t), name=names, position=rng.normal(size=9),
            velocity=rng.normal(size=9), effort=rng.normal(size=9),
        )  # fmt: skip
        events.append(("/joint_states", "sensor_msgs/msg/JointState", t + 150_000, js))
        if k % 3 == 0:
            p = T["geometry_msgs/msg/PointStamped"](
                header=header(k, t), point=T["geometry_msgs/msg/Point"](x=k, y=-k, z=0.0)
            )
            events.append(("/camera/marker", "geometry_msgs/msg/PointStamped", t + 9_000_000, p))
    events.append(("/amsfe/config", "std_msgs/msg/String", 5, T["std_msgs/msg/String"](data="{}")))
    order = rng.permutation(len(events))
    w = Writer(path)
    if compression != "none":
        w.set_compression(Writer.CompressionFormat[compression.upper()])
    w.chunk_threshold = threshold
    with w:
        conns: dict[str, Any] = {}
        for i in order:
            topic, msgtype, t, msg = events[i]
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conns[topic], t, bytes(ts.serialize_ros1(msg, msgtype)))
    return path


@pytest.mark.parametrize(
    ("compression", "threshold"), [("none", 1 << 20), ("bz2", 20000), ("lz4", 5000)]
)
def test_ros1_bags(tmp_path: Path, compression: str, threshold: int) -> None:
    from rosbags.rosbag1 import Reader

    bag = _ros1_bag(tmp_path / "arm.bag", compression, threshold)
    got = read_topics(bag, TOPICS | {"/joint_states"})
    by: dict[str, tuple[str, list[bytes], list[int]]] = {}
    with Reader(bag) as r:
        for c, t, raw in r.messages():
            entry = by.setdefault(c.topic, (c.msgtype, [], []))
            entry[1].append(bytes(raw))
            entry[2].append(t)
    assert set(got) == set(by)
    for topic, (msgtype, raws, times) in by.items():
        g = got[topic]
        assert g.encoding == "ros1" and g.msgtype == msgtype
        assert g.log_time_ns.tolist() == times
        _same_columns(REFERENCE[msgtype](raws, "ros1"), g.decoded)
    js = got["/joint_states"].decoded
    assert js.names == [(*(f"panda_joint{i}" for i in range(1, 8)), "finger1", "finger2")]


def _same_columns(ref: Any, got: Any) -> None:
    for f in dataclasses.fields(ref):
        x, y = getattr(ref, f.name), getattr(got, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
        else:
            assert x == y, f.name


def test_a_damaged_ros1_bag_is_refused_in_one_line(tmp_path: Path) -> None:
    bag = _ros1_bag(tmp_path / "arm.bag", "none", 1 << 20)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[:-2000])  # the index at the end is gone
    with pytest.raises(LogError) as exc:
        read_topics(cut, TOPICS)
    assert "\n" not in str(exc.value)


def test_damaged_bytes_give_columns_or_one_line(bag: Path, tmp_path: Path) -> None:
    """Random bytes overwritten anywhere in the MCAP: read_topics returns columns or raises
    LogError (one line), never another exception."""
    data = next(bag.glob("*.mcap")).read_bytes()
    rng = np.random.default_rng(7)
    for i in range(25):
        broken = bytearray(data)
        at = int(rng.integers(0, len(data) - 16))
        broken[at : at + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
        path = tmp_path / f"d{i}.mcap"
        path.write_bytes(bytes(broken))
        try:
            read_topics(path, TOPICS, progress=False)
        except LogError as exc:
            assert "\n" not in str(exc)


@pytest.mark.parametrize("compression", ["none", "bz2"])
def test_damaged_ros1_bytes_give_columns_or_one_line(tmp_path: Path, compression: str) -> None:
    data = _ros1_bag(tmp_path / "arm.bag", compression, 20000).read_bytes()
    rng = np.random.default_rng(5)
    for i in range(30):
        broken = bytearray(data)
        low = 0 if i % 2 else max(0, len(data) - 4000)  # half of them in the index at the end
        at = int(rng.integers(low, len(data) - 8))
        broken[at : at + 8] = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
        path = tmp_path / f"d{i}.bag"
        path.write_bytes(bytes(broken))
        try:
            read_topics(path, TOPICS | {"/joint_states"}, progress=False)
        except LogError as exc:
            assert "\n" not in str(exc)


def _first_by_reference(messages: Any, count: int) -> dict[str, tuple[list[int], list[bytes]]]:
    """The first ``count`` (log time, payload) of each topic of a message stream."""
    out: dict[str, tuple[list[int], list[bytes]]] = {}
    for topic, t, raw in messages:
        times, raws = out.setdefault(topic, ([], []))
        if len(times) < count:
            times.append(t)
            raws.append(raw)
    return out


@pytest.mark.parametrize("count", [1, 3, 400])
def test_first_payloads_of_a_folder_equal_rosbags(bag: Path, count: int) -> None:
    """A rosbag2 folder of one MCAP: its topics and first payloads, read with mcap and cut
    with numpy, are rosbags' AnyReader's (the reader the folder went through before)."""
    from amsfe_sym.logs import source
    from amsfe_sym.logs.firsts import first_payloads

    assert source.log_topics(bag) == source._rosbags_topics(bag, "rosbag2")
    ref = _first_by_reference(source._rosbags_payloads(bag, TOPICS), count)
    got = first_payloads(bag, TOPICS, count=count)
    assert set(got) == TOPICS and set(ref) == TOPICS
    for topic, (times, raws) in ref.items():
        assert got[topic].log_time_ns.tolist() == times and got[topic].raws == raws, topic


@pytest.mark.parametrize("count", [1, 5, 250])
@pytest.mark.parametrize(
    "options",
    [
        {"compression": "ZSTD", "chunk_size": 4096},
        {"compression": "LZ4", "chunk_size": 20000},
        {"use_chunking": False},
        {"index_types": "NONE", "chunk_size": 8192},
        {"compression": "ZSTD", "chunk_size": 3000, "shuffle": True},
    ],
    ids=["zstd-small", "lz4", "unchunked", "no-index", "shuffled"],
)
def test_first_messages_equal_mcaps_reader(
    bag: Path, tmp_path: Path, options: dict[str, Any], count: int
) -> None:
    """first_messages (the fewest chunks, cut with numpy) against mcap's own reader in
    log-time order, on small chunks, out-of-order files; None without indexes."""
    from amsfe_sym.logs import source
    from amsfe_sym.logs.firsts import first_messages, first_payloads

    path = _variant(bag, tmp_path, options)
    ref = _first_by_reference(source._mcap_payloads(path, TOPICS), count)
    got = first_messages(path, TOPICS, count)
    if "index_types" in options or "use_chunking" in options:
        assert got is None  # the caller reads message by message
    else:
        assert got == ref
    via = first_payloads(path, TOPICS, count=count)
    slow = source.first_payloads(path, TOPICS, count=count)
    assert {t: (d.log_time_ns.tolist(), d.raws) for t, d in via.items()} == ref
    assert {t: (d.log_time_ns.tolist(), d.raws) for t, d in slow.items()} == ref
