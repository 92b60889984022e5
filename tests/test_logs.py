"""Robot logs (docs/how-to/logs.md): a simulated run written as a rosbag2 and estimated back equals
the loop's own estimates; bags written independently with ``rosbags``' writer (jittered,
reordered, dropped, duplicated and broken frames, encoder gaps, missing topics, wrong types,
truncated files) are estimated as the estimator fed the same inputs directly, or refused with
one line and nothing left behind."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.apps.estimate import EstimateOptions, estimate_command
from amsfe_sym.codegen import library_for
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import LogError
from amsfe_sym.logs.source import typestore
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing
from amsfe_sym.sim.loop import run

ESTIMATORS = ("encoders", "naive", "oosm", "replay", "cloning")


def joint_state(
    t: float,
    names: list[str],
    position: np.ndarray | None = None,
    velocity: np.ndarray | None = None,
    effort: np.ndarray | None = None,
) -> Any:
    """A ``sensor_msgs/msg/JointState`` stamped ``t`` [s], built from rosbags' own types (as
    the message-by-message writer built it; None: an empty field)."""
    types = typestore().types
    sec, nanosec = divmod(round(t * 1e9), 1_000_000_000)
    stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    empty = np.zeros(0)
    return types["sensor_msgs/msg/JointState"](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
        name=list(names),
        position=np.asarray(position if position is not None else empty, dtype=np.float64),
        velocity=np.asarray(velocity if velocity is not None else empty, dtype=np.float64),
        effort=np.asarray(effort if effort is not None else empty, dtype=np.float64),
    )


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """One 1 s paper-sim run per estimator (compiled loop) and its bag."""
    out = {}
    root = tmp_path_factory.mktemp("bags")
    for name in ESTIMATORS:
        sc = load_scenario("paper-sim").with_overrides(
            estimator=name, controller="amsfe", duration=1.0, seed=3
        )
        res = run(sc, library_for(sc), runtime="compiled")
        out[name] = (res, write_run_bag(res, root / name))
    return out


@pytest.mark.parametrize("name", ESTIMATORS)
def test_round_trip_equals_the_loop(name: str, sim, tmp_path) -> None:
    res, bag = sim[name]
    est = estimate_command(bag, tmp_path / "est", EstimateOptions(plots=False)).estimate
    assert est.x_hat.shape == res.x_hat.shape
    assert np.max(np.abs(est.x_hat - res.x_hat)) <= 1e-12
    assert np.max(np.abs(est.P_diag - res.P_diag)) <= 1e-12
    assert est.counters["frames_applied"] == res.counters["frames_applied"]
    assert (tmp_path / "est" / "estimates" / "estimates.mcap").is_file()


def test_a_plain_mcap_file_reads_as_its_folder(sim, tmp_path) -> None:
    _, bag = sim["oosm"]
    a = estimate_command(bag, tmp_path / "a", EstimateOptions(plots=False)).estimate
    b = estimate_command(bag / f"{bag.name}.mcap", tmp_path / "b", EstimateOptions(plots=False))
    assert np.array_equal(a.x_hat, b.estimate.x_hat)


# ---------------------------------------------------------------------- bags made by hand
def _write(
    path: Path,
    res,
    frames,
    drop_encoder=(),
    encoder_type=None,
    camera_type=None,
    with_torque=True,
    storage="mcap",
) -> Path:
    """A bag from ``res``'s encoder and torque records with the camera ``frames`` given as
    (exposure step, arrival time [s], u, v), written with rosbags' own writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = typestore()
    T, n = res.lib.T, res.lib.n
    joints = list(res.lib.manifest.joints)
    events = []
    for k, t in enumerate(res.t):
        if k not in drop_encoder:
            events.append(
                (t, "/motor_encoders", joint_state(t, joints, res.z_enc[k, :n], res.z_enc[k, n:]))
            )
        if with_torque:
            events.append((t, "/motor_torque", joint_state(t, joints, effort=res.u[k])))
    P = ts.types["geometry_msgs/msg/PointStamped"]
    for kappa, arrive, pu, pv in frames:
        hdr = joint_state(kappa * T, []).header
        events.append(
            (
                arrive,
                "/camera/marker",
                P(header=hdr, point=ts.types["geometry_msgs/msg/Point"](x=pu, y=pv, z=0.0)),
            )
        )
    events.sort(key=lambda e: e[0])
    types = {
        "/motor_encoders": encoder_type or "sensor_msgs/msg/JointState",
        "/motor_torque": "sensor_msgs/msg/JointState",
        "/camera/marker": camera_type or "geometry_msgs/msg/PointStamped",
    }
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {}
        for t, topic, msg in events:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, types[topic], typestore=ts)
            real = msg.__msgtype__
            w.write(conns[topic], round(t * 1e9), ts.serialize_cdr(msg, real))
    return path


