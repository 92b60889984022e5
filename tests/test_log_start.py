"""Where ``amsfe estimate LOG --robot ROBOT`` starts the links (docs/how-to/logs.md, "Where the
estimate starts"; issue 26): a log of effort kind ``none`` gives motor angles only, and on
the paper's soft arm the springs deflect 1.45 rad under gravity.  The start is the springs'
balance at the first sample, chosen by the first camera frame
(:mod:`amsfe_sym.estimation.static_start`).

References: a pendulum whose balances are all found by bracketing on a fine grid (another
method than Newton); the plant's own start (``sim.builders.plant_start``: qm = q + Ks^-1 g(q),
the inverse map); and the same estimator started at the true state.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

import amsfe_sym.apps.estimate_build as estimate_app
from amsfe_sym.apps.cli import main
from amsfe_sym.apps.estimate import EstimateOptions, estimate_command
from amsfe_sym.apps.estimate_start import log_link_start
from amsfe_sym.codegen import library_for
from amsfe_sym.estimation.static_start import (
    FirstFrame,
    balance_candidates,
    static_link_start,
)
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import plant_start
from amsfe_sym.sim.loop import run
from tests.test_log_reader import _read, arm_events, write_log

# ---------------------------------------------------------------- a soft pendulum
MGL, KS, FOCAL = 14.0, 10.0, 300.0  # [N m], [N m/rad], [px per m of a 1 m link]


def _pendulum_torque(q: np.ndarray) -> np.ndarray:
    return -MGL * np.sin(q)  # g = dV/dq, V = MGL cos q: upright (unstable) at q = 0


def _pendulum_camera(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    y = FOCAL * np.array([np.sin(q[0]), np.cos(q[0])])
    return y, FOCAL * np.array([[np.cos(q[0])], [-np.sin(q[0])]])


def _all_balances(qm: float) -> list[float]:
    """Every root of -MGL sin q = KS (qm - q) in [-2 pi, 2 pi], by sign changes on a grid
    refined with Brent's method."""

    def f(q: float) -> float:
        return float(-MGL * np.sin(q) - KS * (qm - q))

    grid = np.linspace(-2 * np.pi, 2 * np.pi, 20001)
    v = [f(g) for g in grid]
    return [
        brentq(f, grid[i], grid[i + 1], xtol=1e-14)
        for i in range(grid.size - 1)
        if v[i] * v[i + 1] < 0
    ]


def test_a_pendulum_weaker_than_gravity_has_three_balances_and_the_camera_picks_the_true_one():
    """MGL > KS: near the top the spring cannot hold the link alone (the soft paper arm's
    case), so q = qm has three balances.  Newton from the motor angle finds one of them;
    with a frame taken at another one (the arm held there by a controller), that one is
    chosen, to Brent's root at 1e-9."""
    qm = 0.1
    roots = _all_balances(qm)
    assert len(roots) == 3, roots
    alone = static_link_start(_pendulum_torque, np.array([KS]), np.array([qm]), 1.0, 1e-3)
    assert not alone.frame_nis
    assert min(abs(alone.q[0] - r) for r in roots) < 1e-9
    for truth in roots:
        if abs(truth - alone.q[0]) < 1e-6:
            continue
        y, _ = _pendulum_camera(np.array([truth]))
        frame = FirstFrame(y + 0.3, 0.25 * np.eye(2), _pendulum_camera, np.zeros(1))
        got = static_link_start(_pendulum_torque, np.array([KS]), np.array([qm]), 1.0, 1e-3, frame)
        assert abs(got.q[0] - truth) < 1e-9, (got.q, truth, got.candidates)
        h = -MGL * np.cos(truth) + KS  # dtau/dq + Ks
        assert got.stable == (h > 0)


def test_the_start_covariance_is_the_balance_sensitivity_to_a_torque_error():
    """cov = H^-1 tau_std^2 H^-T + (H^-1 Ks) qm_std^2 (..)^T: checked against the balances
    re-solved with the torque and the motor angle moved by a small step (central
    differences of the solution, another computation than the jacobian at the root)."""
    qm, tau_std, qm_std, h = 0.3, 2.0, 0.01, 1e-6
    Ks = np.array([KS])
    base = static_link_start(_pendulum_torque, Ks, np.array([qm]), tau_std, qm_std)

    def root(dtau: float, dqm: float) -> float:
        c = balance_candidates(
            lambda q: _pendulum_torque(q) + dtau, Ks, np.array([qm + dqm]), [base.q]
        )
        return float(c[0][0])

    dq_dtau = (root(h, 0) - root(-h, 0)) / (2 * h)
    dq_dqm = (root(0, h) - root(0, -h)) / (2 * h)
    expected = (dq_dtau * tau_std) ** 2 + (dq_dqm * qm_std) ** 2
    assert abs(base.cov[0, 0] - expected) <= 1e-6 * expected


