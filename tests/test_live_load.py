"""Faults of the simulated arm and the live loop under CPU load (issue 34 item 4,
docs/live-load.md).

In process: :class:`~amsfe_sym.ros.faults.FaultPlan` changes exactly what it says, from the
tick it says, and nothing before (the arm's random streams untouched).  Over real DDS
(markers ``ros`` and ``slow``; each test on its own ROS_DOMAIN_ID and topics, localhost, every
process bounded and killed in a ``finally``, tests/test_ros.py's harness): outcomes, never
times.
"""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.apps.bench.ros import node_impls
from amsfe_sym.codegen import library_for
from amsfe_sym.core.cpu_load import CpuHogs
from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.faults import Fault, FaultPlan, parse_fault
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from tests.conftest import c_program_built
from tests.test_node_record import _bag
from tests.test_ros import PATIENT_ARM, PATIENT_NODE, PATIENT_WATCHDOG, _finish, _ros_env, _start


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=0.3)
    return sc, library_for(sc)


def _run_arm(sc: Any, lib: Any, faults: tuple[Fault, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The arm driven by a fixed command sequence: the samples it sends, the states it had."""
    arm, plan = SimArm(sc, lib), FaultPlan(faults, lib.T, lib.n)
    u = np.array([3.0, -1.0])[: lib.n]
    z, x = [], []
    for k in range(arm.K):
        x.append(arm.state)
        z.append(plan.encoders(k, arm.sense().z))
        if k + 1 < arm.K:
            arm.advance(plan.torque(k, u))
    return np.array(z), np.array(x)


@pytest.mark.parametrize(
    "fault",
    [Fault("encoder_frozen", 0.1), Fault("encoder_jump", 0.1, 0.25), Fault("torque_loss", 0.1)],
)
def test_a_fault_changes_what_it_says_from_its_tick(paper: Any, fault: Fault) -> None:
    sc, lib = paper
    n, kf = lib.n, 100
    z0, x0 = _run_arm(sc, lib, ())
    z1, x1 = _run_arm(sc, lib, (fault,))
    assert np.array_equal(z1[:kf], z0[:kf]) and np.array_equal(x1[: kf + 1], x0[: kf + 1])
    if fault.kind == "encoder_frozen":
        assert np.array_equal(x1, x0)  # the arm moves on; its encoders say it does not
        assert np.all(z1[kf:] == z0[kf]) and not np.array_equal(z0[kf:], z1[kf:])
    elif fault.kind == "encoder_jump":
        assert np.array_equal(x1, x0)
        np.testing.assert_array_equal(z1[kf:, :n], z0[kf:, :n] + 0.25)
        np.testing.assert_array_equal(z1[kf:, n:], z0[kf:, n:])
    else:  # no torque from tick kf: the arm departs from the driven one at kf + 1
        assert not np.array_equal(x1[kf + 1], x0[kf + 1])
        arm = SimArm(sc, lib)
        for k in range(kf + 1):
            arm.sense()
            arm.advance(np.array([3.0, -1.0])[:n] if k < kf else np.zeros(n))
        np.testing.assert_array_equal(arm.state, x1[kf + 1])


@pytest.mark.parametrize(
    "text",
    [
        "encoder_stuck@1",
        "encoder_frozen",
        "encoder_frozen@-1",
        "encoder_frozen@nan",
        "encoder_frozen@1=2",
        "encoder_jump@1",
        "encoder_jump@1=0",
        "encoder_jump@1=1e9",
        "torque_loss@x",
    ],
)
def test_a_bad_fault_is_one_line(text: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_fault(text)
    assert "\n" not in str(err.value) and "Fix" in str(err.value)


def test_faults_parse_and_the_same_kind_twice_is_refused(paper: Any) -> None:
    _, lib = paper
    assert parse_fault("encoder_jump@1.5=-0.5") == Fault("encoder_jump", 1.5, -0.5)
    assert parse_fault("torque_loss@0").label() == "torque_loss@0"
    with pytest.raises(ConfigError, match="each kind at most once"):
        FaultPlan((Fault("torque_loss", 1.0), Fault("torque_loss", 2.0)), lib.T, lib.n)


# ---------------------------------------------------------------------- over real DDS
#: The hold line of a watchdog (ros/watchdog.py): its reason and the tick it held at.
HOLD = re.compile(r"hold: (\w+): .*at tick (\d+), (\d+) missing\)")

#: The reasons that name the arm (its encoders, its torque, its path): an arm fault's.
ARM_REASONS = ("innovation", "tracking", "actuation")

#: The reasons that name this node being behind (CPU load, priority, a stall, a steady lag).
BEHIND_REASONS = ("deadline", "node_stalled", "compute", "lag")

#: A hold must come within this much of the arm's time after its cause [ticks of 1 ms].
WITHIN_TICKS = 100

#: The node implementations ``amsfe node`` offers (``--impl``), each tested.
IMPLS = node_impls()


#: A repeat of a free-running run for how often it holds: CI runs it once (docs/how-to/tests.md).
REPEAT = pytest.mark.nightly("a repeat of a free-running DDS run that CI makes once")

#: The C node on the C arm (the default arm) under load: test_carm.py's free-running run
#: (``--impl c`` both), which CI runs; here a repeat of it.
FREE_IMPLS = [pytest.param(i, marks=REPEAT) if i == "c" else i for i in IMPLS]


def _impl_args(impl: str) -> list[str]:
    """``--impl impl`` (none when the node has one implementation); the C node built first."""
    if impl == "c":
        c_program_built("paper-sim")
    return ["--impl", impl] if len(IMPLS) > 1 else []


def _hold(text: str) -> tuple[str, int] | None:
    """The watchdog's hold (reason, tick) in a node's output, None without one."""
    found = HOLD.findall(text)
    return (found[-1][0], int(found[-1][1])) if found else None


def _held(code: int, text: str) -> tuple[str, int]:
    """The node held (exit 3, its hold line): the reason and tick."""
    assert code == 3, text
    hold = _hold(text)
    assert hold is not None, text
    return hold


def _stop_arm(sim: Any, node: Any, timeout: float) -> tuple[int, str]:
    """Wait for the node to end, then stop the arm (SIGTERM: a lockstep arm would wait for
    the command of a node that held): the node's exit code and output."""
    code = node.p.wait(timeout=timeout)
    node._reader.join(timeout=5)
    if sim.p.poll() is None:
        sim.kill(signal.SIGTERM)
    return code, node.text


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", IMPLS)
@pytest.mark.parametrize(
    "fault",
    [
        "encoder_frozen@0.5",
        "encoder_jump@0.5=0.2",
        "torque_loss@0.5",
    ],
)
def test_an_arm_fault_holds_with_its_reason_within_100_ms(
    tmp_path: Path, fault: str, impl: str
) -> None:
    """A frozen encoder, an encoder jump of 0.2 rad, a torque loss at t = 0.5 s (lockstep,
    so every run is the same run): the node holds with a reason naming the arm (the
    innovations or the tracking error; the torque loss: ``actuation``, the torque the arm
    reports applying is not the command) within 100 ms of the arm's time, publishes its hold
    command and exits 3; its record ends at the hold and says why; the arm had not left its
    path by more than the in-process run's largest error plus 0.1 rad before it."""
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs: list[Any] = []
    try:
        # the timing watchdogs off (lockstep: the arm waits for the node): under load the
        # Python node's first tick once took longer than compute_budget (a CI run at load 5)
        # and held for `compute` before the arm's fault; the arm's reasons are the test's
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--duration", "1",
                      "--record", str(rec), *_impl_args(impl),
                      "--ros-args", *PATIENT_WATCHDOG)  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "1",
                     "--fault", fault, *PATIENT_ARM)  # fmt: skip
        procs += [node, sim]
        code, text = _stop_arm(sim, node, 180.0)
    finally:
        _finish(procs, 30.0)
    reason, k = _held(code, text)
    assert reason in ARM_REASONS and 500 <= k <= 500 + WITHIN_TICKS, (fault, reason, k)
    if fault.startswith("torque_loss"):
        assert reason == "actuation", (fault, reason, k)
    assert "hold command" in text
    bag = _bag(rec)
    cmd = bag["/effort_controller/commands"]
    assert len(cmd) >= 500  # every tick's command up to the hold, then the hold
    _assert_not_diverged(bag, max_k=k)


