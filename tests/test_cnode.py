"""The C node (``amsfe node --impl c``, ``ros/c/amsfe_node*.c``; docs/live-control.md).

Over real DDS (marker ``ros``; each test on its own domain and topics, every process bounded,
as tests/test_ros.py does): ``sim-node --lockstep`` + the C node reproduce ``amsfe simulate``
(the compiled loop) bit for bit on paper-sim and the Panda, and equal the Python node's run;
the build is cached by content (a second build compiles nothing); the wheels missing is one
line.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import RosError
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from tests.conftest import LOCKSTEP_S, c_program_built
from tests.test_node_record import _bag
from tests.test_ros import (
    _PREFIX,
    PATIENT_ARM,
    PATIENT_NODE,
    PATIENT_WATCHDOG,
    SRC,
    _finish,
    _ros_env,
    _start,
)


def _lockstep(
    tmp_path: Path,
    scenario: str,
    impl: str,
    duration: float = 2.0,
    node_args: tuple[str, ...] = (),
    arm_args: tuple[str, ...] = (),
) -> dict[str, Any]:
    """``sim-node --lockstep ARM_ARGS`` + ``node --impl IMPL --controller amsfe --record
    NODE_ARGS`` for ``duration`` s: both exit 0; the record's topics and the node's output."""
    env = _ros_env(tmp_path)
    rec = tmp_path / f"rec-{impl}"
    d = f"{duration:g}"
    procs = []
    try:
        procs.append(_start(env, "node", scenario, "--controller", "amsfe", "--impl", impl,
                            "--duration", d, "--record", str(rec), *node_args,
                            *PATIENT_NODE))  # fmt: skip
        procs.append(_start(env, "sim-node", scenario, "--lockstep", "--duration", d,
                            *arm_args, *PATIENT_ARM))  # fmt: skip
    finally:
        results = _finish(procs, 180.0)
    for code, text in results:
        assert code == 0, text
    got: dict[str, Any] = dict(_bag(rec))
    got["_text"] = results[0][1]
    return got


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["paper-sim", "panda-control"])
def test_c_node_lockstep_is_simulate(scenario: str, lockstep_runs: Any) -> None:
    """The C node over DDS in lockstep: its estimates, theta and commands (from its record,
    every tick) equal ``amsfe simulate``'s compiled loop of the same seed bit for bit, its
    frames fused and refused are the loop's, and it ends with the hold command.  (The run,
    1 s, is shared: tests/conftest.py's ``lockstep_runs``.)"""
    sc = load_scenario(scenario).with_overrides(duration=LOCKSTEP_S)
    run_ = lockstep_runs.get(scenario, "c")
    assert_is_simulate({**run_.topics, "_text": run_.node_text}, sc, library_for(sc))


def assert_is_simulate(got: dict[str, Any], sc: Any, lib: Any) -> None:
    """A lockstep record ``got`` of the C node (:func:`_lockstep`) is ``amsfe simulate``'s
    compiled loop of ``sc`` bit for bit: estimates, std, theta, commands and truth every
    tick, the frames fused and refused, the hold command last."""
    assert "the C node" in got["_text"], got["_text"]
    assert f"done: {round(sc.duration / lib.T) + 1} ticks" in got["_text"], got["_text"]
    ref = run(sc, lib, runtime="compiled")
    n = lib.n
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    cmd = np.array([m.data for m in got["/effort_controller/commands"]])
    theta = np.array([m.data for m in got["/amsfe/theta"]])
    assert est.shape == (ref.t.size, 2 * n)
    np.testing.assert_array_equal(est, ref.x_hat[:, : 2 * n])
    np.testing.assert_array_equal(theta, ref.x_hat[:, 4 * n :])
    np.testing.assert_array_equal(cmd[:-1], ref.u)  # the last: the hold
    std = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate_std"]])
    np.testing.assert_array_equal(std, np.sqrt(ref.P_diag[:, : 2 * n]))
    assert len(got["/camera/marker"]) == ref.counters["frames_delivered"] > 0
    diag = json.loads(got["/amsfe/diagnostics"][-1].data)
    assert diag["frames_fused"] == ref.counters["frames_applied"] > 0
    assert diag["frames_refused"] == ref.counters["frames_rejected"]
    truth = np.array([m.data for m in got["/amsfe/truth"]])  # each tick's own
    np.testing.assert_array_equal(truth, ref.x_true)
    assert "latency sample received -> command published" in got["_text"]


