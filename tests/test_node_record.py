"""``amsfe node --record`` with the effort on the encoders' topic (a driver's
``/joint_states``: position, velocity and effort in one JointState, docs/how-to/ros.md): the record
writes one JointState a tick with all three, as the arm sent it, and the log reader gives
back, bit for bit, the samples and the effort the node recorded (no sample skipped)."""

from __future__ import annotations

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