def _assert_not_diverged(bag: dict[str, list[Any]], max_k: int | None = None) -> None:
    """The true arm of a record (``/joint_states``, each tick's own) never farther from q_d
    than the in-process run of the same seed ever is, plus 0.1 rad."""
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    ref = run(sc, library_for(sc), runtime="compiled")
    n = ref.lib.n
    worst = np.abs(ref.x_true[:, :n] - ref.q_des).max()
    T = round(ref.lib.T * 1e9)
    js = bag["/joint_states"]
    ks = np.array([(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec) // T for m in js])
    q = np.array([m.position for m in js])
    keep = ks < ref.t.size if max_k is None else ks <= max_k
    err = np.abs(q[keep] - ref.q_des[ks[keep]]).max()
    assert err <= worst + 0.1, (err, worst)


def _wall_tick0(sim: Any) -> float:
    """The wall clock of a free-running arm's tick 0 (epoch [s], from its line)."""
    found = re.findall(r"sim-node: tick 0 at wall clock ([0-9.]+) s", sim.text)
    assert found, sim.text
    return float(found[0])


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", IMPLS)
@pytest.mark.parametrize("repeat", [1, pytest.param(2, marks=REPEAT)])
def test_a_300_ms_stall_of_the_node_holds_within_100_ms(
    tmp_path: Path, impl: str, repeat: int
) -> None:
    """Free running at 1 kHz: the harness stops the node's processes for 300 ms (SIGSTOP,
    SIGCONT) once the arm passed t = 1 s.  The node holds with a reason saying it is
    behind (deadline, node stalled, compute, lag; never "encoder stall": the arm's driver did
    not stop), at most 100 ms of the arm's time after the stall began, and exits 3.  (A node
    that could not keep up before the stall holds earlier, with such a reason too.)"""
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs: list[Any] = []
    try:
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--duration", "3",
                      "--record", str(rec), *_impl_args(impl))  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--duration", "3", "--start-timeout", "120")
        procs += [node, sim]
        sim.wait_for("sim-node: t = 1.0 s", 180.0)
        stalled = node.p.poll() is None
        if stalled:
            os.killpg(node.p.pid, signal.SIGSTOP)
            at = time.time()
            time.sleep(0.3)
            os.killpg(node.p.pid, signal.SIGCONT)
        code, text = _stop_arm(sim, node, 120.0)
    finally:
        _finish(procs, 30.0)
    reason, k = _held(code, text)
    assert reason in BEHIND_REASONS, (reason, k)
    if stalled:
        k_stall = int((at - _wall_tick0(sim)) / 1e-3)
        assert k <= k_stall + WITHIN_TICKS, (reason, k, k_stall)
    _assert_not_diverged(_bag(rec), max_k=k)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", FREE_IMPLS)
def test_free_running_under_load_tracks_or_holds_for_being_behind(
    tmp_path: Path, impl: str
) -> None:
    """Two CPU hogs (this suite's own, :class:`~amsfe_sym.core.cpu_load.CpuHogs`) beside the
    arm and the node, free running at 1 kHz for 2 s: either the node tracks as in process
    (no hold, exit 0; the link tracking RMSE over the run's window at most twice the
    in-process one of the same seed plus 0.05 rad), or it holds (exit 3) with a reason
    saying it is behind; never "encoder stall" (the arm's driver never stopped), never an
    arm diverged without a hold.  (Replaces the timed ``test_free_running_tracks``; the arm
    is ``sim-node``'s default, the C arm when it builds.)"""
    free_running_under_load(tmp_path, _impl_args(impl), [])


def free_running_run(
    tmp_path: Path, node_args: list[str], arm_args: list[str]
) -> tuple[int, str, dict[str, Any], Any]:
    """``amsfe node paper-sim --controller amsfe *node_args`` and ``amsfe sim-node paper-sim
    *arm_args``, free running for 2 s beside two CPU hogs: the node's exit code and output,
    its record's topics, and the arm's process."""
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs: list[Any] = []
    with CpuHogs(2, limit_s=600):
        try:
            node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--duration", "2",
                          "--record", str(rec), *node_args)  # fmt: skip
            sim = _start(env, "sim-node", "paper-sim", "--duration", "2", "--start-timeout",
                         "120", *arm_args)  # fmt: skip
            procs += [node, sim]
            code, text = _stop_arm(sim, node, 300.0)
        finally:
            _finish(procs, 60.0)
    return code, text, _bag(rec), sim