@pytest.mark.ros
@pytest.mark.slow
def test_c_node_equals_the_python_node(lockstep_runs: Any) -> None:
    """The same lockstep run with the C node and with the Python node (the readable
    reference): the same estimates, standard deviations, theta and commands (1e-12), the same
    estimator decisions.  (Not the skipped messages: whether a torque sample arrives before
    or after the next encoder sample is DDS's timing, and in lockstep either way the step
    uses the same torque, the command.)  The two runs of test_ros.py's
    ``test_lockstep_reproduces_simulate``, shared (tests/conftest.py's ``lockstep_runs``)."""
    c = lockstep_runs.get("paper-sim", "c").topics
    py = lockstep_runs.get("paper-sim", "python").topics
    for topic in ("/amsfe/estimate", "/amsfe/estimate_std"):
        a = np.array([np.r_[m.position, m.velocity] for m in c[topic]])
        b = np.array([np.r_[m.position, m.velocity] for m in py[topic]])
        assert a.shape == b.shape and a.shape[0] == round(LOCKSTEP_S / 1e-3) + 1
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    for topic in ("/amsfe/theta", "/effort_controller/commands"):
        a = np.array([m.data for m in c[topic]])
        b = np.array([m.data for m in py[topic]])
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    dc = json.loads(c["/amsfe/diagnostics"][-1].data)
    dp = json.loads(py["/amsfe/diagnostics"][-1].data)
    for key in ("k", "frames_fused", "frames_refused", "refused"):
        assert dc[key] == dp[key], key


