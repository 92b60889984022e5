"""Issue 37 item 3: ``amsfe play`` of every container the log reader reads.

A ROS 1 ``.bag`` was published as its ROS 1 bytes (play exited 0, the node logged Fast CDR
exceptions and waited forever).  Here a simulated run's rosbag2 is written again as a ROS 1
bag (Noetic definitions: ``std_msgs/Header`` with its ``seq``) with rosbags' ROS 1 writer;
its payloads converted by :func:`amsfe_sym.ros.play.ros1_to_cdr` equal, message by message,
the CDR of the rosbag2.  Played over real DDS into ``amsfe node`` it gives the estimates of
``amsfe estimate`` on the same bag: tests/test_ros.py's ``test_play_into_node_is_estimate``
(its ``ros1`` case plays this bag into the Python node: one DDS run for both).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.ros.middleware import QUEUE_SECONDS, depth_for
from amsfe_sym.ros.play import ros1_to_cdr
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.topics import TopicSpec
from tests.test_ros import PLAY_S


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=PLAY_S)
    return sc, library_for(sc)


def _as_ros1(obj: Any, store: Any) -> Any:
    """A ROS 2 message object rebuilt with ``store``'s ROS 1 types (a Header's seq: 0)."""
    name = getattr(obj, "__msgtype__", None)
    if name is not None:
        cls = store.types[name]
        kw = {
            f: (_as_ros1(getattr(obj, f), store) if hasattr(obj, f) else 0)
            for f in cls.__dataclass_fields__
            if f != "__msgtype__"
        }
        return cls(**kw)
    if isinstance(obj, list):
        return [_as_ros1(x, store) for x in obj]
    return obj


def ros2_to_ros1_bag(src: Path, dst: Path) -> list[tuple[str, int, bytes]]:
    """Every message of the rosbag2 ``src`` written to the ROS 1 bag ``dst``; returns the
    source's (topic, log time, CDR) in order."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ros1, ros2 = get_typestore(Stores.ROS1_NOETIC), get_typestore(Stores.ROS2_HUMBLE)
    out = []
    with AnyReader([src], default_typestore=ros2) as reader, Writer(dst) as w:
        conns = {}
        for c, t, raw in reader.messages():
            if c.topic not in conns:
                conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=ros1)
            msg = _as_ros1(ros2.deserialize_cdr(raw, c.msgtype), ros1)
            w.write(conns[c.topic], t, ros1.serialize_ros1(msg, c.msgtype))
            out.append((c.topic, t, bytes(raw)))
    return out


def test_ros1_payloads_convert_to_the_recorded_cdr(paper: Any, tmp_path: Path) -> None:
    from amsfe_sym.logs.source import iter_messages, log_topics

    sc, lib = paper
    bag2 = write_run_bag(
        run(sc.with_overrides(duration=0.2), lib, runtime="compiled"), tmp_path / "b"
    )
    src = ros2_to_ros1_bag(bag2, tmp_path / "run.bag")
    topics = set(log_topics(tmp_path / "run.bag"))
    got = [
        (m.topic, m.log_time_ns, ros1_to_cdr(m.raw, m.msgtype))
        for m in iter_messages(tmp_path / "run.bag", topics)
    ]
    assert sorted(got) == sorted(src) and len(got) > 200


def test_the_queue_depth_rule() -> None:
    spec = TopicSpec()
    assert depth_for(1000.0, spec) == round(1000 * QUEUE_SECONDS) > spec.depth
    assert depth_for(8.0, spec) == spec.depth  # a camera: the spec's depth is more
    assert depth_for(1e9, spec) == 100_000 and depth_for(0.0, spec) == spec.depth


@pytest.mark.ros
@pytest.mark.slow
def test_play_at_the_recorded_pace_loses_no_sample(paper: Any, tmp_path: Path) -> None:
    """``amsfe play BAG`` into ``amsfe node`` with neither ``--ordered`` nor ``-p
    qos.depth:=5000`` (tests/test_ros.py passes both): the queues of both ends are sized by
    ``depth_for``, so on this loaded machine every encoder sample of the bag reaches the
    node, which estimates each one."""
    from tests.test_node_record import _bag
    from tests.test_ros import PATIENT_NODE, _finish, _ros_env, _start

    sc, lib = paper
    res = run(sc, lib, runtime="compiled")
    bag = write_run_bag(res, tmp_path / "bag")
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs = []
    try:
        procs.append(_start(env, "node", "paper-sim", "--duration", f"{PLAY_S:g}",
                            "--record", str(rec), *PATIENT_NODE))  # fmt: skip
        procs.append(_start(env, "play", str(bag), "--start-timeout", "60"))
    finally:
        results = _finish(procs, 120.0)
    for code, text in results:
        assert code == 0, text
    got = _bag(rec)
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    assert est.shape == (res.t.size, 2 * lib.n) and np.isfinite(est).all()
