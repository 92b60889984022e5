"""The real-arm-shaped logs of tests/real_logs.py, read back with rosbags' AnyReader, and
tools/real_recording.py's facts checked against the timing the writers drew."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.real_logs import (
    FRANKA_ARM,
    FRANKA_FINGERS,
    UR_JOINTS,
    ArmMotion,
    FrankaLikeOptions,
    URLikeOptions,
    WrittenLog,
    motion_from_run,
    smooth_motion,
    write_franka_like_bag,
    write_ur_like_rosbag2,
)

ROOT = Path(__file__).resolve().parent.parent
TOOL = ROOT / "tools" / "real_recording.py"


def _read(path: Path) -> dict[str, Any]:
    """Every JointState of the log: names, stamps, log times and the three arrays."""
    from rosbags.highlevel import AnyReader

    out: dict[str, Any] = {"names": [], "stamp": [], "log": [], "p": [], "v": [], "e": []}
    with AnyReader([path]) as reader:
        out["topics"] = {c.topic: c.msgtype for c in reader.connections}
        out["callerid"] = {getattr(c.ext, "callerid", None) for c in reader.connections}
        for c, t, raw in reader.messages():
            m: Any = reader.deserialize(raw, c.msgtype)
            out["names"].append(tuple(m.name))
            out["stamp"].append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
            out["log"].append(t)
            out["p"].append(m.position)
            out["v"].append(m.velocity)
            out["e"].append(m.effort)
    for key in ("p", "v", "e"):
        out[key] = np.vstack(out[key])
    out["stamp"] = np.asarray(out["stamp"], dtype=np.int64)
    out["log"] = np.asarray(out["log"], dtype=np.int64)
    return out


def _facts(path: Path) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    run = subprocess.run(
        [sys.executable, str(TOOL), str(path), "--json"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    facts: dict[str, Any] = json.loads(run.stdout)
    return facts


@pytest.fixture(scope="module")
def franka(tmp_path_factory: pytest.TempPathFactory) -> tuple[ArmMotion, WrittenLog]:
    rng = np.random.default_rng(26)
    motion = smooth_motion(FRANKA_ARM, 60.0, 0.001, rng)
    path = tmp_path_factory.mktemp("franka") / "panda.bag"
    return motion, write_franka_like_bag(path, motion, rng)


def test_franka_like_bag_is_what_franka_ros_records(franka: tuple[ArmMotion, WrittenLog]) -> None:
    motion, log = franka
    got = _read(log.path)
    assert got["topics"] == {"/joint_states": "sensor_msgs/msg/JointState"}
    assert got["callerid"] == {"/joint_state_publisher"}
    assert set(got["names"]) == {FRANKA_ARM + FRANKA_FINGERS}
    assert log.path.suffix == ".bag" and log.path.read_bytes()[:13] == b"#ROSBAG V2.0\n"
    # 60 s at 30 Hz: 1801 messages, each the grid row it says, bit for bit
    assert len(got["stamp"]) == 1801
    np.testing.assert_array_equal(got["p"][:, :7], motion.q[log.sample_index])
    np.testing.assert_array_equal(got["v"][:, :7], motion.qd[log.sample_index])
    np.testing.assert_array_equal(got["e"][:, :7], motion.effort[log.sample_index])
    assert not got["p"][:, 7:].any() and not got["v"][:, 7:].any() and not got["e"][:, 7:].any()
    # the zero-order hold: the row is the newest one at the message's true time
    t_row = log.sample_index * motion.period
    assert np.all(t_row <= log.true_time + 1e-12)
    assert np.all(log.true_time - t_row < motion.period + 1e-12)
    # header stamps on the other machine's clock, 203.6 s ahead; log times increase
    np.testing.assert_array_equal(got["stamp"], log.stamp_ns)
    np.testing.assert_array_equal(got["log"], log.log_time_ns)
    ahead = (got["stamp"] - got["log"]) / 1e9
    lat_min = FrankaLikeOptions().latency_min
    assert ahead.min() > 203.59 and ahead.max() <= 203.6 - lat_min + 1e-9
    assert np.all(np.diff(got["log"]) >= 0)


def test_real_recording_tool_finds_the_drawn_timing(
    franka: tuple[ArmMotion, WrittenLog],
) -> None:
    """The tool's facts (rosbags' reader, its own statistics) against the writer's draws."""
    _, log = franka
    facts = _facts(log.path)
    assert facts["container"] == "ROS 1 bag"
    assert facts["message_count"] == len(log.stamp_ns)
    (js,) = facts["joint_states"]
    assert js["names"] == list(FRANKA_ARM + FRANKA_FINGERS) and js["names_constant"]
    assert js["filled"] == {"position": 9, "velocity": 9, "effort": 9}
    offset = (log.stamp_ns - log.log_time_ns) / 1e9
    assert js["stamp_minus_log_s"]["median"] == pytest.approx(np.median(offset), abs=1e-9)
    assert js["stamp_minus_log_s"]["min"] == pytest.approx(offset.min(), abs=1e-9)
    dts = np.diff(log.stamp_ns) / 1e9
    assert js["stamp_period_s"]["median"] == pytest.approx(np.median(dts), abs=1e-9)
    assert js["stamp_period_s"]["median"] == pytest.approx(1 / 30, rel=2e-3)
    assert js["stamp_minus_log_mean_s"] == pytest.approx(np.mean(offset), abs=1e-9)
    # the fitted grid: the writer's rate, and its stamp jitter (std 0.049 ms) about it
    assert js["grid_period_s"] == pytest.approx(1 / 30, rel=1e-5)
    assert js["grid_residual_std_s"] == pytest.approx(FrankaLikeOptions().stamp_jitter, rel=0.1)
    assert js["gaps"] == 0 and js["largest_gap_periods"] < 1.1
    assert js["repeated_samples"] == 0
    assert js["backwards_stamps"] == js["repeated_stamps"] == js["zero_stamps"] == 0