def test_build_is_cached_by_content(tmp_path: Path) -> None:
    """Building the node twice compiles once: the second build reuses the executable (same
    key, same file, not rewritten)."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.ros.cnode import build_node

    lib = library_for(load_scenario("paper-sim"))
    first = build_node(lib, tmp_path)
    assert first.compiled and first.path.is_file()
    stamp = first.path.stat().st_mtime_ns
    second = build_node(lib, tmp_path)
    assert not second.compiled
    assert (second.path, second.key) == (first.path, first.key)
    assert second.path.stat().st_mtime_ns == stamp
    made = json.loads((first.path.parent / "build.json").read_text())
    assert "-O1" in made["cflags"] and "--disable-new-dtags" in made["command"]


def test_a_failed_build_names_the_compilers_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A compiler that fails prints its error, then warnings (as gcc orders them when the
    error is in the last function): the one-line refusal quotes the error, not the
    warnings after it (a build broken by a redeclaration once said only 'warning: ignoring
    return value')."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.ros.cnode import build_node

    fake = tmp_path / "fake-cc"
    fake.write_text(
        "#!/bin/sh\n"
        'case "$*" in *--version*) echo fake-cc 1.0; exit 0;; esac\n'
        "echo \"a.c:698:26: error: conflicting types for 'pubs'\" >&2\n"
        'for i in 1 2 3 4; do echo "a.c:34$i:11: warning: ignoring return value" >&2; done\n'
        "exit 1\n"
    )
    fake.chmod(0o755)
    lib = library_for(load_scenario("paper-sim"))  # (built by the real compiler)
    monkeypatch.setenv("CC", str(fake))
    with pytest.raises(RosError) as err:
        build_node(lib, tmp_path / "out")
    line = str(err.value)
    assert "\n" not in line and "conflicting types for 'pubs'" in line, line
    assert "warning" not in line, line


def test_missing_wheels_is_one_line(tmp_path: Path) -> None:
    """Without rcl's headers and libraries (the [ros] extra) the C node's build says so in
    one line naming the fix; ``amsfe node --impl c`` then exits 2 with that one line and
    writes nothing."""
    from amsfe_sym.ros.cnode import ros_paths

    with pytest.raises(RosError, match=r"rcl's C headers.*Fix: pip install"):
        ros_paths(tmp_path)
    block = (
        "import sys; sys.prefix = sys.argv[1]; from amsfe_sym.apps.cli import main; "
        "sys.exit(main(['node', 'paper-sim', '--impl', 'c']))"
    )
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    empty = tmp_path / "empty-prefix"
    empty.mkdir()
    node = subprocess.run(
        [sys.executable, "-c", block, str(empty)],
        env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert node.returncode == 2, node.stderr
    lines = [x for x in node.stderr.splitlines() if x.startswith("error:")]
    assert len(lines) == 1 and ".[ros]" in lines[0] and "librcl" in lines[0], node.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty-prefix"]


@pytest.mark.ros
@pytest.mark.slow
def test_amsfe_live_is_simulate(tmp_path: Path) -> None:
    """``amsfe live --lockstep`` (the arm and the C node in one command) exits 0 and its
    record equals ``amsfe simulate`` bit for bit."""
    sc = load_scenario("paper-sim").with_overrides(duration=1.0)
    lib = library_for(sc)
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs = []
    try:
        procs.append(_start(env, "live", "paper-sim", "--controller", "amsfe", "--lockstep",
                            "--duration", "1", "--impl", "c", "--record", str(rec),
                            "--encoder-timeout", "20", "--command-timeout", "60",
                            "--ros-args", *PATIENT_WATCHDOG))  # fmt: skip
    finally:
        results = _finish(procs, 180.0)
    code, text = results[0]
    assert code == 0, text
    assert "sim-node: 1001 ticks" in text and "node: done: 1001 ticks" in text, text
    ref = run(sc, lib, runtime="compiled")
    got = _bag(rec)
    est = np.array([np.r_[m.position, m.velocity] for m in got["/amsfe/estimate"]])
    np.testing.assert_array_equal(est, ref.x_hat[:, : 2 * lib.n])
    cmd = np.array([m.data for m in got["/effort_controller/commands"]])
    np.testing.assert_array_equal(cmd[:-1], ref.u)


def test_amsfe_live_gives_both_the_same_duration() -> None:
    """``amsfe live`` without ``--duration``: the node and the arm both get the scenario's
    (exactly), so the arm's last tick is the node's end; with it, both get it."""
    from amsfe_sym.ros.pair import PairOptions, pair_commands

    for opts, want in [
        (PairOptions("paper-sim", "amsfe", lockstep=True), load_scenario("paper-sim").duration),
        (PairOptions("paper-sim", "amsfe", duration=0.1234567), 0.1234567),
    ]:
        for args in pair_commands(opts):
            assert args.count("--duration") == 1, args
            assert float(args[args.index("--duration") + 1]) == want, args


@pytest.mark.ros
def test_amsfe_live_stops_the_arm_when_the_node_is_gone(tmp_path: Path) -> None:
    """A node that ends without a hold (here exit 2: a controller name it refuses after the
    arm has started) stops the arm at once: the arm (start and command timeouts 150 s) says
    it was stopped by Ctrl-C and the command exits with the node's code.  Before, the arm
    waited out its start timeout for a node that was gone (a CI run's crashed node)."""
    env = _ros_env(tmp_path)
    procs = []
    try:
        procs.append(_start(env, "live", "paper-sim", "--controller", "nosuch",
                            "--duration", "1", "--command-timeout", "150"))  # fmt: skip
    finally:
        results = _finish(procs, 120.0)  # under the arm's timeouts: a wait fails the test
    code, out = results[0]
    assert code == 2, out
    assert "live: the node ended (exit 2) before the arm; the arm is stopped" in out, out
    assert "amsfe sim-node stopped by Ctrl-C" in out or "sim-node" not in out, out


def test_amsfe_live_names_how_a_process_ended() -> None:
    from amsfe_sym.ros.pair import _how

    assert [_how(2), _how(-11), _how(-200)] == [
        "exit 2",
        "killed by SIGSEGV",
        "killed by signal 200",
    ]


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize(
    ("impl", "mode"),
    [("c", "--lockstep"), ("python", "--lockstep"), ("c", "free"), ("python", "free")],
)
def test_amsfe_live_ends_with_the_data(tmp_path: Path, impl: str, mode: str) -> None:
    """``amsfe live SCENARIO --controller amsfe`` with no ``--duration`` (docs/live-control.md's
    first block, on a 0.5 s copy of paper-sim): at the arm's last tick the node says ``done``
    and the command exits 0, in lockstep and free running (the arm at a quarter of real time
    with the timing watchdogs off: a loaded machine), for the C and the Python node.  It held
    with ``encoder_stall`` (exit 3) once the arm had ended: the node had no duration."""
    import re

    text, count = re.subn(
        r"(?m)^duration = [0-9.]+", "duration = 0.5", (SRC.parent / "scenarios/paper-sim.toml")
        .read_text()
    )  # fmt: skip
    assert count == 1
    short = tmp_path / "short.toml"
    short.write_text(text)
    env = _ros_env(tmp_path)
    timing = ["--lockstep"] if mode == "--lockstep" else ["--rate", "0.25"]
    procs = []
    try:
        procs.append(_start(env, "live", str(short), "--controller", "amsfe", "--impl", impl,
                            *timing, "--encoder-timeout", "20", "--command-timeout", "60",
                            "--ros-args", *PATIENT_WATCHDOG))  # fmt: skip
    finally:
        results = _finish(procs, 180.0)
    code, out = results[0]
    assert code == 0, out
    node = [x for x in out.splitlines() if x.startswith("node: ") and "latency" not in x]
    assert node[-1].startswith("node: done: 501 ticks (0.500 s of samples)"), out
    assert "sim-node: 501 ticks" in out and "encoder_stall" not in out, out


#: The stamps' origin in the messy stream: the system clock of a driver (ns since 1970).
EPOCH_NS = 1_700_000_000 * 10**9


def _messy_messages(sc: Any, lib: Any) -> list[tuple[Any, ...]]:
    """The messages of a closed-loop run of the Python LiveLoop with the arm, as a driver and
    a late DDS would deliver them (stamps on the system clock, source timestamps from a
    counter): a frame and a torque before the first sample, samples duplicated, off the grid
    and missing (a gap of 3), frames duplicated, with a NaN pixel, off the grid and sent
    after the sample of their tick, torque samples of some ticks (slightly off the command),
    one late; and issue 37's bad stamps, each skipped by name: one sample stamped 1 h ahead,
    two with a zero stamp, two 0.3 s back (a clock step back and forth)."""
    from amsfe_sym.ros.arm import SimArm
    from amsfe_sym.ros.live import LiveLoop

    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True)
    T = round(lib.T * 1e9)
    bad = {50: 3600 * 10**9, 75: None, 76: None, 85: -3 * 10**8, 86: -3 * 10**8}
    sent = iter(range(1, 10**9))
    msgs: list[tuple[Any, ...]] = []

    def send(*m: Any) -> None:
        msgs.append(m)
        if m[0] == "frame":
            loop.frame(m[1], np.array(m[2:4]), m[4])
        elif m[0] == "applied":
            loop.applied(m[1], np.array(m[2]))
        else:
            out = loop.encoders(m[1], np.array(m[3]), m[2])
            if out is not None:
                last[0] = out

    last: list[Any] = [None]
    send("frame", EPOCH_NS, 100.0, 100.0, next(sent))  # before the first sample: skipped
    send("applied", EPOCH_NS, np.full(lib.n, 0.5))  # before the first sample: waits for it
    late: list[tuple[Any, ...]] = []
    for k in range(arm.K):
        s = arm.sense()
        for f in s.frames:
            m = ("frame", EPOCH_NS + f.exposure_step * T, *map(float, f.z), next(sent))
            if k % 7 == 3:
                late.append(m)  # sent after this tick's sample: fused at the next one
            else:
                send(*m)
            if k % 5 == 0:
                send(*m[:4], next(sent))  # the same exposure again: a duplicate
        stamp = EPOCH_NS + k * T
        if k == 40:
            send("frame", stamp + T // 2, 1.0, 1.0, next(sent))  # exposure off the grid
            send("frame", stamp - T, float("nan"), 1.0, next(sent))  # a NaN pixel
        if k in bad:  # skipped by name; the next good sample predicts through
            step = bad[k]
            send("enc", 0 if step is None else stamp + step, next(sent), s.z)
        elif k not in (60, 61, 62):  # a gap of 3: predicted through
            send("enc", stamp, next(sent), s.z)
        if k % 11 == 0:
            send("enc", stamp, next(sent), s.z)  # duplicated
        if k == 30:
            send("enc", stamp + T // 2, next(sent), s.z)  # off the grid
        for m in late:
            send(*m[:4], next(sent))
        late.clear()
        out = last[0]
        assert out is not None and out.u is not None
        u = out.u + (1e-3 if k % 13 == 0 else 0.0)
        if k % 3 == 0:
            send("applied", stamp, u)  # what the arm applied (else: the command)
        if k == 90:
            send("applied", EPOCH_NS + 80 * T, u)  # after its tick was estimated: skipped
        if k + 1 < arm.K:
            arm.advance(u if k % 13 == 0 else out.u)
    return msgs


def _replay(
    tmp_path: Path, sc: Any, lib: Any, msgs: list[tuple[Any, ...]], spec: Any = None
) -> list[str]:
    """The C node's live loop (``amsfe_node --replay``, no rcl) on ``msgs`` (``spec``: the
    topic spec, default TopicSpec()): its lines."""
    from amsfe_sym.ros.cnode import build_node, write_params
    from amsfe_sym.topics import TopicSpec

    lines = []
    for m in msgs:
        if m[0] == "frame":
            lines.append(f"frame {m[1]} {m[2]!r} {m[3]!r} {m[4]}")
        elif m[0] == "applied":
            lines.append(f"applied {m[1]} " + " ".join(repr(float(v)) for v in m[2]))
        else:
            lines.append(f"enc {m[1]} {m[2]} " + " ".join(repr(float(v)) for v in m[3]))
    events = tmp_path / "events.txt"
    events.write_text("\n".join(lines) + "\n")
    opts = {"end_k": -1, "std_every": 10, "hold": "gravity", "encoder_timeout": 0.5,
            "subscriber_wait": 1.0, "record": None, "sched_priority": 0}  # fmt: skip
    spec = TopicSpec() if spec is None else spec
    params = write_params(tmp_path, sc, lib, spec, controller=True, options=opts)
    exe = build_node(lib).path
    done = subprocess.run([str(exe), str(params), "--replay", str(events)],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


@pytest.mark.parametrize("shift", [0, 3])
def test_c_live_loop_is_the_python_live_loop(tmp_path: Path, shift: int) -> None:
    """The C node's live loop (``amsfe_live.c``, run by ``amsfe_node --replay`` without rcl)
    and the Python LiveLoop on the same messy message stream (early, duplicated, off-grid,
    missing, NaN and late messages, zero stamps, stamps 1 h ahead and 0.3 s back): the same
    estimates and commands at every tick (1e-9), the same ticks skipped, the same skip counts
    by reason and the same decisions; with the camera's ``[camera] time_offset`` of
    ``shift`` ticks too (frames taken as exposed ``shift`` ticks before their stamps)."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.ros.live import LiveLoop
    from amsfe_sym.topics.spec import parse_topic_spec

    sc = load_scenario("paper-sim").with_overrides(duration=0.3)
    lib = library_for(sc)
    msgs = _messy_messages(sc, lib)
    spec = parse_topic_spec({"camera": {"time_offset": shift * lib.T}})
    assert spec.exposure_shift(lib.T) == shift
    out = _replay(tmp_path, sc, lib, msgs, spec)
    # the Python reference on the same messages
    loop = LiveLoop(sc, lib, controller=True, exposure_shift=shift)
    want: list[str | np.ndarray] = []
    for m in msgs:
        if m[0] == "frame":
            loop.frame(m[1], np.array(m[2:4]), m[4])
        elif m[0] == "applied":
            loop.applied(m[1], np.array(m[2]))
        else:
            tick = loop.encoders(m[1], np.array(m[3]), m[2])
            want.append("skip" if tick is None else np.r_[tick.k, tick.x_hat, tick.u])
    got = [ln for ln in out if ln == "skip" or ln.startswith("tick")]
    assert len(got) == len(want)
    assert [g == "skip" for g in got] == [isinstance(w, str) for w in want]
    ticks = [np.array(g.split()[1:], dtype=float) for g in got if g != "skip"]
    ref = [w for w in want if not isinstance(w, str)]
    np.testing.assert_allclose(np.array(ticks), np.array(ref), rtol=0, atol=1e-9)
    skipped = dict(ln[len("skipped ") :].rsplit("|", 1) for ln in out if ln.startswith("skipped"))
    assert {k: int(v) for k, v in skipped.items()} == loop.skipped
    assert len(loop.skipped) >= 9  # every kind of mess above was seen
    assert loop.skipped["encoder sample with a zero header stamp (unstamped)"] == 2
    assert loop.skipped["encoder stamp behind the last one (a clock step back)"] == 2
    ahead = "encoder stamp ahead of its send time (a clock step or a corrupt stamp)"
    assert loop.skipped[ahead] == 1
    applied, rejected, enc_rejected = (int(x) for x in out[-1].split()[1:])
    c = loop.counters
    assert (applied, rejected) == (c["frames_applied"], c["frames_rejected"])
    assert enc_rejected == c["encoder_rejected"]


def test_c_live_loop_keeps_every_effort_before_a_late_first_sample(tmp_path: Path) -> None:
    """The first encoder sample arriving after 120 torque samples (a reader that matched the
    encoders' writer late, the efforts flowing meanwhile): the C loop keeps every one (it
    kept 64 and held the torque from tick 65 on, a false innovation hold of ``amsfe play``),
    so its estimates are the Python LiveLoop's on the same stream (1e-9), and those of the
    stream in its order (each torque before its sample), bit for bit."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.ros.arm import SimArm
    from amsfe_sym.ros.live import LiveLoop

    sc = load_scenario("paper-sim").with_overrides(duration=0.15)
    lib = library_for(sc)
    arm, T = SimArm(sc, lib), round(lib.T * 1e9)
    rng = np.random.default_rng(3)
    efforts, samples = [], []
    for k in range(arm.K):
        u = rng.uniform(-2.0, 2.0, lib.n)  # what the arm applied over tick k
        samples.append(("enc", EPOCH_NS + k * T, 1000 + 2 * k, arm.sense().z))
        efforts.append(("applied", EPOCH_NS + k * T, u))
        if k + 1 < arm.K:
            arm.advance(u)
    burst = efforts[:120] + [
        m for k, e in enumerate(samples) for m in (e, *efforts[120:][k : k + 1])
    ]
    in_order = [m for k in range(arm.K) for m in (efforts[k - 1], samples[k]) if k > 0]
    in_order = [samples[0], *in_order]

    def python(msgs: list[tuple[Any, ...]]) -> np.ndarray:
        loop, rows = LiveLoop(sc, lib, controller=True), []
        for m in msgs:
            if m[0] == "applied":
                loop.applied(m[1], np.array(m[2]))
            else:
                tick = loop.encoders(m[1], np.array(m[3]), m[2])
                assert tick is not None and tick.u is not None
                rows.append(np.r_[tick.k, tick.x_hat, tick.u])
        return np.array(rows)

    want = python(burst)
    np.testing.assert_array_equal(want[:, : 1 + lib.N], python(in_order)[:, : 1 + lib.N])
    out = _replay(tmp_path, sc, lib, burst)
    got = np.array([ln.split()[1:] for ln in out if ln.startswith("tick")], dtype=float)
    assert got.shape == want.shape == (arm.K, 1 + lib.N + lib.n)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert not [ln for ln in out if ln.startswith("skipped torque")], out[-5:]


@pytest.mark.parametrize(
    ("step_ns", "words"),
    [
        (None, "zero header stamp"),
        (3600 * 10**9, "ahead of its send time"),
        (-3 * 10**8, "a clock step back"),
    ],
)
def test_c_live_loop_holds_bad_stamps_by_name(
    tmp_path: Path, step_ns: int | None, words: str
) -> None:
    """More than max_gap_steps bad stamps in a row (issue 37): the C live loop stops with
    the Python LiveLoop's EstimatorError word for word (what the C node holds with), not as
    a stall; the samples before them are the same ticks."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.errors import EstimatorError
    from amsfe_sym.ros.live import LiveLoop
    from amsfe_sym.topics import TopicSpec

    sc = load_scenario("paper-sim").with_overrides(duration=0.1)
    lib = library_for(sc)
    T = round(lib.T * 1e9)
    z = np.zeros(2 * lib.n)
    msgs = []
    for k in range(40):  # a clock step at tick 30: every stamp after it is off
        stamp = EPOCH_NS + k * T
        if k >= 30:
            stamp = 0 if step_ns is None else stamp + step_ns
        msgs.append(("enc", stamp, 5 * 10**9 + k * T, z))
    loop = LiveLoop(sc, lib, controller=True)
    with pytest.raises(EstimatorError) as info:
        for m in msgs:
            loop.encoders(m[1], m[3], m[2])
    out = _replay(tmp_path, sc, lib, msgs)
    stop = [ln for ln in out if ln.startswith("stop")]
    assert stop == [f"stop -2 {info.value}"]
    assert words in stop[0] and "stalled" not in stop[0]
    assert sum(ln.startswith("tick") for ln in out) == 30
    assert out.count("skip") == TopicSpec().max_gap_steps  # then the hold


@pytest.mark.ros
@pytest.mark.slow
def test_c_node_sigterm_holds_and_records(tmp_path: Path) -> None:
    """SIGTERM to ``amsfe node --impl c`` alone (not its process group): it is forwarded to
    the C node, which publishes the hold command and says so; ``amsfe node`` exits 143 and
    its record is written, every tick's estimate with its command, the hold last."""
    import signal

    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs = []
    try:
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--impl", "c",
                      "--record", str(rec), *PATIENT_NODE)  # fmt: skip
        sim = _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "30",
                     "--command-timeout", "20")  # fmt: skip
        procs += [node, sim]
        sim.wait_for("t = 1.0 s", 90.0)
        os.kill(node.p.pid, signal.SIGTERM)
        assert node.p.wait(timeout=60.0) == 143, node.text
        sim.kill(signal.SIGTERM)
    finally:
        _finish(procs, 60.0)
    assert "node: hold: interrupted; hold command [" in node.text, node.text
    got = _bag(rec)
    assert len(got["/amsfe/estimate"]) == len(got["/effort_controller/commands"]) - 1 >= 1000


@pytest.mark.ros
@pytest.mark.slow
def test_c_node_managed(tmp_path: Path) -> None:
    """``amsfe node --impl c --managed``: rcl_lifecycle's services (change_state, get_state)
    take it to ``inactive`` and ``active``; then it closes the lockstep loop, every tick
    recorded, and ends at its duration (exit 0)."""
    from tests.test_ros import _lifecycle

    c_program_built("paper-sim")  # not inside the lifecycle client's wait for the service
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs = []
    try:
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--managed",
                      "--impl", "c", "--duration", "0.5", "--record", str(rec),
                      *PATIENT_NODE)  # fmt: skip
        procs.append(node)
        assert _lifecycle(env, "amsfe_node", "configure", "activate") == ["inactive", "active"]
        procs.insert(0, _start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "0.5",
                               *PATIENT_ARM))  # fmt: skip
    finally:
        results = _finish(procs, 120.0)
    for code, text in results:
        assert code == 0, text
    assert "the C node" in node.text and "waiting for configure and activate" in node.text
    assert len(_bag(rec)["/amsfe/estimate"]) == 501


