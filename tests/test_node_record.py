"""``amsfe node --record`` (ros/record.py).

With the effort on the encoders' topic (a driver's ``/joint_states``: position, velocity and
effort in one JointState, docs/how-to/ros.md): the record writes one JointState a tick with all
three, as the arm sent it, and the log reader gives back, bit for bit, the samples and the
effort the node recorded (no sample skipped).  Streamed (issue 37 item 7): written in segments
with bounded memory, equal to the record written at the end, readable and marked unfinished
after a SIGKILL; one writer a path (item 2); each tick's truth its own (issue 34 item 5).
:func:`assert_record_is_run` compares every topic of a record with ``amsfe simulate``: used
by the lockstep tests over DDS (tests/test_ros.py)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.logs.read import read_log
from amsfe_sym.ros.record import NodeRecord
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.topics import read_topic_spec

SRC = Path(__file__).resolve().parent.parent / "src"
LOCK = ".amsfe-record.lock"


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=0.2)
    lib = library_for(sc)
    return sc, lib, run(sc, lib, runtime="compiled")


def _bag(path: Path) -> dict[str, list[Any]]:
    from rosbags.highlevel import AnyReader

    from amsfe_sym.logs.source import typestore

    topics: dict[str, list[Any]] = {}
    with AnyReader([path], default_typestore=typestore()) as r:
        for c, _t, raw in r.messages():
            topics.setdefault(c.topic, []).append(r.deserialize(raw, c.msgtype))
    return topics


def _spec(folder: Path, kind: str, shared: str | None) -> Any:
    """A topic spec with effort ``kind`` and the effort on the topic ``shared`` with the
    encoders (None: on its own, the default ``/motor_torque``)."""
    path = folder / "spec.toml"
    topics = f'[topics]\nencoders = "{shared}"\neffort = "{shared}"\n' if shared else ""
    path.write_text(f'{topics}[effort]\nkind = "{kind}"\n')
    return read_topic_spec(path)


def _record(paper: Any, spec: Any, kind: str, tau: np.ndarray) -> NodeRecord:
    """The calls of :class:`amsfe_sym.ros.node` for each tick, in its order: the effort of
    kind ``joint_torque`` or ``applied`` before the tick's outputs, the command of kind
    ``none`` (the node's controller) after them."""
    sc, lib, res = paper
    rec = NodeRecord(sc, lib, spec, lib.manifest.joints)
    T = round(lib.T * 1e9)
    for k in range(res.t.size):
        ns = k * T
        if kind != "none":
            rec.applied(ns, tau[k])
        rec.encoders(ns, res.z_enc[k])
        rec.truth(ns, res.x_true[k])
        theta = res.x_hat[k, 4 * lib.n :]
        rec.outputs(ns, res.x_hat[k], np.zeros(lib.N), theta, res.u[k])
        if kind == "none":
            rec.applied(ns, tau[k])
    rec.hold((res.t.size - 1) * T, np.zeros(lib.n))
    return rec


#: Where the effort is: on the encoders' default topic, on a driver's ``/joint_states``
#: (where a simulated arm's true q, qd would go too: not written there), on its own.
SHARED = ["/motor_encoders", "/joint_states", None]


@pytest.mark.parametrize("shared", SHARED)
@pytest.mark.parametrize("kind", ["applied", "joint_torque", "none"])
def test_a_record_reads_back_the_samples_and_effort_put_in(
    paper: Any, tmp_path: Path, kind: str, shared: str | None
) -> None:
    """Effort on the encoders' topic (``shared``): one JointState a tick on it, with the
    sample's position and velocity and the tick's effort; on a topic of its own: an
    effort-only JointState there, as before.  Read back with the spec, the encoder samples
    and the effort held on the ticks equal those recorded, bit for bit, none skipped."""
    _, lib, res = paper
    n, K = lib.n, res.t.size
    spec = _spec(tmp_path, kind, shared)
    tau = np.random.default_rng(3).standard_normal((K, n))  # unlike any other column
    path = _record(paper, spec, kind, tau).write(tmp_path / "rec")
    bag = _bag(path)
    enc = bag[spec.encoders]
    stamps = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in enc]
    assert stamps == [k * round(lib.T * 1e9) for k in range(K)]  # one message a tick
    got_z = np.array([np.r_[m.position, m.velocity] for m in enc])
    assert np.array_equal(got_z, res.z_enc)
    got_tau = np.array([m.effort for m in (enc if shared else bag[spec.effort])])
    assert np.array_equal(got_tau, tau)
    if not shared:
        assert all(m.effort.size == 0 for m in enc)
        assert all(m.position.size == m.velocity.size == 0 for m in bag[spec.effort])
    read_as = kind if kind != "none" else "applied"  # none: the reader would not read it
    log = read_log(path, _spec(tmp_path, read_as, shared), lib.manifest.joints, lib.T, lib.N)
    assert log.z.shape == (K, 2 * n) and np.array_equal(log.z, res.z_enc)
    assert log.effort is not None and np.array_equal(log.effort, tau)
    assert not log.usage["encoders"].skipped and not log.usage["effort"].skipped
    assert log.usage["encoders"].used == log.usage["effort"].used == K
    assert log.truth is not None and np.array_equal(log.truth, res.x_true)