def free_running_rmse(bag: dict[str, Any]) -> tuple[Any, Any, int, int]:
    """The link tracking RMSE per joint [rad] of a 2 s free-running paper-sim record's
    ``/joint_states`` over the run's window, that of the in-process run of the same seed over
    the same ticks, how many ticks the record has (ticks the node skipped are predicted
    through) and how many the in-process run has."""
    from amsfe_sym.sim.record import window

    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    ref = run(sc, library_for(sc), runtime="compiled")
    n, T = ref.lib.n, round(ref.lib.T * 1e9)
    js = bag["/joint_states"]
    ks = np.array([(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec) // T for m in js])
    w = ks >= window(ref.t.size).start
    q = np.array([m.position for m in js])[w]
    got = np.sqrt(np.mean((q - ref.q_des[ks[w]]) ** 2, axis=0))
    want = np.sqrt(np.mean((ref.x_true[ks[w], :n] - ref.q_des[ks[w]]) ** 2, axis=0))
    return got, want, int(ks.size), int(ref.t.size)


def free_running_under_load(tmp_path: Path, node_args: list[str], arm_args: list[str]) -> str:
    """The run and the assertions of
    :func:`test_free_running_under_load_tracks_or_holds_for_being_behind` for ``amsfe node
    ... *node_args`` and ``amsfe sim-node ... *arm_args``; its outcome (``tracked`` or
    ``held <reason> at <tick>``), and the arm's summary lines, printed."""
    code, text, bag, sim = free_running_run(tmp_path, node_args, arm_args)
    hold = _hold(text)
    outcome = f"held {hold[0]} at {hold[1]}" if hold else "tracked"
    print("outcome:", node_args, arm_args, outcome, sim.text.splitlines()[-2:])
    if code == 3:
        assert hold is not None and hold[0] in BEHIND_REASONS, text
        _assert_not_diverged(bag, max_k=hold[1])
        return outcome
    assert code == 0 and hold is None and "encoder" not in text.split("node: done")[-1], text
    got, want, ticks, ref_ticks = free_running_rmse(bag)
    assert ticks > ref_ticks // 2  # (ticks the node skipped are predicted through)
    assert np.all(got <= 2 * want + 0.05), (got, want)
    _assert_not_diverged(bag)
    return outcome


_INTRUDER = """
import sys, time
import rclpy
from std_msgs.msg import Float64MultiArray
rclpy.init(args=["intruder", "--ros-args", *sys.argv[1:]])
node = rclpy.create_node("amsfe_sim")  # the arm's own name, too
pub = node.create_publisher(Float64MultiArray, "/effort_controller/commands", 100)
print("publishing", flush=True)
end = time.monotonic() + 120
while time.monotonic() < end:
    pub.publish(Float64MultiArray(data=[0.0, 0.0]))
    time.sleep(0.01)
"""


@pytest.mark.ros
@pytest.mark.slow
def test_a_lockstep_arm_refuses_a_second_controller_by_name(tmp_path: Path) -> None:
    """A second publisher of the command topic (a node that also carries the arm's name)
    beside ``amsfe node``: ``sim-node --lockstep`` warns of the two nodes named amsfe_sim and
    refuses, in one line naming both publishers, instead of applying their commands
    interleaved (issue 37 item 2)."""
    import subprocess
    import sys

    from tests.test_ros import _remaps

    env = _ros_env(tmp_path)
    procs: list[Any] = []
    intruder = subprocess.Popen(
        [sys.executable, "-c", _INTRUDER, *_remaps(env)], env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        assert intruder.stdout is not None and "publishing" in intruder.stdout.readline()
        # 5 s of arm time: the refusal ends the run at the intruder's first command, but the
        # arm must have discovered it by then (a 1 s run took 0.67 s of wall time in CI and
        # ended before discovery did: the arm never heard of the intruder and ran to its end)
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--duration", "5",
                      "--impl", "python", *PATIENT_NODE)  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "5",
                     *PATIENT_ARM)  # fmt: skip
        procs += [sim, node]
        code = sim.p.wait(timeout=180)
        sim._reader.join(timeout=5)
        if node.p.poll() is None:  # (its arm refused to run: it waits for samples)
            node.kill(signal.SIGTERM)
    finally:
        _finish(procs, 60.0)
        os.killpg(intruder.pid, signal.SIGKILL)
        intruder.wait()
        if intruder.stdout is not None:
            intruder.stdout.close()
    assert code == 2, sim.text
    errors = [x for x in sim.text.splitlines() if x.startswith("error:")]
    assert len(errors) == 1 and "one controller" in errors[0], sim.text
    assert "amsfe_node" in errors[0] and "amsfe_sim" in errors[0], errors[0]
    assert "2 nodes named" in sim.text and "amsfe_sim" in sim.text, sim.text