#: ``rcl_send_response`` failing as Fast DDS's does when the client's response reader is not
#: matched yet (RCL_RET_TIMEOUT, nothing sent): the first $AMSFE_TEST_FAILED_SENDS calls of
#: the process (-1: every call), then rcl's own.  Preloaded into the C node.
_SEND_FAILS_C = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdint.h>
#include <stdlib.h>
typedef int32_t (*send_fn)(const void *, void *, void *);
static int failed;
int32_t rcl_send_response(const void *service, void *header, void *response) {
  static send_fn real;
  const char *n = getenv("AMSFE_TEST_FAILED_SENDS");
  int limit = n ? atoi(n) : 0;
  if (limit < 0 || failed < limit) {
    ++failed;
    return 2; /* RCL_RET_TIMEOUT */
  }
  if (!real) real = (send_fn)dlsym(RTLD_NEXT, "rcl_send_response");
  return real(service, header, response);
}
"""

#: One get_state request, its answer awaited 15 s; prints "answered" or "silent".
_ONE_GET_STATE = """
import sys
import rclpy
from lifecycle_msgs.srv import GetState

rclpy.init()
client = rclpy.create_node("lifecycle_once")
get = client.create_client(GetState, f"{sys.argv[1]}/get_state")
assert get.wait_for_service(timeout_sec=60.0)
fut = get.call_async(GetState.Request())
rclpy.spin_until_future_complete(client, fut, timeout_sec=15.0)
print("answered" if fut.result() is not None else "silent")
"""


@pytest.mark.ros
@pytest.mark.slow
def test_c_node_sends_a_lifecycle_response_again(tmp_path: Path) -> None:
    """A lifecycle response the middleware could not send (``rcl_send_response`` made to
    fail as Fast DDS's does before the client's reader is matched): the C node keeps it and
    sends it again, so configure and activate are answered at the client's first asking
    (no ask again) and the node runs its lockstep loop; one that can never be sent is dropped
    after 10 s with a line, and the node stops at Ctrl-C (130)."""
    from tests.test_ros import _LIFECYCLE_CLIENT

    c_program_built("paper-sim")
    shim = tmp_path / "send_fails.so"
    (tmp_path / "send_fails.c").write_text(_SEND_FAILS_C)
    cc = os.environ.get("CC", "cc")
    subprocess.run([cc, "-shared", "-fPIC", "-O1", "-o", str(shim), str(tmp_path / "send_fails.c"),
                    "-ldl"], check=True)  # fmt: skip
    for fails in ("3", "-1"):
        env = {**_ros_env(tmp_path), "LD_PRELOAD": str(shim), "AMSFE_TEST_FAILED_SENDS": fails}
        procs = []
        try:
            node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--managed",
                          "--impl", "c", *PATIENT_NODE)  # fmt: skip
            procs.append(node)
            name = f"{env[_PREFIX]}/amsfe_node"
            clean = {k: v for k, v in env.items() if k not in ("LD_PRELOAD",)}
            if fails == "3":  # configure's answer fails 3 times, then goes
                done = subprocess.run(
                    [sys.executable, "-c", _LIFECYCLE_CLIENT, name, "configure", "activate"],
                    env=clean, capture_output=True, text=True, timeout=300,
                )  # fmt: skip
                assert done.returncode == 0, done.stderr
                assert json.loads(done.stdout.strip().splitlines()[-1]) == ["inactive", "active"]
                assert "no answer" not in done.stderr, done.stderr  # sent again, not asked
            else:  # never sent: dropped after 10 s
                done = subprocess.run(
                    [sys.executable, "-c", _ONE_GET_STATE, name],
                    env=clean, capture_output=True, text=True, timeout=300,
                )  # fmt: skip
                assert done.returncode == 0, done.stderr
                assert done.stdout.strip().splitlines()[-1] == "silent"
                node.wait_for("response to a lifecycle get_state not delivered", 60.0)
            node.kill(signal.SIGINT)
        finally:
            results = _finish(procs, 60.0)
        assert results[0][0] == 130, results[0][1]
        dropped = "not delivered (its client's reader not matched within 10 s): dropped"
        assert (dropped in node.text) == (fails == "-1"), node.text


#: A client on the test's domain: an rclpy lifecycle node of its own (the reference) and the
#: node named in argv[1]; each asked what ``ros2 lifecycle list`` asks (get_available_states,
#: get_available_transitions; and ``list --all``'s get_transition_graph) unconfigured, then
#: both configured and asked again: one JSON line {"ref": [...], "node": [...]}.
_INTROSPECTION_CLIENT = """
import json, sys, threading
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetAvailableStates, GetAvailableTransitions, GetState

