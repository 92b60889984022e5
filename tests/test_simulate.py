"""Closed-loop simulation: the run folder, reproducibility, convergence, NEES, bad input."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import summarize


def test_cli_run_folder_and_exact_rerun(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    args = ["simulate", "--duration", "0.6", "--estimator", "replay", "--seed", "3"]
    args += ["--controller", "amsfe"]  # one run (without it: the scenario's comparison)
    assert main([*args, "--out", str(out), "--no-progress"]) == 0
    assert "run folder" in capsys.readouterr().out
    for name in (
        "config.toml",
        "timeseries.csv",
        "frames.csv",
        "summary.json",
        "estimation_errors.png",
        "theta.png",
        "tracking.png",
    ):
        assert (out / name).is_file(), name
    s = json.loads((out / "summary.json").read_text())
    for key in (
        "scenario",
        "estimator",
        "controller",
        "seed",
        "ticks",
        "sim_time_s",
        "wall_time_s",
        "estimation_rmse",
        "tracking_rmse",
        "nees_mean",
    ):
        assert key in s
    assert (s["scenario"], s["estimator"], s["seed"], s["ticks"]) == ("paper-sim", "replay", 3, 601)
    assert len(s["estimation_rmse"]["q"]) == 2 and len(s["estimation_rmse"]["theta"]) == 1
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert header[:2] == ["t", "true_q1"] and "est_payload" in header and "nees" in header
    # the saved config re-runs the same run exactly
    again = tmp_path / "again"
    assert (
        main(
            [
                "simulate",
                str(out / "config.toml"),
                "--out",
                str(again),
                "--no-progress",
                "--no-plots",
            ]
        )
        == 0
    )
    s2 = json.loads((again / "summary.json").read_text())
    assert s2["estimation_rmse"] == s["estimation_rmse"]
    assert s2["tracking_rmse"] == s["tracking_rmse"]
    a = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(again / "timeseries.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(a, b)


def test_paper_sim_converges_from_the_wrong_start(paper_sim) -> None:
    """Estimator starts at q = (0.9, 0.9), qd = (0.25, 0) against the true (0.5, 0.5), 0;
    theta (a 0.15 kg tip payload) starts at 0."""
    sc, lib = paper_sim
    res = run(sc.with_overrides(estimator="oosm", duration=6.0), lib)
    err = res.x_true - res.x_hat
    assert np.max(np.abs(err[0, :2])) > 0.39  # it did start wrong
    late = slice(int(4.0 / lib.T), None)
    assert np.max(np.abs(err[late, :2])) < 0.01  # rad
    assert np.sqrt(np.mean(err[late, 2:4] ** 2)) < 0.05  # rad/s
    theta = res.x_hat[:, 8]
    assert abs(theta[-1] - 0.15) < 0.01 and abs(theta[0]) < 1e-12  # kg


def test_replay_nees_inside_its_95_percent_band(paper_sim) -> None:
    """Average NEES over 20 seeds (N = 9 states) inside the two-sided 95 % chi-square band
    [chi2(0.025, N M) / M, chi2(0.975, N M) / M] at >= 90 % of the steps of the last 80 %."""
    sc, lib = paper_sim
    M = 20
    nees = np.array(
        [
            # the oracle controller isolates the estimator (the tracking transient of a
            # controller on the estimate is not what this test is about); the compiled loop,
            # the default, equals the Python reference here to ~1e-12
            # (tests/test_compiled_loop.py, docs/how-to/runtime-c.md)
            run(
                sc.with_overrides(estimator="replay", seed=s, duration=2.0, controller="truth-ct"),
                lib,
                runtime="compiled",
            ).nees
            for s in range(M)
        ]
    )
    K = nees.shape[1]
    anees = nees.mean(axis=0)[K // 5 :]
    lo, hi = chi2.ppf(0.025, lib.N * M) / M, chi2.ppf(0.975, lib.N * M) / M
    inside = np.mean((anees >= lo) & (anees <= hi))
    assert inside >= 0.9, (inside, anees.mean(), lo, hi)


def test_paper_integrator_makes_the_filter_inconsistent(paper_sim) -> None:
    """Measured reason for the rk4 default: eqs. (1a)-(1d) lag the encoders (NEES >> N)."""
    sc, _ = paper_sim
    paper = dataclasses.replace(sc, integrator="paper", duration=2.0, estimator="encoders")
    res = run(paper, library_for(paper))
    assert summarize(res)["nees_mean"] > 10 * res.lib.N


@pytest.mark.parametrize(
    ("section", "field", "value", "needle"),
    [
        ("filter", "link_torque_std", 0.0, "positive definite"),
        ("filter", "camera_pixel_std", -1.0, "camera_pixel_std"),
        ("encoders", "q_std", -0.1, "q_std"),
        ("estimate0", "std", {"q": 0.0}, "std.q"),
    ],
)
def test_bad_noise_settings_are_refused(tmp_path: Path, section, field, value, needle) -> None:
    text = (Path(__file__).parent.parent / "scenarios" / "paper-sim.toml").read_text()
    line = f"{field} = {{ q = 0.0 }}" if isinstance(value, dict) else f"{field} = {value}"
    lines = []
    current = None
    for raw in text.splitlines():
        if raw.startswith("["):
            current = raw.strip("[] ")
        if current == section and raw.split("=")[0].strip() == field:
            raw = line
        lines.append(raw)
    path = tmp_path / "bad.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=needle):
        load_scenario(path)


def test_delay_longer_than_buffer_is_refused(paper_sim) -> None:
    sc, lib = paper_sim
    bad = dataclasses.replace(
        sc, estimator="replay", filter=dataclasses.replace(sc.filter, buffer_steps=50)
    )
    with pytest.raises(ConfigError, match="buffer_steps"):
        run(bad, lib)


def test_noise_free_camera_needs_an_explicit_filter_R(paper_sim) -> None:
    sc, lib = paper_sim
    exact = dataclasses.replace(sc.camera, pixel_std=0.0, round_to_pixel=False)
    with pytest.raises(ConfigError, match="camera_pixel_std"):
        run(dataclasses.replace(sc, camera=exact, duration=0.1), lib)
    ok = dataclasses.replace(sc.filter, camera_pixel_std=0.1)
    assert run(dataclasses.replace(sc, camera=exact, filter=ok, duration=0.1), lib).t.size == 101


def test_unknown_names_are_refused(paper_sim, capsys) -> None:
    sc, lib = paper_sim
    with pytest.raises(ConfigError, match="cloning"):
        run(sc.with_overrides(estimator="kalman"), lib)
    assert main(["simulate", "--estimator", "kalman", "--no-progress"]) == 2
    assert "error:" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="truth-ct"):
        run(sc.with_overrides(controller="pid"), lib)
    with pytest.raises(ConfigError, match="paper-sim"):
        load_scenario("no-such-scenario")


@pytest.mark.parametrize("estimator", ["replay", "cloning", "oosm"])
def test_dropped_and_jittered_frames(paper_sim, estimator: str) -> None:
    """Half the frames lost, delivery jitter of up to 40 steps: counted, the rest used,
    the estimate stays good."""
    sc, lib = paper_sim
    cam = dataclasses.replace(sc.camera, drop_probability=0.5, jitter_steps=40)
    res = run(dataclasses.replace(sc, duration=3.0, estimator=estimator, camera=cam), lib)
    c = res.counters
    assert c["frames_dropped"] >= 3 and c["frames_applied"] >= 3
    assert c["frames_dropped"] + c["frames_delivered"] <= c["frames_exposed"]
    # every delivered frame is applied (jitter 40 < buffer) and none refused
    assert c["frames_applied"] == c["frames_delivered"] and c["frames_rejected"] == 0
    late = slice(int(2.0 / lib.T), None)
    # measured 4.46 mrad (q) and 1.66 g (payload) for all three; ~2x
    assert np.max(np.abs(res.x_true[late, :2] - res.x_hat[late, :2])) < 0.01
    th = lib.layout["theta"]
    assert np.max(np.abs(res.x_true[late, th] - res.x_hat[late, th])) < 0.004
    # the frames are used: the estimate is not the encoders-only one
    enc = run(dataclasses.replace(sc, duration=3.0, estimator="encoders", camera=cam), lib)
    assert np.max(np.abs(res.x_hat[:, :2] - enc.x_hat[:, :2])) > 1e-5


def test_paper_exp_runs(tmp_path: Path) -> None:
    sc = load_scenario("paper-exp").with_overrides(duration=2.0, estimator="cloning")
    res = run(sc, library_for(sc))
    s = summarize(res)
    assert s["ticks"] == 201 and res.counters["frames_applied"] >= 45
    assert res.counters["frames_applied"] == res.counters["frames_delivered"]
    assert max(s["estimation_rmse"]["q"]) < 0.0012  # measured 0.52 mrad


def test_controller_reference_grid_equals_direct_evaluation(paper_sim) -> None:
    from amsfe_sym.control import make_controller
    from amsfe_sym.signals.trajectory import from_config as trajectory_from_config

    sc, lib = paper_sim
    traj = trajectory_from_config(dict(sc.trajectory))
    ctrl = make_controller("truth-ct", lib, traj)
    t = np.arange(50) * lib.T
    ctrl.prepare(t)
    for k in (0, 17, 49):
        direct = traj.evaluate(float(t[k]))
        for a, b in zip(ctrl.reference(k, float(t[k])), direct, strict=True):
            np.testing.assert_array_equal(a, b)
    # off the grid (another time, or beyond it) it evaluates directly
    off = ctrl.reference(3, 0.123)
    np.testing.assert_array_equal(off[0], traj.evaluate(0.123).q)


def test_run_folder_values_match_the_run(paper_sim, tmp_path: Path) -> None:
    """timeseries.csv and frames.csv hold the run's values (full precision), and
    every frame is where the camera saw the true tracked point at its exposure step."""
    from amsfe_sym.sim.record import write_run

    sc, lib = paper_sim
    res = run(sc.with_overrides(duration=1.0, estimator="replay", seed=4), lib)
    write_run(res, tmp_path / "run")
    ts = np.loadtxt(tmp_path / "run" / "timeseries.csv", delimiter=",", skiprows=1)
    N, n = lib.N, lib.n
    cols = [res.t, res.x_true, res.x_hat, res.P_diag, res.nees, res.q_des, res.u, res.z_enc]
    cols += [res.s, res.saturated.astype(float)]
    expect = np.column_stack([*cols, res.tau_d])
    assert ts.shape == expect.shape == (1001, 1 + 3 * N + 1 + 7 * n + 1)
    np.testing.assert_array_equal(ts, expect)  # full precision (%.17g)
    fr = np.loadtxt(tmp_path / "run" / "frames.csv", delimiter=",", skiprows=1, ndmin=2)
    np.testing.assert_allclose(fr, res.frames, rtol=1e-9)
    period, delay = lib.manifest.camera.period, lib.manifest.camera.delay
    assert fr.shape == (8, 4)  # exposures 0, 125, ..., 875, delivered by step 1000
    assert np.all(fr[:, 0] % period == 0) and np.all(fr[:, 1] - fr[:, 0] == delay)
    cam = lib.function("camera")
    for kappa, _, u_px, v_px in fr:
        x = res.x_true[int(kappa)]
        y = cam(x[lib.layout["q"]], x[lib.layout["theta"]])[0]
        # whole pixels (round_to_pixel) of the true projection plus 0.32 px noise
        assert u_px == round(u_px) and v_px == round(v_px)
        assert np.max(np.abs(np.array([u_px, v_px]) - y)) < 2.0
    # the encoder columns are the true motor state plus noise of the configured size
    enc_err = res.z_enc[1:, :n] - res.x_true[1:, lib.layout["qm"]]
    assert 0.5e-3 < np.std(enc_err) < 2e-3  # q_std = 1 mrad