def test_an_effort_without_its_sample_is_kept_effort_only(paper: Any, tmp_path: Path) -> None:
    """An effort whose sample the live loop skipped (off the grid: no encoder row of its
    stamp) is written as today, an effort-only JointState of its stamp, not dropped nor put
    into another tick's sample."""
    _, lib, res = paper
    spec = _spec(tmp_path, "joint_torque", "/motor_encoders")
    tau = np.random.default_rng(4).standard_normal((res.t.size, lib.n))
    rec = _record(paper, spec, "joint_torque", tau)
    off = round(2.5 * lib.T * 1e9)
    rec.applied(off, tau[0] + 1.0)
    enc = _bag(rec.write(tmp_path / "rec"))[spec.encoders]
    alone = [m for m in enc if m.position.size == 0]
    assert len(enc) == res.t.size + 1 and len(alone) == 1
    assert alone[0].header.stamp.nanosec == off and np.array_equal(alone[0].effort, tau[0] + 1)
    assert all(m.effort.size == lib.n for m in enc)


# ------------------------------------------------------------- streamed, one writer, its tick
def _fill(paper: Any, rec: NodeRecord, ticks: int | None = None) -> None:
    """The node's calls for each tick of ``paper``'s run, the truth matched by the source
    timestamps (sample k sent at 10 k + 5; the truth of k sent at 10 k + 1, delivered
    before its sample on even ticks, after it on odd ones, as DDS may)."""
    res = paper[2]
    for k in range(res.t.size if ticks is None else ticks):
        _fill_tick(paper, rec, k)


def test_a_streamed_record_is_the_record_in_memory(paper: Any, tmp_path: Path) -> None:
    """Written in segments of 30 ticks while it runs (its memory bounded by them), the record
    reads back as one bag with every message of the record written at the end, the truth of
    each tick its own whatever the delivery order; its metadata says finished, and why."""
    from amsfe_sym.ros.record import LAG_TICKS
    from amsfe_sym.ros.record_bag import record_state
    from amsfe_sym.topics import TopicSpec

    sc, lib, res = paper
    whole = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints)
    _fill(paper, whole)
    one = whole.write(tmp_path / "one", reason="done: 201 ticks")
    streamed = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, tmp_path / "s", 30)
    most = 0
    for k in range(res.t.size):  # tick by tick, to watch the rows held
        _fill_tick(paper, streamed, k)
        most = max(most, len(streamed._rows))
    assert most <= (30 + LAG_TICKS + 1) * 12  # (12 rows a tick at most here)
    assert streamed._bag is not None
    deadline = time.monotonic() + 120.0  # (bounded: the writer thread writes them)
    while streamed._bag._written < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(list((tmp_path / "s").glob("*.mcap"))) >= 2  # written on the way
    path = streamed.write(reason="hold: tracking: test")
    a, b = _bag(one), _bag(path)
    assert sorted(a) == sorted(b)
    for topic in a:
        assert len(a[topic]) == len(b[topic]), topic
        for ma, mb in zip(a[topic], b[topic], strict=True):
            assert repr(ma) == repr(mb), topic
    truth = np.array([m.data for m in b["/amsfe/truth"]])
    assert np.array_equal(truth, res.x_true)
    assert record_state(path) == {
        "amsfe.record": "finished",
        "amsfe.end": "hold: tracking: test",
        "amsfe.writer_pid": str(os.getpid()),
        "amsfe.truth_missing": "0",
    }
    assert not (path / LOCK).exists()


def _fill_tick(paper: Any, rec: NodeRecord, k: int) -> None:
    _, lib, res = paper
    ns = k * round(lib.T * 1e9)
    rec.applied(ns, res.u[k])
    if k % 2 == 0:
        rec.truth_sent(10 * k + 1, res.x_true[k])
    rec.encoders(ns, res.z_enc[k], 10 * k + 5)
    if k % 2 == 1:
        rec.truth_sent(10 * k + 1, res.x_true[k])
    rec.outputs(ns, res.x_hat[k], np.zeros(lib.N), res.x_hat[k, 4 * lib.n :], res.u[k])


