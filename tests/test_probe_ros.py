"""Issue 37 item 6: ROS parameters as strict as the spec, and a node that says what it waits
for.  ``-p qos.depth:=abc`` and ``-p timing.grid_tolerance:=1`` were tracebacks, ``-p
joints.names:=['a']`` for a 2-joint robot was accepted, a mistyped ``-p topic.encoders`` was
ignored and the node waited forever without a word.

In process, each case declares the parameters on a real rclpy node (its own context and
domain); over DDS (marker ``ros``) ``amsfe node`` is started as a user would, with the
bounds of tests/test_ros.py (own domain and topic prefix, every process killed in a
``finally``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.topics import TopicSpec

JOINTS = ("joint1", "joint2")
#: rclpy in this process imports lark (through rosidl), which imports the deprecated
#: sre_parse and sre_constants
pytestmark = pytest.mark.filterwarnings("ignore:module 'sre_.*' is deprecated")


def _spec_from(args: list[str], monkeypatch: pytest.MonkeyPatch) -> TopicSpec:
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.ros.middleware import check_parameters, spec_parameters, start, stop

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = start(args, domain_id=1 + (os.getpid() * 13) % 101)
    import rclpy

    node = rclpy.create_node("amsfe_probe", context=ctx)
    try:
        spec = spec_parameters(node, TopicSpec(), JOINTS)
        check_parameters(node)
        return spec
    finally:
        stop(ctx, node)


@pytest.mark.ros
@pytest.mark.parametrize(
    ("param", "words"),
    [
        ("qos.depth:=abc", ["qos.depth", "an integer >= 1", "'abc'"]),
        ("timing.grid_tolerance:=1", ["grid_tolerance", "(0, 0.5)", "1.0"]),
        ("timing.grid_tolerance:=abc", ["grid_tolerance", "a number in (0, 0.5)", "'abc'"]),
        ("joints.names:=['a']", ["joints.names", "2 names", "['a']"]),
        ("topic.encoders:=/x", ["['topic.encoders']", "topics.encoders"]),
        ("qos.depth:=2000000000", ["[qos] depth", "[1, 100000]"]),
    ],
)
def test_a_bad_parameter_is_one_line(
    param: str, words: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(ConfigError) as info:
        _spec_from(["-p", param], monkeypatch)
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


@pytest.mark.ros
def test_good_parameters_are_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    args = ["-p", "timing.grid_tolerance:=0.3", "-p", "qos.depth:=500"]
    args += ["-p", "joints.names:=['b','a']", "-p", "topics.encoders:=/arm/joint_states"]
    spec = _spec_from(args, monkeypatch)
    assert spec.grid_tolerance == 0.3 and spec.depth == 500
    assert spec.joint_names == ("b", "a") and spec.encoders == "/arm/joint_states"


@pytest.mark.ros
@pytest.mark.slow
def test_a_waiting_node_names_the_type_mismatch(tmp_path: Path) -> None:
    """``amsfe node`` whose encoder topic has a publisher of another type (a String): within
    its first report (10 s) it names the topic, its own type and the publisher's.  Each node
    implementation, side by side on the one topic (one wait for both)."""
    from amsfe_sym.apps.bench.ros import node_impls
    from tests.test_ros import _PREFIX, _finish, _impl, _ros_env, _start

    env = _ros_env(tmp_path)
    topic = env[_PREFIX] + TopicSpec().encoders
    procs: list[Any] = []
    try:
        nodes = [_start(env, "node", "paper-sim", "--duration", "1", *_impl(impl))
                 for impl in node_impls()]  # fmt: skip
        procs += nodes
        import subprocess
        import sys

        code = (
            "import sys, time, rclpy\n"
            "from std_msgs.msg import String\n"
            "rclpy.init()\n"
            "n = rclpy.create_node('wrong_type')\n"
            "p = n.create_publisher(String, sys.argv[1], 10)\n"
            "end = time.monotonic() + 60\n"
            "while time.monotonic() < end:\n"
            "    p.publish(String(data='x')); time.sleep(0.1)\n"
        )
        wrong = subprocess.Popen(
            [sys.executable, "-c", code, topic], env=env, start_new_session=True
        )
        try:
            for node in nodes:
                node.wait_for("a type mismatch", 90)
        finally:
            wrong.kill()
            wrong.wait()
        for node in nodes:
            line = next(ln for ln in node.lines if "a type mismatch" in ln)
            assert f"nothing on {topic} (sensor_msgs/msg/JointState)" in line, line
            assert "['std_msgs/msg/String']" in line, line
            node.kill(2)
    finally:
        _finish(procs, 30.0)