def test_repeated_samples_and_jitter_are_counted(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    motion = smooth_motion(FRANKA_ARM, 20.0, 0.001, rng)
    opts = FrankaLikeOptions(repeat_probability=0.05, stamp_jitter=0.2 / 30 / 3)
    log = write_franka_like_bag(tmp_path / "r.bag", motion, rng, opts)
    repeats = int(np.sum(log.sample_index[1:] == log.sample_index[:-1]))
    assert repeats > 5
    (js,) = _facts(log.path)["joint_states"]
    assert js["repeated_samples"] == repeats
    jit = np.diff(log.stamp_ns) / 1e9
    med = np.median(jit)
    assert js["jitter_over_period"]["max"] == pytest.approx((jit.max() - med) / med, rel=1e-6)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_ur_like_rosbag2_logs_currents_in_driver_order(tmp_path: Path, storage: str) -> None:
    rng = np.random.default_rng(5)
    motion = smooth_motion(UR_JOINTS, 4.0, 0.001, rng)
    k = np.array([13.0, 13.0, 9.0, 4.0, 4.0, 4.0])
    opts = URLikeOptions(newton_metres_per_ampere=list(k), storage=storage)  # type: ignore[arg-type]
    log = write_ur_like_rosbag2(tmp_path / "ur", motion, rng, opts)
    assert any(p.suffix == (".mcap" if storage == "mcap" else ".db3") for p in log.path.iterdir())
    got = _read(log.path)
    alphabetical = tuple(sorted(UR_JOINTS))
    assert set(got["names"]) == {alphabetical} and alphabetical[0] == "elbow_joint"
    perm = [UR_JOINTS.index(n) for n in alphabetical]
    assert len(got["stamp"]) == 501  # 4 s at 125 Hz
    np.testing.assert_array_equal(got["p"], motion.q[log.sample_index][:, perm])
    # effort: the applied torque over N m per ampere, in the same order
    np.testing.assert_allclose(
        got["e"] * k[perm], motion.effort[log.sample_index][:, perm], rtol=1e-15, atol=1e-14
    )
    assert np.all(np.abs(got["stamp"] - got["log"]) < 2e-3 * 1e9)  # one clock: no offset


def test_writers_refuse_what_they_cannot_write(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="must agree"):
        ArmMotion(FRANKA_ARM, 0.001, np.zeros((3, 7)), np.zeros((3, 6)), np.zeros((3, 7)))
    ur = smooth_motion(UR_JOINTS, 1.0, 0.001, rng)
    with pytest.raises(ValueError, match="panda_joint1"):
        write_franka_like_bag(tmp_path / "x.bag", ur, rng)
    with pytest.raises(ValueError, match="6 values > 0"):
        write_ur_like_rosbag2(
            tmp_path / "y", ur, rng, URLikeOptions(newton_metres_per_ampere=[1.0] * 5)
        )
    assert not (tmp_path / "x.bag").exists() and not (tmp_path / "y").exists()


def test_rest_effort_against_gravity_finds_the_missing_load(tmp_path: Path) -> None:
    """A Panda at rest in three poses logs the gravity torque of its URDF plus 0.6 kg at the
    TCP (Pinocchio: a body appended to joint 7, computeGeneralizedGravity); the tool's fit
    (the TCP Jacobian's transpose against the effort minus the URDF's g(q)) finds +0.6 kg."""
    import pinocchio as pin

    urdf = ROOT / "robots" / "panda" / "panda.urdf"
    loaded = pin.buildModelFromUrdf(str(urdf))
    tcp = loaded.frames[loaded.getFrameId("panda_hand_tcp")]
    inertia = pin.Inertia(0.6, np.zeros(3), np.zeros((3, 3)))
    loaded.appendBodyToJoint(tcp.parentJoint, inertia, tcp.placement)
    data = loaded.createData()
    rng = np.random.default_rng(3)
    poses = rng.uniform(-1.0, 1.0, (3, 7)) + np.array([0, 0, 0, -1.8, 0, 1.6, 0])
    q = np.repeat(poses, 1000, axis=0)  # 1 s each at 1 kHz
    effort = np.empty_like(q)
    for k, pose in enumerate(poses):
        full = pin.neutral(loaded)
        full[:7] = pose
        effort[k * 1000 : (k + 1) * 1000] = pin.computeGeneralizedGravity(loaded, data, full)[:7]
    motion = ArmMotion(FRANKA_ARM, 0.001, q, np.zeros_like(q), effort)
    log = write_franka_like_bag(tmp_path / "rest.bag", motion, rng)
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    args = [str(log.path), "--urdf", str(urdf), "--mass-at", "panda_hand_tcp", "--json"]
    run = subprocess.run(
        [sys.executable, str(TOOL), *args], capture_output=True, text=True, env=env, check=True
    )
    (js,) = json.loads(run.stdout)["joint_states"]
    assert js["rest_samples"] == len(log.stamp_ns)
    assert js["mass_fit_kg"] == pytest.approx(0.6, abs=1e-9)
    assert max(abs(v) for v in js["residual_after_mass_fit"].values()) < 1e-9


@pytest.mark.slow
def test_a_simulated_ur5_run_as_a_ur_driver_logs_it(tmp_path: Path) -> None:
    """One second of the shipped UR5 scenario (its ur5_rk4 library: ~15 s of compile on a
    fresh checkout, then cached) written as a UR driver's log: the currents times N m per
    ampere give back the applied torque u, the positions the true link angles; and the
    joint-torque effort is Ks (qm - q) with Ks read from the robot spec, not the library."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.load import load_robot
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    sc = load_scenario("ur5-demo").with_overrides(duration=1.0)
    lib = library_for(sc)
    res = run(sc, lib=lib)
    applied = motion_from_run(res, "applied")
    assert applied.names == UR_JOINTS and applied.period == lib.T
    k = np.array([12.0, 12.0, 10.0, 5.0, 5.0, 5.0])
    rng = np.random.default_rng(11)
    opts = URLikeOptions(newton_metres_per_ampere=list(k))
    log = write_ur_like_rosbag2(tmp_path / "ur5", applied, rng, opts)
    got = _read(log.path)
    perm = [UR_JOINTS.index(n) for n in sorted(UR_JOINTS)]
    rows = log.sample_index
    assert len(rows) == 126  # 1 s at 125 Hz
    np.testing.assert_array_equal(got["p"], res.x_true[rows][:, lib.layout["q"]][:, perm])
    np.testing.assert_allclose(got["e"] * k[perm], res.u[rows][:, perm], rtol=1e-14, atol=1e-12)
    spring = motion_from_run(res, "joint_torque")
    ks = load_robot("ur5").Ks
    x = res.x_true
    expected = ks * (x[:, lib.layout["qm"]] - x[:, lib.layout["q"]])
    np.testing.assert_allclose(spring.effort, expected, rtol=1e-12, atol=1e-12)


def test_make_real_like_logs_writes_or_refuses_in_one_line(tmp_path: Path) -> None:
    tool = ROOT / "tools" / "make_real_like_logs.py"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))

    def call(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, str(tool), *args], capture_output=True, text=True, env=env
        )

    out = tmp_path / "f.bag"
    ok = call("franka", str(out), "--duration", "2", "--offset", "-5.0")
    assert ok.returncode == 0, ok.stderr
    (js,) = _facts(out)["joint_states"]
    assert js["count"] == 61 and js["stamp_minus_log_s"]["max"] < -5.0
    again = call("franka", str(out), "--duration", "2")
    assert again.returncode == 2 and again.stdout.count("\n") == 1 and "exists" in again.stdout
    lone = call("ur", str(tmp_path / "u"), "--truth", str(tmp_path / "t.npz"))
    assert lone.returncode == 2 and "--scenario" in lone.stdout
    assert not (tmp_path / "u").exists() and not (tmp_path / "t.npz").exists()