def test_a_truth_that_never_comes_leaves_its_tick_without_one(paper: Any, tmp_path: Path) -> None:
    """No tick gets another tick's truth: a lost one is missing and counted."""
    from amsfe_sym.ros.record_bag import record_state
    from amsfe_sym.topics import TopicSpec

    sc, lib, res = paper
    rec = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, tmp_path / "r")
    T = round(lib.T * 1e9)
    for k in range(20):
        if k != 7:
            rec.truth_sent(10 * k + 1, res.x_true[k])
        rec.encoders(k * T, res.z_enc[k], 10 * k + 5)
        rec.outputs(k * T, res.x_hat[k], np.zeros(lib.N), res.x_hat[k, 4 * lib.n :], None)
    bag = _bag(rec.write(reason="done"))
    assert len(bag["/amsfe/truth"]) == 19
    want = np.delete(res.x_true[:20], 7, axis=0)
    assert np.array_equal(np.array([m.data for m in bag["/amsfe/truth"]]), want)
    assert record_state(tmp_path / "r")["amsfe.truth_missing"] == "1"


_KILLED = """
import os, signal, sys, time
import numpy as np
from amsfe_sym.codegen import library_for
from amsfe_sym.ros.record import NodeRecord
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.topics import TopicSpec
sc = load_scenario("paper-sim").with_overrides(duration=0.2)
lib = library_for(sc)
res = run(sc, lib, runtime="compiled")
rec = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, sys.argv[1], 40)
T = round(lib.T * 1e9)
for k in range(res.t.size):
    rec.truth_sent(10 * k + 1, res.x_true[k])
    rec.encoders(k * T, res.z_enc[k], 10 * k + 5)
    rec.outputs(k * T, res.x_hat[k], np.zeros(lib.N), res.x_hat[k, 4 * lib.n:], res.u[k])
while rec._bag._written < 2:  # two segments on disk (the writer thread's), then the kill
    time.sleep(0.01)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_killed_writer_leaves_a_readable_unfinished_record(paper: Any, tmp_path: Path) -> None:
    """SIGKILL of the writer: the record reads back (``amsfe estimate``'s reader) up to its
    last segment, bit for bit, marked unfinished; its path is then refused to a new writer
    in one line naming the dead process, and nothing of it is removed."""
    import signal
    import subprocess
    import sys

    from amsfe_sym.errors import RunFolderError
    from amsfe_sym.ros.record_bag import LOCK, record_state
    from amsfe_sym.topics import TopicSpec

    sc, lib, res = paper
    out = tmp_path / "rec"
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    done = subprocess.run(
        [sys.executable, "-c", _KILLED, str(out)], env=env, capture_output=True, timeout=300
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    state = record_state(out)
    assert state["amsfe.record"] == "unfinished" and "amsfe.end" not in state
    log = read_log(out, read_topic_spec(None), lib.manifest.joints, lib.T, lib.N)
    K = log.z.shape[0]
    assert 40 <= K < res.t.size  # the segments written before the kill, not the rest
    assert np.array_equal(log.z, res.z_enc[:K])
    assert log.truth is not None and np.array_equal(log.truth, res.x_true[:K])
    before = sorted(p.name for p in out.iterdir())
    with pytest.raises(RunFolderError) as err:
        NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, out)
    pid = (out / LOCK).read_text().split()[0]
    assert "\n" not in str(err.value) and f"unfinished record of process {pid}" in str(err.value)
    assert sorted(p.name for p in out.iterdir()) == before


def test_a_second_writer_is_refused_before_it_starts(paper: Any, tmp_path: Path) -> None:
    """One record path, one writer: a second record (in process) and a second
    ``amsfe node --record`` of the same path (exit 2, before rclpy) are refused in one line
    naming the writer's pid; the first writes on, unharmed."""
    import subprocess
    import sys

    from amsfe_sym.errors import RunFolderError
    from amsfe_sym.topics import TopicSpec

    sc, lib, _ = paper
    out = tmp_path / "rec"
    first = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, out)
    with pytest.raises(RunFolderError) as err:
        NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, out)
    assert f"being written there by process {os.getpid()}" in str(err.value)
    block = (
        "import sys; sys.modules['rclpy'] = None; from amsfe_sym.apps.cli import main; "
        f"sys.exit(main(['node', 'paper-sim', '--record', {str(out)!r}]))"
    )
    # the lock names this (live) test process: the node must refuse it as a writer at work
    node = subprocess.run(
        [sys.executable, "-c", block], env={**os.environ, "PYTHONPATH": str(SRC)},
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert node.returncode == 2, node.stderr
    lines = [x for x in node.stderr.splitlines() if x.startswith("error:")]
    assert len(lines) == 1 and f"process {os.getpid()}" in lines[0], node.stderr
    _fill(paper, first, 10)
    bag = _bag(first.write(reason="done"))
    assert len(bag["/amsfe/estimate"]) == 10


def assert_record_is_run(bag: dict[str, list[Any]], res: Any, tol: float = 1e-9) -> None:
    """Every topic of a node's record (``bag``: :func:`_bag`) against the run ``res`` of
    ``amsfe simulate`` (compiled loop) of the same scenario and seed, tick by tick: stamps,
    encoder samples, frames (exposure stamp, pixel, the tick that fused them), applied torque,
    truth and ``/joint_states``, estimate, its standard deviations, theta, commands (then
    the hold), diagnostics, ``/tf`` (true and estimated arms) and the config."""
    from amsfe_sym.logs.write import TF_RATE_HZ

    lib = res.lib
    n, K, T = lib.n, res.t.size, round(lib.T * 1e9)

    def stamps(msgs: list[Any]) -> list[int]:
        return [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs]

    def close(a: Any, b: Any, what: str) -> None:
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        assert a.shape == b.shape, (what, a.shape, b.shape)
        np.testing.assert_allclose(a, b, rtol=0, atol=tol, err_msg=what)

    ticks = [k * T for k in range(K)]
    enc = bag["/motor_encoders"]
    assert stamps(enc) == ticks
    close([np.r_[m.position, m.velocity] for m in enc], res.z_enc, "encoders")
    eff = bag["/motor_torque"]  # (the last tick's: the arm sends it after the last command,
    # when a node that stops at its duration may be gone: over [t_K-1, t_K], after the run)
    assert stamps(eff) in (ticks, ticks[:-1])
    close([m.effort for m in eff], res.u[: len(eff)], "applied torque")
    close([m.data for m in bag["/amsfe/truth"]], res.x_true, "truth")  # every tick its own
    js = bag["/joint_states"]
    assert stamps(js) == ticks
    close([np.r_[m.position, m.velocity] for m in js], res.x_true[:, : 2 * n], "joint_states")
    est = bag["/amsfe/estimate"]
    assert stamps(est) == ticks
    close([np.r_[m.position, m.velocity] for m in est], res.x_hat[:, : 2 * n], "estimate")
    std = bag["/amsfe/estimate_std"]
    assert stamps(std) == ticks
    want_std = np.sqrt(np.maximum(res.P_diag[:, : 2 * n], 0.0))
    close([np.r_[m.position, m.velocity] for m in std], want_std, "estimate_std")
    close([m.data for m in bag["/amsfe/theta"]], res.x_hat[:, 4 * n :], "theta")
    cmd = [m.data for m in bag["/effort_controller/commands"]]
    assert len(cmd) == K + 1  # the hold last
    close(cmd[:-1], res.u, "commands")
    cam = bag["/camera/marker"]
    frames = res.frames[np.argsort(res.frames[:, 1], kind="stable")]
    assert len(cam) == len(frames) == res.counters["frames_delivered"] > 0
    assert stamps(cam) == [round(kappa) * T for kappa in frames[:, 0]]
    close([[m.point.x, m.point.y] for m in cam], frames[:, 2:], "camera pixels")
    diag = json.loads(bag["/amsfe/diagnostics"][-1].data)
    assert diag["frames_fused"] == res.counters["frames_applied"]
    assert diag["frames_refused"] == res.counters["frames_rejected"]
    config = json.loads(bag["/amsfe/config"][0].data)
    assert config["estimator"] == res.scenario.estimator and config["T"] == lib.T
    every = max(1, round(1.0 / (TF_RATE_HZ * lib.T)))
    tf = bag["/tf"]
    assert [m.transforms[0].header.stamp.nanosec for m in tf] == [
        k * T % 1_000_000_000 for k in range(0, K, every)
    ]
    for m in tf:  # the true arm's links and the estimated arm's, both
        names = [tr.child_frame_id for tr in m.transforms]
        assert len(names) % 2 == 0 and names[len(names) // 2 :] == [
            "est/" + x for x in names[: len(names) // 2]
        ]