rclpy.init()
ref = LifecycleNode("amsfe_lifecycle_reference")
client = rclpy.create_node("lifecycle_introspection")
ex = SingleThreadedExecutor()
ex.add_node(ref)
spinner = threading.Thread(target=ex.spin, daemon=True)
spinner.start()

def call(name, srv, req):
    # asked again when no answer comes in 10 s: a response is lost when the server's writer
    # has not matched this client's reader yet (Fast DDS waits 100 ms), as on a loaded machine
    c = client.create_client(srv, name)
    assert c.wait_for_service(timeout_sec=60.0), name
    for _ in range(6):
        fut = c.call_async(req)
        rclpy.spin_until_future_complete(client, fut, timeout_sec=10.0)
        if fut.result() is not None:
            return fut.result()
        print(f"{name}: no answer in 10 s, asked again", file=sys.stderr)
    raise AssertionError(name)

def ask(node):
    states = call(f"{node}/get_available_states", GetAvailableStates, GetAvailableStates.Request())
    out = {"states": [(s.id, s.label) for s in states.available_states]}
    for what in ("get_available_transitions", "get_transition_graph"):
        r = call(f"{node}/{what}", GetAvailableTransitions, GetAvailableTransitions.Request())
        out[what] = [(t.transition.id, t.transition.label, t.start_state.id,
                      t.start_state.label, t.goal_state.id, t.goal_state.label)
                     for t in r.available_transitions]
    return out

