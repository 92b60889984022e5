"""The batch path of ``estimate_log`` (one ``amsfe_est_run`` C call per chunk of ticks) against
the per-tick path (``est.step`` from Python, the estimator's own StepReports), for all five
compiled estimators: the same x(k|k), diag P(k|k), counters, encoder NIS per tick and frame
records (kappa, arrival, NIS, fused), on a simulated log as written and on the same log with
the frames a real log has (duplicates, NaN pixels, frames older than the history, several in
one tick, out of exposure order) and encoder gaps (docs/how-to/logs.md, "Speed")."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.logs.read import RobotLog, read_log
from amsfe_sym.logs.replay import LogEstimate, estimate_log
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.runtime.estimator_batch import run_log
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing
from amsfe_sym.sim.loop import run

ESTIMATORS = ("encoders", "naive", "oosm", "replay", "cloning")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """One 1 s paper-sim run per estimator (compiled loop), written as a bag and read back."""
    out = {}
    root = tmp_path_factory.mktemp("batch")
    for name in ESTIMATORS:
        sc = load_scenario("paper-sim").with_overrides(
            estimator=name, controller="amsfe", duration=1.0, seed=5
        )
        lib = library_for(sc)
        res = run(sc, lib, runtime="compiled")
        bag = write_run_bag(res, root / name)
        out[name] = (sc, lib, res, read_log(bag, LogSpec(), lib.manifest.joints, lib.T, lib.N))
    return out


def _estimate(sc, lib, log: RobotLog, *, batch: bool, compiled: bool = True) -> LogEstimate:
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    est = build_estimator(sc, lib, sensors, log.z[0], compiled=compiled)
    return estimate_log(log, est, batch=batch, progress=False)


def _same(a: LogEstimate, b: LogEstimate, tol: float = 1e-12) -> None:
    assert a.x_hat.shape == b.x_hat.shape
    assert np.max(np.abs(a.x_hat - b.x_hat)) <= tol
    assert np.max(np.abs(a.P_diag - b.P_diag)) <= tol
    assert a.counters == b.counters
    assert np.array_equal(np.isnan(a.encoder_nis), np.isnan(b.encoder_nis))
    assert np.nanmax(np.abs(a.encoder_nis - b.encoder_nis), initial=0.0) <= 1e-9
    fa, fb = a.frame_nis, b.frame_nis
    assert np.array_equal(fa.kappa, fb.kappa)
    assert np.array_equal(fa.arrival, fb.arrival)
    assert np.array_equal(fa.fused, fb.fused)
    assert np.array_equal(np.isnan(fa.nis), np.isnan(fb.nis))
    assert np.nanmax(np.abs(fa.nis - fb.nis), initial=0.0) <= 1e-9
    if a.nees is not None and b.nees is not None:  # Cholesky in C, LU in numpy
        assert np.allclose(a.nees, b.nees, rtol=1e-9, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_batch_equals_per_tick_and_the_loop(name: str, logs) -> None:
    sc, lib, res, log = logs[name]
    batch = _estimate(sc, lib, log, batch=True)
    per_tick = _estimate(sc, lib, log, batch=False)
    _same(batch, per_tick)
    assert np.array_equal(batch.x_hat, res.x_hat)  # the loop's own estimates, bit for bit
    assert np.array_equal(batch.P_diag, res.P_diag)
    # NIS where there was an update, NaN elsewhere
    assert np.isnan(batch.encoder_nis[0]) and np.isfinite(batch.encoder_nis[1:]).all()
    assert len(batch.frame_nis.kappa) == len(log.frames)
    fused = int(batch.frame_nis.fused.sum())
    assert fused == batch.counters["frames_applied"] == res.counters["frames_applied"]
    if name != "encoders":
        assert fused > 0


def _unusual(log: RobotLog, seed: int) -> RobotLog:
    """``log`` with encoder gaps and the frames real logs have."""
    rng = np.random.default_rng(seed)
    K = log.K
    z = log.z.copy()
    for start in rng.integers(2, K - 20, size=4):
        z[start : start + rng.integers(1, 6)] = np.nan
    frames = list(log.frames)
    extra: list[CameraFrame] = []
    for fr in log.frames:
        roll = rng.random()
        if roll < 0.3:  # the same exposure again, later or in the same tick
            later = min(K - 1, fr.delivery_step + int(rng.integers(0, 3)))
            extra.append(CameraFrame(fr.exposure_step, fr.z + 0.5, later))
        elif roll < 0.5:  # a NaN pixel of the same exposure first
            extra.append(CameraFrame(fr.exposure_step, np.array([np.nan, 1.0]), fr.delivery_step))
    # an unscheduled exposure, one older than the history (buffer 400), two in one tick out
    # of exposure order, a frame arriving at tick 0 (never given), a non-finite pixel
    pix = log.frames[0].z
    extra += [
        CameraFrame(37, pix, 60),
        CameraFrame(50, pix + 1.0, 600),
        CameraFrame(300, pix, 330),
        CameraFrame(290, pix - 1.0, 330),
        CameraFrame(0, pix, 0),
        CameraFrame(400, np.array([np.nan, np.inf]), 420),
    ]
    frames += extra
    order = rng.permutation(len(frames))  # arrival order within a tick: any
    frames = sorted((frames[i] for i in order), key=lambda f: f.delivery_step)
    return dataclasses.replace(log, z=z, frames=frames)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("name", ESTIMATORS)
def test_batch_equals_per_tick_on_an_unusual_log(name: str, seed: int, logs) -> None:
    sc, lib, _, log = logs[name]
    odd = _unusual(log, seed)
    batch = _estimate(sc, lib, odd, batch=True)
    per_tick = _estimate(sc, lib, odd, batch=False)
    _same(batch, per_tick)
    assert np.isnan(batch.encoder_nis[np.isnan(odd.z).any(axis=1)]).all()
    if name != "encoders":
        rejected = batch.counters["frames_rejected"]
        assert rejected >= 4 and batch.counters["refused_nan"] >= 1
        assert batch.counters["refused_too_late"] >= 1
    assert len(batch.frame_nis.kappa) == len(odd.frames) - 1  # not the one at tick 0


def test_python_estimators_report_the_same_nis(logs) -> None:
    """The Python reference's StepReports (per tick) give the compiled batch's NIS."""
    sc, lib, _, log = logs["oosm"]
    ref = _estimate(sc, lib, log, batch=True, compiled=False)
    batch = _estimate(sc, lib, log, batch=True)
    assert np.allclose(ref.encoder_nis, batch.encoder_nis, rtol=1e-6, atol=1e-9, equal_nan=True)
    assert np.array_equal(ref.frame_nis.fused, batch.frame_nis.fused)
    assert np.allclose(ref.frame_nis.nis, batch.frame_nis.nis, rtol=1e-6, equal_nan=True)


def test_run_log_refuses_a_used_estimator(logs) -> None:
    sc, lib, _, log = logs["naive"]
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    est = build_estimator(sc, lib, sensors, log.z[0], compiled=True)
    est.step(log.u[0], log.z[1])
    from amsfe_sym.errors import ConfigError

    with pytest.raises(ConfigError, match="fresh estimator"):
        run_log(est, log.u, log.z, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))
    # arrays of the wrong shape are refused before the C call reads them
    from amsfe_sym.errors import ShapeError

    fresh = build_estimator(sc, lib, sensors, log.z[0], compiled=True)
    none_i, none_z = np.zeros(0, np.int64), np.zeros((0, 2))
    for u, z in ((log.u[:, :1], log.z), (log.u, log.z[:-1]), (log.u[0], log.z)):
        with pytest.raises(ShapeError):
            run_log(fresh, u, z, none_i, none_i, none_z)
    with pytest.raises(ShapeError):
        run_log(fresh, log.u, log.z, np.zeros(2, np.int64), np.zeros(2, np.int64), none_z)
    with pytest.raises(ShapeError):
        run_log(fresh, log.u, log.z, none_i, none_i, none_z, truth=np.zeros((3, 3)))
    assert fresh.k == fresh.k0  # nothing ran
    # estimate_log steps it from Python instead (the per-tick path takes any state)
    assert estimate_log(log, est, progress=False).x_hat.shape == (log.K, est.nx)


def test_progress_bars_change_nothing(logs, capsys) -> None:
    """The tqdm bar over the ticks (forced on for a short log) leaves the numbers alone."""
    sc, lib, _, log = logs["replay"]
    plain = _estimate(sc, lib, log, batch=True)
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    for batch in (True, False):
        est = build_estimator(sc, lib, sensors, log.z[0], compiled=True)
        shown = estimate_log(log, est, batch=batch, progress=True)
        _same(shown, plain)


@pytest.mark.parametrize("name", ["naive", "replay", "cloning"])
def test_batch_equals_per_tick_with_the_encoder_gate_on(name: str, logs, monkeypatch) -> None:
    """Encoder samples gated out (a gate at p = 0.5 refuses about half): counted, and their
    NIS kept, the same on both paths (replay re-filters the gated steps after a frame)."""
    from amsfe_sym.sim import builders

    plain = builders.filter_config
    monkeypatch.setattr(
        builders,
        "filter_config",
        lambda sc, timing: dataclasses.replace(plain(sc, timing), encoder_gate_probability=0.5),
    )
    sc, lib, _, log = logs[name]
    batch = _estimate(sc, lib, log, batch=True)
    per_tick = _estimate(sc, lib, log, batch=False)
    _same(batch, per_tick)
    gated = batch.counters["encoder_rejected"]
    assert 0.2 * log.K < gated < 0.8 * log.K
    assert np.isfinite(batch.encoder_nis[1:]).all()
