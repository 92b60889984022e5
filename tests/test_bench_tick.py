"""``amsfe bench`` sections 4 and 5: the tick three ways and the scaling table.

Correctness only, no timing asserted: the numpy + Pinocchio baseline computes the Python
reference's tick, the pure C tick timer ends where the Python path ends, the scaling table
has its rows, and the growth-exponent fit recovers a known power.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from amsfe_sym.apps.bench.scaling import bench_scaling, chain_urdf
from amsfe_sym.apps.bench.tick import BaselineEkf, bench_tick, fit_exponent
from amsfe_sym.apps.bench.ticks import timing_scenario
from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import generate, library_for
from amsfe_sym.estimation import make_estimator
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import load_spec
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)


def test_baseline_tick_equals_the_python_tick_on_the_semi_implicit_model() -> None:
    """Same model (semi-implicit Euler), same EKF: the baseline's x and P equal the Python
    ``encoders`` estimator's over 300 ticks.  The one model difference, A's d/dtheta column
    (Pinocchio's derivatives have none), is switched off by a frozen payload: no theta noise
    and a 1e-30 prior variance, so that column multiplies ~1e-30."""
    spec = load_spec("paper_2link")
    spec = replace(
        spec,
        name="paper_2link_semi_implicit",  # the library_for override's: compiled once
        model=replace(spec.model, integrator="semi_implicit"),
    )
    lib = ModelLibrary(generate(spec).out_dir)
    robot = load_robot(spec)
    n, N = lib.n, lib.N
    Qw = noise_covariance(lib, 0.1, 0.1, 0.0)
    enc = EncoderMeasurement(lib, 1e-6, 1e-3)
    x0 = np.r_[0.3, -0.2, 0.0, 0.0, 0.3, -0.2, 0.0, 0.0, lib.theta_true]
    P0 = np.diag(np.r_[np.full(n, 1e-2), np.full(n, 1e-1), np.full(2 * n, 1e-6), 1e-30])
    py = make_estimator(
        "encoders",
        model=CompiledTransition(lib, Qw),
        encoder=enc,
        camera=CameraMeasurement(lib, 1.0),
        x0=x0,
        P0=P0,
    )
    base = BaselineEkf(robot, Qw, enc.R, x0, P0)
    rng = np.random.default_rng(0)
    for k in range(300):
        u = np.array([2.0 * np.sin(0.01 * k), 0.5])
        z = enc.H @ py.x + rng.normal(0.0, 1e-3, 2 * n) if k % 7 else None
        py.step(u, z)
        base.tick(u, z)
        assert np.max(np.abs(base.x - py.x)) <= 1e-10 * max(1.0, np.max(np.abs(py.x)))
        assert np.max(np.abs(base.P - py.P)) <= 1e-12 * np.max(np.abs(py.P))
    assert N == 9 and np.max(np.abs(py.x[:n] - x0[:n])) > 1e-3  # the arm moved


def test_bench_tick_routes_agree_on_paper_sim(libraries) -> None:
    """The pure C tick (amsfe_est_tick in the timer) ends at the Python reference's x."""
    sc = timing_scenario(libraries.get("paper_2link")[1], 0.3)
    out = bench_tick(sc, library_for(sc), load_robot(sc.robot), ("oosm", "encoders"), rounds=2)
    assert out["ticks"] == 300 and [r["estimator"] for r in out["rows"]] == ["oosm", "encoders"]
    for r in out["rows"]:
        assert r["max_dx_compiled_python"] <= 1e-10
        for route in ("compiled", "python", "baseline"):
            assert r[route]["ticks"] == 300
            assert 0 < r[route]["median_us"] <= r[route]["p99_us"]
        assert r["compiled_with_law_us"] > r["compiled"]["median_us"]
    frames = out["rows"][0]["late_frame"]  # oosm's frames, timed in the timer's second run
    assert 0 < frames["applied"] <= frames["frames"] and frames["median_us"] > 0
    assert "late_frame" not in out["rows"][1]  # the encoders alone take no frame


@pytest.mark.slow
def test_scaling_table_has_a_row_per_chain() -> None:
    out = bench_scaling((1, 2), ticks=50, panda=False, loop_duration=0.1, rounds=1)
    assert [r["joints"] for r in out["rows"]] == [1, 2]
    assert [r["N"] for r in out["rows"]] == [4, 8]  # 4n: a bare URDF has no theta
    for r in out["rows"]:
        assert r["c_lines"] > 0 and r["generate_s"] > 0 and r["tick_us"] > 0
        assert r["peak_mb"] > 0 and r["baseline_us"] > 0 and r["aba_derivatives_us"] > 0
        # stored to one decimal (bench/tick.py): equal to the ratio within that rounding
        ratio = r["baseline_us"] / r["tick_us"]
        assert r["speedup_baseline"] == pytest.approx(ratio, rel=0.01, abs=0.051)
        assert r["real_time_factor"] == pytest.approx(1e3 / r["loop_us_per_tick"], rel=0.01)
    assert out["exponents"] == {}  # one row with n >= 2: nothing to fit
    assert chain_urdf(3) == chain_urdf(3) != chain_urdf(3, seed=1)  # deterministic


def test_fit_exponent_recovers_a_power() -> None:
    joints = [2, 3, 5, 8, 12]
    assert fit_exponent(joints, [0.7 * j**3 for j in joints]) == pytest.approx(3.0, abs=1e-12)
    assert fit_exponent(joints, [4.0 * j**1.5 for j in joints]) == pytest.approx(1.5, abs=1e-12)


def test_bench_joints_option_refuses_a_bad_range(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--joints", "0-3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--joints" in err and "1 <= A <= B" in err


def test_compile_prints_progress_while_it_runs(monkeypatch, capsys, tmp_path) -> None:
    """generate(progress=True)'s compile says it is alive every COMPILE_PROGRESS_S seconds,
    and still returns the compiler's exit code and messages."""
    import sys

    from amsfe_sym.codegen import compile_units

    monkeypatch.setattr(compile_units, "COMPILE_PROGRESS_S", 0.05)
    cmd = [sys.executable, "-c", "import sys, time; time.sleep(0.3); sys.exit('boom')"]
    proc = compile_units.run_commands([cmd], tmp_path, True, "slow")
    assert proc.returncode == 1 and "boom" in proc.stderr
    err = capsys.readouterr().err
    assert err.count("[amsfe] slow: compiling, ") >= 2
    quiet = compile_units.run_commands([cmd], tmp_path, False, "slow")
    assert quiet.returncode == 1 and "boom" in quiet.stderr
    assert capsys.readouterr().err == ""


def test_parallel_units_stop_at_the_first_failure(tmp_path) -> None:
    """Commands run two at a time: the failing one's exit code and messages come back, the
    one still running is killed (it never writes its file), the pending one never starts."""
    import sys

    from amsfe_sym.codegen import compile_units

    slow = [sys.executable, "-c", "import time; time.sleep(5); open('slow', 'w')"]
    bad = [sys.executable, "-c", "import sys; sys.exit('bad unit')"]
    never = [sys.executable, "-c", "open('never', 'w')"]
    proc = compile_units.run_commands([slow, bad, never], tmp_path, False, "x", jobs=2)
    assert proc.returncode == 1 and "bad unit" in proc.stderr and proc.args == bad
    assert not (tmp_path / "slow").exists() and not (tmp_path / "never").exists()
    ok = [sys.executable, "-c", "import sys; print('warn', file=sys.stderr)"]
    done = compile_units.run_commands([ok, ok, ok], tmp_path, False, "x", jobs=2)
    assert done.returncode == 0 and "warn" in done.stderr


def test_aba_derivatives_timing_on_the_panda() -> None:
    """The scaling table's computeABADerivatives column runs on the Panda's locked model."""
    from amsfe_sym.apps.bench.scaling import aba_derivatives_us

    robot = load_robot("panda")
    assert robot.pin_model_at(robot.theta_true).nv == 7
    assert aba_derivatives_us(robot, rounds=1) > 0