def test_the_paper_arms_balance_inverts_the_plants_start():
    """The plant starts at ``qm = q + Ks^-1 g(q)`` (sim.builders.plant_start, the inverse
    map); the balance of that qm seen by the camera at q is q again, to 1e-9 rad, although
    that balance is unstable open loop (the spring weaker than the gravity gradient)."""
    sc = load_scenario("paper-sim")
    lib = library_for(sc)
    n, th = lib.n, lib.theta_true
    x0 = plant_start(sc, lib)
    q, qm = x0[:n], x0[2 * n : 3 * n]
    bias = lib.function("bias")
    measure = lib.function("camera_measure")

    def torque(qq: np.ndarray) -> np.ndarray:
        return np.asarray(bias(qq, np.zeros(n), th)[0]).ravel()

    def camera(qq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y, J, _ = measure(qq, th)
        return np.asarray(y).ravel(), np.asarray(J).reshape(2, n)

    frame = FirstFrame(camera(q)[0], 0.25 * np.eye(2), camera, np.zeros(n))
    got = static_link_start(torque, lib.stiffness(th), qm, 5.0, 0.01, frame)
    assert np.max(np.abs(got.q - q)) < 1e-9, (got.q, q, got.candidates)
    assert not got.stable


# ---------------------------------------------------------------- the driver bag, kind none
SECONDS, SEED = 2.0, 3


@pytest.fixture(scope="module")
def arm_bag(tmp_path_factory):
    """A 2 s paper-sim run (compiled loop) written as a driver's ROS 1 bag: /joint_states
    with the two joints and two fingers, stamps 203.6 s ahead, 0.2 T jitter, 0.1-0.6 ms
    latency, camera frames (tests/test_log_reader.py ``arm_events``)."""
    sc = load_scenario("paper-sim").with_overrides(
        estimator="oosm", controller="amsfe", duration=SECONDS, seed=SEED
    )
    res = run(sc, library_for(sc), runtime="compiled")
    ev, _ = arm_events(res)
    return res, write_log(tmp_path_factory.mktemp("bag") / "arm.bag", ev, "bag")


def _estimate(bag: Path, out: Path, start_at: np.ndarray | None = None):
    """``amsfe estimate BAG --robot paper_2link --estimator replay`` (effort kind none, the
    default for /joint_states); ``start_at``: the link angles forced instead (the reference
    run started at the truth)."""
    opts = EstimateOptions(robot="paper_2link", estimator="replay", plots=False)
    if start_at is None:
        return estimate_command(bag, out, opts)
    orig = estimate_app._link_start

    def forced(*args):
        got = orig(*args)
        return replace(got, q=np.array(start_at, dtype=float), how="the truth")

    estimate_app._link_start = forced
    try:
        return estimate_command(bag, out, opts)
    finally:
        estimate_app._link_start = orig


def test_the_none_bag_is_tracked_from_the_springs_balance(arm_bag, tmp_path, capsys):
    """Started at the springs' balance (not at the motor angles, 1.45 rad off), the replay
    estimator fuses every camera frame, keeps a positive definite P to the last tick, and
    from the first frame's delivery on its link angles are those of the same filter started
    at the true state to within half its own 1-sigma: the start costs nothing once the first
    frame is in.  The link error against the truth is inside 4.5 of the filter's own sigma
    from the second frame on (a consistent filter crosses 4.5 sigma with probability 6.8e-6
    per sample: below 5 % over the 2 n K samples by the union bound).  The command says
    where it started."""
    res, bag = arm_bag
    n = res.lib.n
    q_true = res.x_true[:, :n]
    out = tmp_path / "balance"
    args = ["estimate", str(bag), "--robot", "paper_2link"]  # replay: the default for none
    code = main([*args, "--out", str(out), "--no-plots"])
    printed = capsys.readouterr().out
    assert code == 0
    assert "estimator replay: the default for effort kind 'none'" in printed, printed
    assert "start: link angles from the springs' balance" in printed, printed
    assert "chosen by the first camera frame" in printed, printed
    ref = _estimate(bag, tmp_path / "truth", start_at=q_true[0])
    s = json.loads((out / "summary.json").read_text())
    assert s["estimator"] == "replay"
    est = pd.read_parquet(out / "estimates.parquet")
    frames = ref.log.frames
    K = q_true.shape[0]
    x = est[[f"est_{i}" for i in range(res.lib.N)]].to_numpy()
    P = est[[f"var_{i}" for i in range(res.lib.N)]].to_numpy()
    assert x.shape[0] == K and np.isfinite(x).all() and (P[-1] > 0).all()
    assert s["frames_fused"] == len(frames) == len(res.frames), s["frames_fused"]
    # the start: within its own 1-sigma of the truth (was 1.45 rad = 3 sigma of P(0|0))
    assert (np.abs(x[0, :n] - q_true[0]) < np.sqrt(P[0, :n])).all()
    first, second = sorted(f.delivery_step for f in frames)[:2]
    sig = np.sqrt(P[:, :n])
    gap = np.abs(x[:, :n] - ref.estimate.x_hat[:, :n]) / sig
    assert gap[first:].max() < 0.5, gap[first:].max()
    z = np.abs(x[:, :n] - q_true) / sig
    assert z[second:].max() < 4.5, z[second:].max()


def test_a_joint_torque_start_is_exact_and_applied_keeps_the_positions(arm_bag):
    """With the effort said to be a joint torque sensor's, q = position - tau_J / Ks of the
    first sample (positions said to be the link's: the position itself); with the applied
    torque, the position (the motor equation sees the deflection from the first update)."""
    res, bag = arm_bag
    lib, n = res.lib, res.lib.n
    th = lib.theta_initial
    log = _read(res, bag)
    assert log.effort_kind == "none"
    tau = np.tile(np.array([3.0, -1.0]), (log.z.shape[0], 1))
    jt = replace(log, effort_kind="joint_torque", effort=tau)
    noise = {"tau_std": 5.0, "qm_std": 0.01, "pixel_var": 1.0}
    start = log_link_start(jt, lib, th, scale=2.0, **noise)
    assert start.std is None
    assert np.array_equal(start.q, log.z[0, :n] - 2.0 * tau[0] / lib.stiffness(th))
    link = log_link_start(jt, lib, th, positions="link", **noise)
    assert np.array_equal(link.q, log.z[0, :n])
    applied = log_link_start(replace(log, effort_kind="applied"), lib, th, **noise)
    assert np.array_equal(applied.q, log.z[0, :n])
    balance = log_link_start(log, lib, th, **noise)
    assert balance.std is not None and "camera frame" in balance.how