nodes = {"ref": "/amsfe_lifecycle_reference", "node": sys.argv[1]}
got = {k: [ask(v)] for k, v in nodes.items()}
for k, v in nodes.items():
    req = ChangeState.Request()
    req.transition.id = Transition.TRANSITION_CONFIGURE
    # once: a second configure would be refused; a lost answer is told by the state
    c = client.create_client(ChangeState, f"{v}/change_state")
    assert c.wait_for_service(timeout_sec=60.0), k
    fut = c.call_async(req)
    rclpy.spin_until_future_complete(client, fut, timeout_sec=30.0)
    if fut.result() is not None:
        assert fut.result().success, k
    else:
        now = call(f"{v}/get_state", GetState, GetState.Request()).current_state.label
        assert now == "inactive", (k, now)
    got[k].append(ask(v))
print(json.dumps(got), flush=True)
ex.shutdown()
spinner.join(timeout=10.0)
rclpy.shutdown()
"""


@pytest.mark.ros
@pytest.mark.slow
def test_c_node_lifecycle_introspection_is_rclpy_s(tmp_path: Path) -> None:
    """``amsfe node --impl c --managed`` answers what ``ros2 lifecycle list`` asks
    (get_available_states, get_available_transitions; get_transition_graph for ``--all``)
    with what an rclpy lifecycle node answers over DDS, unconfigured and configured."""
    env = _ros_env(tmp_path)
    procs = []
    try:
        node = _start(env, "node", "paper-sim", "--controller", "amsfe", "--managed",
                      "--impl", "c", *PATIENT_NODE)  # fmt: skip
        procs.append(node)
        done = subprocess.run(
            [sys.executable, "-c", _INTROSPECTION_CLIENT, f"{env[_PREFIX]}/amsfe_node"],
            env=env, capture_output=True, text=True, timeout=150,
        )  # fmt: skip
        node.kill(signal.SIGTERM)
    finally:
        _finish(procs, 60.0)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["node"] == got["ref"], got
    unconfigured, inactive = got["node"]
    assert ("unconfigured" in {s[1] for s in unconfigured["states"]}) and len(
        unconfigured["states"]
    ) >= 10
    assert {t[1] for t in unconfigured["get_available_transitions"]} >= {"configure", "shutdown"}
    assert {t[1] for t in inactive["get_available_transitions"]} >= {"activate", "cleanup"}
    assert len(inactive["get_transition_graph"]) > len(inactive["get_available_transitions"])


def test_what_the_c_node_refuses_and_its_queues() -> None:
    """``--impl auto`` picks the Python node, saying why, for what the C node does not run
    (an effort kind other than ``applied``, ``--runtime python``); the C node's queues hold
    the samples of the lag it catches up from at the rates: min(encoder_timeout, 2 s) of
    encoder samples, and of frames plus the camera's delay (never fewer than qos.depth)."""
    from dataclasses import replace

    from amsfe_sym.ros.cnode import c_node_refusal, queue_depths
    from amsfe_sym.topics import TopicSpec

    sc = load_scenario("paper-sim")
    spec = TopicSpec()
    assert c_node_refusal(sc, spec, managed=True, controller=True) is None
    assert "joint_torque" in str(
        c_node_refusal(sc, replace(spec, effort_kind="joint_torque"), False)
    )
    assert "--runtime python" in str(c_node_refusal(sc, spec, False, True, compiled=False))
    small = replace(spec, depth=10)
    assert queue_depths(small, 1e-3, 10, 5, 0.5) == (501, 53)  # ceil(0.505 / 0.01) + 2
    assert queue_depths(small, 1e-3, 10, 5, 20.0) == (2001, 203)  # the lag capped at 2 s
    assert queue_depths(spec, 1e-3, 10, 5, 0.05) == (100, 100)  # qos.depth is the least
