"""The closed loop in C (runtime/c/amsfe_loop.c) against the Python loop (sim/loop.py).

Two comparisons, for every estimator x controller pair on paper-sim:

1. the C loop against the Python loop running the library's C estimator: this isolates the
   loop, the sensors, the noise batches, the controllers and the decisions; every recorded
   signal agrees to 1e-8 (in practice exactly, but for the NEES: Cholesky vs LU) and every
   counter is equal;
2. the C loop against the full Python reference (numpy estimators): equal to 1e-8 while the
   two estimators' last-digit differences (5e-14, tests/test_compiled_estimator.py) stay
   small.  On the ``amsfe`` and ``dtsmc-ekf`` loops they do not stay small: those loops
   amplify a 1e-13 perturbation to O(1) in about 6 s, the Python reference as much as the
   C path (docs/how-to/runtime-c.md, ``tools/loop_equivalence.py``), so they are compared over
   their first second; ``truth`` over 10 s, the rest over 2 s (the tool runs all of them
   over 10 s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.control import LawInputs
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, apply_sets, load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.result import RunResult

ESTIMATORS = ("encoders", "naive", "oosm", "replay", "cloning")
CONTROLLERS = ("amsfe", "dtsmc", "dtsmc-ekf", "truth", "amsfe-paper", "dtsmc-paper", "truth-ct")
#: The loops that amplify last-digit differences of the estimate (see the module docstring).
SENSITIVE = ("amsfe", "dtsmc-ekf")
#: The cascades paper-sim starts with the blended reference.  At its first tick the
#: reference starts at the estimate, so e = q_hat - q_r is ~1e-16 and |e|^p (p = 0.6) turns
#: the numpy and C estimators' last-digit differences into 1e-8 N m at once: the numpy
#: reference is compared without the blend; the blend itself is held equal on the path with
#: the C estimator (test_blended_start_c_loop_equals_python_loop) and tick by tick.
BLENDED = ("amsfe", "dtsmc-ekf")  # truth acts on the true state: compared with the blend
SIGNALS = ("x_true", "x_hat", "P_diag", "nees", "u", "z_enc", "s", "bound", "frames", "tau_d")


def assert_same_run(a: RunResult, b: RunResult, tol: float = 1e-8) -> None:
    """Every recorded signal within ``tol`` (relative to 1 + |a|), the same decisions."""
    assert a.diverged_at == b.diverged_at
    assert a.t.shape == b.t.shape
    for name in SIGNALS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        assert np.array_equal(np.isnan(x), np.isnan(y)), name
        ok = ~np.isnan(x)
        err = np.abs(x[ok] - y[ok]) / (1.0 + np.abs(x[ok]))
        assert err.size == 0 or err.max() <= tol, f"{name}: {err.max():.3g}"
    assert np.array_equal(a.saturated, b.saturated)
    assert a.counters == b.counters
    np.testing.assert_array_equal(a.q_des, b.q_des)


@pytest.mark.slow
@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_c_loop_equals_python_loop(
    paper_sim: tuple[Scenario, ModelLibrary], estimator: str, controller: str
) -> None:
    sc, lib = paper_sim
    # the paper's pair over 10 s, the others over 1 s (tools/loop_equivalence.py runs them all
    # over 10 s: docs/how-to/runtime-c.md)
    duration = 10.0 if (estimator, controller) == ("oosm", "amsfe") else 1.0
    sc = sc.with_overrides(estimator=estimator, controller=controller, duration=duration, seed=1)
    c = run(sc, lib, runtime="compiled")
    py = run(sc, lib, runtime="python", compiled_estimator=True)
    assert_same_run(py, c)
    assert c.counters["frames_exposed"] > 0
    if estimator in ("oosm", "replay", "cloning") and c.diverged_at is None:
        assert c.counters["frames_applied"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_c_loop_equals_the_python_reference(
    paper_sim: tuple[Scenario, ModelLibrary], controller: str
) -> None:
    sc, lib = paper_sim
    duration = 1.0 if controller in SENSITIVE else (10.0 if controller == "truth" else 2.0)
    seed = 1 if controller in SENSITIVE else 2  # seed 2's start transient amplifies sooner
    sc = sc.with_overrides(estimator="oosm", controller=controller, duration=duration, seed=seed)
    if controller in BLENDED:
        sc = apply_sets(sc, [f"controller_gains.{controller}.blend_accel=inf"])
    assert_same_run(run(sc, lib), run(sc, lib, runtime="compiled"))


def test_the_comparison_can_fail(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """Another seed is another run: the check sees it."""
    sc, lib = paper_sim
    sc = sc.with_overrides(estimator="oosm", controller="truth", duration=0.3, seed=1)
    a = run(sc, lib, runtime="compiled")
    b = run(sc.with_overrides(seed=2), lib, runtime="compiled")
    with pytest.raises(AssertionError):
        assert_same_run(a, b)


@pytest.mark.parametrize("blend", ["inf", "20"])
def test_compiled_controller_tick_by_tick(
    paper_sim: tuple[Scenario, ModelLibrary], blend: str
) -> None:
    """amsfe_ctrl alone, fed the Python controller's inputs, gives its torques (1e-12), with
    and without the blended start (control/blend.py)."""
    from amsfe_sym.runtime.compiled_loop import CompiledController
    from amsfe_sym.scenario import apply_sets
    from amsfe_sym.sim.builders import build_controller
    from amsfe_sym.sim.compiled import controller_params

    sc, lib = paper_sim
    rng = np.random.default_rng(0)
    for name in CONTROLLERS:
        one = sc.with_overrides(controller=name)
        if name in ("amsfe", "dtsmc", "dtsmc-ekf", "truth"):
            one = apply_sets(
                one,
                [
                    f"controller_gains.{name}.blend_accel={blend}",
                    f"controller_gains.{name}.blend_rate=10.0",
                ],
            )
        ctrl, traj = build_controller(one, lib)
        cc = CompiledController(str(lib.library_path), controller_params(ctrl, lib), lib.n)
        waited: list[bool] = []
        t = np.arange(50) * lib.T
        ctrl.prepare(t)
        q, qd, qdd = traj.evaluate(t)
        jerk, snap = traj.higher(t)
        x = np.concatenate([q[0], qd[0], q[0], qd[0], lib.theta_true])
        for k in range(50):
            ref = np.concatenate([q[k], qd[k], qdd[k], jerk[k], snap[k]])
            x_hat = x + 1e-3 * rng.standard_normal(lib.N)
            z = x[2 * lib.n : 4 * lib.n] + 1e-4 * rng.standard_normal(2 * lib.n)
            # a covariance that converges: the start-up waits for the first ticks
            P = np.diag(np.full(lib.N, (0.3 * np.exp(-k / 4.0)) ** 2))
            tick = LawInputs(k, float(t[k]), x[: 4 * lib.n], x[4 * lib.n :], x_hat, z, np.diag(P))
            u_py, sat = ctrl.saturate(ctrl.torque(tick))
            u_c = cc.torque(k, ref, x_hat, z, x, P)
            waited.append(not getattr(ctrl, "_ready", True))
            # truth-ct's motor feedforward is the second backward difference of qm_d over T:
            # it scales a last-bit difference of qm_d (libm's and numpy's sin differ by an ulp
            # on some CPU kinds, e.g. an AMD EPYC: 1.2e-10 N m seen at k = 16) by ~4 Mm / T^2
            atol = 1e-9 if name == "truth-ct" else 1e-12
            np.testing.assert_allclose(u_c, u_py, rtol=1e-12, atol=atol, err_msg=f"{name} k={k}")
            assert cc.saturated == sat
            np.testing.assert_allclose(cc.s, ctrl.s, rtol=1e-12, atol=1e-12)
            x[: lib.n] += 1e-3 * np.sin(k)  # move the state a little
        if name in ("amsfe", "dtsmc-ekf"):  # the start-up waited, then ran, on both sides
            assert waited[0] and not waited[-1], name
        if blend != "inf" and name == "amsfe":  # the blend ran (truth starts on the path)
            tb = ctrl._blend[2]  # type: ignore[attr-defined]
            assert tb > 0


@pytest.mark.parametrize("controller", ["amsfe", "truth", "dtsmc"])
def test_blended_start_c_loop_equals_python_loop(
    paper_sim: tuple[Scenario, ModelLibrary], controller: str
) -> None:
    """The blended start (blend_accel) in the whole loop: C against Python (C estimator)."""
    from amsfe_sym.scenario import apply_sets

    sc, lib = paper_sim
    sc = sc.with_overrides(estimator="oosm", controller=controller, duration=1.0, seed=3)
    sc = apply_sets(
        sc,
        [
            f"controller_gains.{controller}.blend_accel=20.0",
            f"controller_gains.{controller}.blend_rate=10.0",
        ],
    )
    c = run(sc, lib, runtime="compiled")
    assert_same_run(run(sc, lib, runtime="python", compiled_estimator=True), c)
    plain = run(
        apply_sets(sc, [f"controller_gains.{controller}.blend_accel=inf"]), lib, runtime="compiled"
    )
    assert not np.allclose(plain.u[:700], c.u[:700])  # the blend changed the run (dtsmc
    # diverges on paper-sim by 0.9 s with either start: docs/explanation/control.md)


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["amsfe", "truth-ct"])
def test_c_loop_on_the_6dof_ur5(controller: str) -> None:
    """The UR5 (ur5-control: unknown payload, rk4 estimator model): both comparisons."""
    sc = load_scenario("ur5-control").with_overrides(controller=controller, duration=0.3, seed=1)
    lib = library_for(sc)
    c = run(sc, lib, runtime="compiled")
    assert_same_run(run(sc, lib, runtime="python", compiled_estimator=True), c)
    assert_same_run(run(sc, lib), c)


def test_a_runs_files_are_the_same_on_both_runtimes(tmp_path: Path) -> None:
    """``amsfe simulate --runtime compiled|python`` write the same files with the same
    columns and keys; only the timing and the runtime's name differ."""
    import csv
    import json

    from amsfe_sym.apps.cli import main

    folders = {}
    for rt in ("compiled", "python"):
        folders[rt] = tmp_path / rt
        argv = ["simulate", "--controller", "amsfe", "--duration", "0.3", "--no-progress"]
        argv += ["--set", "controller_gains.amsfe.blend_accel=inf"]  # see BLENDED
        assert main([*argv, "--runtime", rt, "--out", str(folders[rt])]) == 0
    names = {rt: sorted(p.name for p in f.iterdir()) for rt, f in folders.items()}
    assert names["compiled"] == names["python"]
    rows = {}
    for rt, f in folders.items():
        with (f / "timeseries.csv").open() as fh:
            rows[rt] = list(csv.reader(fh))
    assert rows["compiled"][0] == rows["python"][0]
    a = np.array(rows["compiled"][1:], dtype=float)
    b = np.array(rows["python"][1:], dtype=float)
    np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-8)
    sums = {rt: json.loads((f / "summary.json").read_text()) for rt, f in folders.items()}
    assert sums["compiled"].keys() == sums["python"].keys()
    assert (sums["compiled"]["runtime"], sums["python"]["runtime"]) == ("compiled", "python")
    timing = {"runtime", "wall_time_s", "cost_per_tick_us", "provenance"}
    for key in set(sums["python"]) - timing:
        _same_leaves(sums["compiled"][key], sums["python"][key], key)