def _direct(res, frames_by_arrival, skip_z=()):
    """The compiled estimator fed the same inputs directly: x(k|k) per tick."""
    sc, lib = res.scenario, res.lib
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    est = build_estimator(sc, lib, sensors, res.z_enc[0], compiled=True)
    xs = [est.x.copy()]
    for k in range(1, len(res.t)):
        z = None if k in skip_z else res.z_enc[k]
        est.step(res.u[k - 1], z, frames_by_arrival.get(k, []))
        xs.append(est.x.copy())
    return np.array(xs)


def test_hand_made_bag_needs_a_scenario_and_then_matches_the_direct_run(sim, tmp_path) -> None:
    res, _ = sim["oosm"]
    T = res.lib.T
    pix = {int(f[0]): (f[2], f[3]) for f in res.frames}
    exposures = sorted(pix)
    rng = np.random.default_rng(1)
    frames, expected = [], defaultdict(list)
    for i, kappa in enumerate(exposures):
        if i == 1:
            continue  # dropped
        arrive_k = min(kappa + int(rng.integers(20, 300)), len(res.t) - 1)
        frames.append((kappa, arrive_k * T - 0.2 * T, *pix[kappa]))
        expected[arrive_k].append(CameraFrame(kappa, np.array(pix[kappa]), arrive_k))
    frames.append((exposures[0], 0.95, *pix[exposures[0]]))  # duplicate exposure
    frames.append((exposures[-1] + 1, 0.96, np.nan, 1.0))  # NaN pixel
    gap = {500, 501, 502}  # three encoder samples missing: predicted through
    bag = _write(tmp_path / "bag", res, frames, drop_encoder=gap)
    with pytest.raises(LogError, match="--scenario"):
        estimate_command(bag, tmp_path / "x", EstimateOptions(plots=False))
    assert not (tmp_path / "x").exists()
    scen = tmp_path / "scenario.toml"
    from amsfe_sym.core.toml import dump_toml

    scen.write_text(dump_toml(res.scenario.to_dict()))
    got = estimate_command(bag, tmp_path / "est", EstimateOptions(scenario=str(scen), plots=False))
    ref = _direct(res, expected, skip_z=gap)
    assert np.max(np.abs(got.estimate.x_hat - ref)) <= 1e-12
    c = got.estimate.counters
    assert c["frame duplicated (an exposure already seen)"] == 1
    assert c["frame with a non-finite pixel"] == 1
    assert c["encoder samples missing (predicted through)"] == 3
    assert c["frames_applied"] == len(exposures) - 1


