"""The C arm (``amsfe sim-node --impl c``, ``ros/c/amsfe_arm*.c``; docs/live-load.md, "The C
arm").

Over real DDS (marker ``ros``; each test on its own domain and topics, every process bounded,
tests/test_ros.py's harness): in lockstep the C arm and the C node reproduce ``amsfe
simulate`` (the compiled loop) bit for bit, and the C arm sends the Python arm's messages
(the same samples, frames, truth and torques, stamped the same); free running at 1 kHz
beside two CPU hogs the C node on the C arm tracks as in process or holds saying it is
behind.  Outcomes, never times.  Without DDS: what the arm refuses is one line.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from tests.conftest import LOCKSTEP_S
from tests.test_live_load import free_running_under_load
from tests.test_node_record import _bag
from tests.test_ros import PATIENT_NODE, SRC, _finish, _ros_env, _start

#: A free-running run repeated for how often it holds: CI runs it once (docs/how-to/tests.md).
REPEAT = pytest.mark.nightly("a repeat of the free-running run under load CI runs once")


def _stamps(msgs: list[Any]) -> np.ndarray:
    return np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs])


@pytest.mark.ros
@pytest.mark.slow
def test_c_arm_lockstep_is_simulate(lockstep_runs: Any) -> None:
    """The C arm and the C node in lockstep: the truth the arm sent, the samples, the frames,
    the node's estimates and commands (its record, every tick) equal ``amsfe simulate``'s
    compiled loop of the same seed bit for bit.  (The C arm is ``sim-node``'s default; the
    run, 1 s, is shared with test_ros.py and test_cnode.py: tests/conftest.py's
    ``lockstep_runs``.)"""
    sc = load_scenario("paper-sim").with_overrides(duration=LOCKSTEP_S)
    lib = library_for(sc)
    run_ = lockstep_runs.get("paper-sim", "c")
    got = {**run_.topics, "_arm": run_.arm_text}
    ticks = f"{round(LOCKSTEP_S / lib.T) + 1} ticks"
    assert "(c arm)" in got["_arm"] and ticks in got["_arm"], got["_arm"]
    ref = run(sc, lib, runtime="compiled")
    n = lib.n
    truth = np.array([m.data for m in got["/amsfe/truth"]])
    np.testing.assert_array_equal(truth, ref.x_true)
    z = np.array([np.r_[m.position, m.velocity] for m in got["/motor_encoders"]])
    np.testing.assert_array_equal(z, ref.z_enc)
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    np.testing.assert_array_equal(est, ref.x_hat[:, : 2 * n])
    cmd = np.array([m.data for m in got["/effort_controller/commands"]])
    np.testing.assert_array_equal(cmd[:-1], ref.u)  # the last: the node's hold
    applied = np.array([m.effort for m in got["/motor_torque"]])
    np.testing.assert_array_equal(applied, ref.u[: applied.shape[0]])
    frames = got["/camera/marker"]
    assert len(frames) == ref.counters["frames_delivered"] > 0
    diag = json.loads(got["/amsfe/diagnostics"][-1].data)
    assert diag["frames_fused"] == ref.counters["frames_applied"] > 0


@pytest.mark.ros
@pytest.mark.slow
def test_c_arm_sends_the_python_arms_messages(lockstep_runs: Any) -> None:
    """The same lockstep run with the C arm and with the Python arm (the readable
    reference): the node received the same encoder samples, frames (pixels and exposure
    stamps), truth and applied torques, stamped the same, and answered the same commands.
    (1 s runs, the C arm's shared: tests/conftest.py's ``lockstep_runs``.)"""
    runs = lockstep_runs.get("paper-sim", "c"), lockstep_runs.get("paper-sim", "c", "python")
    c, py = ({**r.topics, "_arm": r.arm_text} for r in runs)
    assert "(c arm)" in c["_arm"] and "(python arm)" in py["_arm"]
    for topic in ("/motor_encoders", "/camera/marker", "/motor_torque", "/joint_states"):
        assert c[topic] and len(c[topic]) == len(py[topic]), topic
        np.testing.assert_array_equal(_stamps(c[topic]), _stamps(py[topic]))
    for topic in ("/motor_encoders", "/motor_torque"):
        for field in ("position", "velocity", "effort"):
            a = np.array([getattr(m, field) for m in c[topic]])
            b = np.array([getattr(m, field) for m in py[topic]])
            np.testing.assert_array_equal(a, b)
        assert all(m.name == ["joint1", "joint2"] for m in c[topic])
    a = np.array([[m.point.x, m.point.y, m.point.z] for m in c["/camera/marker"]])
    b = np.array([[m.point.x, m.point.y, m.point.z] for m in py["/camera/marker"]])
    np.testing.assert_array_equal(a, b)
    assert {m.header.frame_id for m in c["/camera/marker"]} == {"camera"}
    for topic in ("/amsfe/truth", "/effort_controller/commands"):
        np.testing.assert_array_equal(
            np.array([m.data for m in c[topic]]), np.array([m.data for m in py[topic]])
        )


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("repeat", [1, *(pytest.param(r, marks=REPEAT) for r in (2, 3))])
def test_free_running_c_arm_under_load_tracks_or_holds_for_being_behind(
    tmp_path: Path, repeat: int
) -> None:
    """Two CPU hogs (:class:`~amsfe_sym.core.cpu_load.CpuHogs`) beside the C arm and the C
    node, free running at 1 kHz for 2 s: the node tracks as in process (exit 0, no hold; the
    link tracking RMSE over the run's window at most twice the in-process one of the same
    seed plus a margin of 0.05 rad, for the latency of one period a free-running command
    has), or holds (exit 3) with a reason saying it is behind; never an arm reason
    (``innovation``: the torque the arm applied is the one the node uses), never an encoder
    stall (the arm's clock never stopped)."""
    free_running_under_load(tmp_path, ["--impl", "c"], ["--impl", "c"])


def _sim_node(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "amsfe_sym", "sim-node", "paper-sim", *args],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip


@pytest.mark.ros
def test_c_arm_without_a_node_is_one_line(tmp_path: Path) -> None:
    """No node on the domain: the C arm gives up after --start-timeout in one line (the
    Python arm's), exit 2; ``--impl c --images`` is refused in one line before it starts."""
    env = _ros_env(tmp_path)
    env["PYTHONPATH"] = str(SRC)
    out = _sim_node("--impl", "c", "--duration", "0.1", "--start-timeout", "0.5", env=env)
    errors = [x for x in out.stderr.splitlines() if x.startswith("error:")]
    assert out.returncode == 2 and len(errors) == 1, out.stdout + out.stderr
    assert "a subscriber of /motor_encoders" in errors[0] and "Fix:" in errors[0]
    out = _sim_node("--impl", "c", "--images", "--duration", "0.1", env=env)
    errors = [x for x in out.stderr.splitlines() if x.startswith("error:")]
    assert out.returncode == 2 and len(errors) == 1 and "--images" in errors[0], out.stderr


#: A lockstep arm in Python that applies half of each command (so the torque it applied is
#: not the node's command; the node's actuation watchdog, which would hold on it, is off)
#: and publishes the torque of tick k-1 before sample k (argv[1] "before") or right after it
#: ("after").  No camera: the encoders and the effort only.
_HALF_ARM = """
import os, sys, time
import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from amsfe_sym.codegen import library_for
from amsfe_sym.ros import messages as m
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.scenario import load_scenario

order = sys.argv[1]
try:  # the two publishes back to back, as the C arm's (when permitted)
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(55))
except (AttributeError, PermissionError, OSError):
    pass
sc = load_scenario("paper-sim").with_overrides(duration=float(sys.argv[2]))
lib = library_for(sc)
rclpy.init(args=["half_arm", "--ros-args", *sys.argv[3:]])
node = rclpy.create_node("amsfe_sim")
qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
enc = node.create_publisher(m.JointState, "/motor_encoders", qos)
eff = node.create_publisher(m.JointState, "/motor_torque", qos)
cmds = []
node.create_subscription(m.Float64MultiArray, "/effort_controller/commands",
                         lambda msg: cmds.append(m.values(msg.data)), qos)
end = time.monotonic() + 60
while enc.get_subscription_count() < 1 or eff.get_subscription_count() < 1:
    rclpy.spin_once(node, timeout_sec=0.05)
    assert time.monotonic() < end, "no node"
arm, T_ns, names = SimArm(sc, lib), round(lib.T * 1e9), ["joint1", "joint2"]
applied = None
for k in range(arm.K):
    z = arm.sense().z
    sample = m.joint_state(k * T_ns, names, z[:2], z[2:])
    torque = None if applied is None else m.joint_state((k - 1) * T_ns, names, effort=applied)
    if order == "before" and torque is not None:
        eff.publish(torque)
    enc.publish(sample)
    if order == "after" and torque is not None:
        eff.publish(torque)
    end = time.monotonic() + 60
    while len(cmds) <= k:
        rclpy.spin_once(node, timeout_sec=0.05)
        assert time.monotonic() < end, f"no command {k}"
    applied = 0.5 * cmds[k]
    if k + 1 < arm.K:
        arm.advance(applied)
print("half arm done", flush=True)
"""


def _half_arm_run(tmp_path: Path, order: str) -> tuple[np.ndarray, str]:
    """The C node on :data:`_HALF_ARM` (0.3 s, lockstep): its estimates and its output."""
    from tests.test_ros import _remaps

    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs: list[Any] = []
    arm = subprocess.Popen(
        [sys.executable, "-c", _HALF_ARM, order, "0.3", *_remaps(env)], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        procs.append(_start(env, "node", "paper-sim", "--controller", "amsfe", "--impl", "c",
                            "--duration", "0.3", "--record", str(rec), *PATIENT_NODE,
                            "-p", "watchdog.actuation_error:=.inf"))  # fmt: skip
        out, _ = arm.communicate(timeout=180)
    finally:
        if arm.poll() is None:
            arm.kill()
            arm.communicate()
        results = _finish(procs, 60.0)
    assert arm.returncode == 0 and "half arm done" in out, out
    code, text = results[0]
    assert code == 0, text
    est = np.array([np.r_[m.position, m.velocity] for m in _bag(rec)["/amsfe/estimate"]])
    return est, text


@pytest.mark.ros
@pytest.mark.slow
def test_the_node_waits_for_the_torque_of_the_previous_tick(tmp_path: Path) -> None:
    """An arm that applies half of each command and sends the torque of tick k-1 right after
    sample k (the order DDS may deliver two topics in): the C node waits for it (counted)
    and estimates exactly what it estimates when the torque comes first, the torque the arm
    applied, not its own command.  (A wait that ran out, on a machine too loaded to deliver
    the torque within T/2, is counted, and the node used its command there: then the test
    skips, saying so.)"""
    import re

    first, _ = _half_arm_run(tmp_path / "before", "before")
    late, text_late = _half_arm_run(tmp_path / "after", "after")
    waits = re.findall(r"waited for the torque applied over the previous tick at (\d+) samples "
                       r"\((\d+) not within the wait", text_late)  # fmt: skip
    assert waits and int(waits[0][0]) > 0, text_late
    if int(waits[0][1]) > 0:
        pytest.skip(f"{waits[0][1]} torques came later than T/2 (a loaded machine)")
    assert first.shape == late.shape == (301, 4)
    np.testing.assert_array_equal(late, first)