def _same_leaves(a: object, b: object, where: str) -> None:
    """Equal structure, numbers within 1e-6 (metrics of signals equal to 1e-8)."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same_leaves(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_leaves(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9, err_msg=where)
    else:
        assert a == b, where


def test_the_c_api_refuses_bad_parameter_blocks(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """amsfe_ctrl_init validates every parameter it accepts (issue 20 item 5): NaN gains, a
    negative actuator limit, a zero motor inertia, a theta index out of range are refused
    (memory size 0 / AMSFE_ERR_CONFIG -> ConfigError), not run for tens of ticks."""
    from dataclasses import replace

    from amsfe_sym.errors import ConfigError
    from amsfe_sym.runtime.compiled_loop import CompiledController
    from amsfe_sym.sim.builders import build_controller
    from amsfe_sym.sim.compiled import controller_params

    sc, lib = paper_sim
    ctrl, _ = build_controller(sc.with_overrides(controller="amsfe"), lib)
    good = controller_params(ctrl, lib)
    CompiledController(str(lib.library_path), good, lib.n)  # accepted
    n = lib.n
    bad = [
        replace(good, gains={**good.gains, "h": np.full(n, np.nan)}),
        replace(good, u_max=-np.ones(n)),
        replace(good, Mm=np.zeros(n)),
        replace(good, ks_theta=np.full(n, 7, dtype=np.int32)),
        replace(good, ready_q_std=float("nan")),
        replace(good, blend_accel=float("nan")),
        replace(good, blend_accel=-1.0),
        replace(good, blend_rate=float("nan")),
    ]
    for params in bad:
        with pytest.raises(ConfigError):
            CompiledController(str(lib.library_path), params, n)