def test_refusals_are_one_line_and_leave_nothing(sim, tmp_path, capsys) -> None:
    from amsfe_sym.core.toml import dump_toml

    res, good = sim["oosm"]
    scen = tmp_path / "scenario.toml"
    scen.write_text(dump_toml(res.scenario.to_dict()))
    one = [(int(res.frames[0][0]), 0.5, res.frames[0][2], res.frames[0][3])]
    cases = {
        "no torque": _write(tmp_path / "a", res, one, with_torque=False),
        "wrong type": _write(tmp_path / "b", res, one, camera_type="std_msgs/msg/String"),
        "long gap": _write(tmp_path / "c", res, one, drop_encoder=set(range(100, 120))),
    }
    mcap = tmp_path / "trunc.mcap"
    data = (good / f"{good.name}.mcap").read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    cases["truncated"] = mcap
    # the effort said to be the applied torque: a log without it is refused (without a
    # spec, a log without effort is an encoders-only log: docs/reference/topics.md)
    spec = tmp_path / "spec.toml"
    spec.write_text('[effort]\nkind = "applied"\n')
    for what, bag in cases.items():
        out = tmp_path / f"out-{what.replace(' ', '_')}"
        args = ["estimate", str(bag), "--out", str(out), "--no-plots", "--scenario", str(scen)]
        code = main([*args, "--log-spec", str(spec)])
        err = capsys.readouterr().err.strip()
        assert code == 2, what
        assert err.startswith("error:") and "\n" not in err, (what, err)
        assert not out.exists(), what


def test_sqlite3_storage_and_a_frame_older_than_the_history(sim, tmp_path) -> None:
    """A rosbag2 in sqlite3 storage (the default before ROS 2 Iron) reads like MCAP; a frame
    that arrives later than the estimator's history is refused by the estimator and counted,
    the others fused as by the estimator fed directly."""
    from amsfe_sym.core.toml import dump_toml

    res, _ = sim["oosm"]
    sc = res.scenario
    scen = tmp_path / "scenario.toml"
    scen.write_text(dump_toml(sc.to_dict()))
    T, buffer = res.lib.T, sc.filter.buffer_steps
    pix = {int(f[0]): (f[2], f[3]) for f in res.frames}
    exposures = sorted(pix)
    late = exposures[0]  # delivered after buffer_steps + 5 steps: older than the history
    frames, expected = [], defaultdict(list)
    for kappa in exposures:
        arrive_k = kappa + (buffer + 5 if kappa == late else 125)
        if arrive_k >= len(res.t):
            continue
        frames.append((kappa, arrive_k * T, *pix[kappa]))
        expected[arrive_k].append(CameraFrame(kappa, np.array(pix[kappa]), arrive_k))
    bag = _write(tmp_path / "bag", res, frames, storage="sqlite3")
    assert any(p.suffix == ".db3" for p in bag.iterdir())
    got = estimate_command(bag, tmp_path / "est", EstimateOptions(scenario=str(scen), plots=False))
    assert np.max(np.abs(got.estimate.x_hat - _direct(res, expected))) <= 1e-12
    c = got.estimate.counters
    assert c["refused_too_late"] == 1 and c["frames_applied"] == len(frames) - 1


def _raw(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """(log time [ns], payload) per topic, as rosbags' reader gives them."""
    from rosbags.rosbag2 import Reader

    out: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
    with Reader(bag) as r:
        for conn, t, raw in r.messages():
            out[conn.topic].append((t, bytes(raw)))
    return out


def test_joint_state_topics_equal_rosbags_one_by_one(sim) -> None:
    """The bag's JointState topics (serialized in bulk, logs/encode.py) hold the bytes and log
    times of the message-by-message writer: rosbags' serialize_cdr of joint_state(...)."""
    res, bag = sim["oosm"]
    ts, n = typestore(), res.lib.n
    joints = list(res.lib.manifest.joints)
    raw = _raw(bag)

    def ref(t: float, **fields) -> tuple[int, bytes]:
        msg = joint_state(t, joints, **fields)
        return round(t * 1e9), bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))

    z, x, xh = res.z_enc, res.x_true, res.x_hat
    want = {
        "/motor_encoders": [
            ref(t, position=z[k, :n], velocity=z[k, n:]) for k, t in enumerate(res.t)
        ],
        "/motor_torque": [ref(t, effort=res.u[k]) for k, t in enumerate(res.t)],
        "/joint_states": [
            ref(t, position=x[k, :n], velocity=x[k, n : 2 * n]) for k, t in enumerate(res.t)
        ],
        "/amsfe/estimate": [
            ref(t, position=xh[k, :n], velocity=xh[k, n : 2 * n]) for k, t in enumerate(res.t)
        ],
    }
    for topic, messages in want.items():
        assert raw[topic] == messages, topic
