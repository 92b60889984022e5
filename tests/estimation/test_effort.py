"""What a log's effort is, and how the estimator uses it (issue 26, item 3;
docs/explanation/effort.md).

Pure parts (no library): the joint-torque measurement and the wrapped transitions against
finite differences, the input reconstruction against an accurate ODE solution and its noise
against Monte Carlo.  With the paper's 2-link library: the estimator re-run over a simulated
log with ``applied`` effort reproduces the run's own estimator, and every mode is consistent
(NEES in its chi-square band over seeds) on runs with known truth.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.stats import chi2

from amsfe_sym.errors import ConfigError, ShapeError
from amsfe_sym.estimation import LinearModel
from amsfe_sym.estimation.effort import (
    EffortSpec,
    MotorParams,
    estimator_inputs,
    input_noise_std,
    reconstruct_input,
)
from amsfe_sym.estimation.effort_models import (
    EffortModels,
    InputStateTransition,
    NetTorqueTransition,
    SpringTorqueMeasurement,
    trapezoid_input_gain,
    wrap_models,
)


def _motor(n: int = 3, p: int = 2, T: float = 1e-3) -> MotorParams:
    """Joint 1's stiffness is theta[1] (when p >= 2); the others are the spec's."""
    idx = np.full(n, -1, dtype=np.int32)
    if p >= 2:
        idx[1] = 1
    return MotorParams(
        Ks=np.linspace(10.0, 30.0, n),
        Mm=np.linspace(0.2, 0.5, n),
        Fm=np.linspace(0.5, 4.0, n),
        T=T,
        p=p,
        stiffness_theta=idx,
    )


def _fd_jacobian(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:  # type: ignore[no-untyped-def]
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.array(cols).T


def test_spring_torque_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(1)
    m = _motor()
    meas = SpringTorqueMeasurement(m, 1e-6, 1e-4, 0.05**2)
    for _ in range(5):
        x = rng.normal(size=m.N)
        x[4 * m.n + 1] = 20.0 + rng.normal()  # a stiffness, in theta
        z, H = meas.predict(x)
        Ks = m.Ks.copy()
        Ks[1] = x[4 * m.n + 1]
        n = m.n
        np.testing.assert_allclose(z[2 * n :], Ks * (x[2 * n : 3 * n] - x[:n]), rtol=1e-15)
        # h is bilinear: central differences are exact up to rounding
        H_fd = _fd_jacobian(lambda y: meas.predict(y)[0], x)
        np.testing.assert_allclose(H, H_fd, atol=1e-7)
        assert H[2 * n + 1, 4 * n + 1] != 0.0  # the bilinear term is there


def _linear_inner(m: MotorParams, rng: np.random.Generator) -> LinearModel:
    N = m.N
    A = np.eye(N) + 0.01 * rng.normal(size=(N, N))
    B = m.T * rng.normal(size=(N, m.n))  # an input acts over one step T
    return LinearModel(A, B, 1e-4 * np.eye(N))


def test_net_torque_transition_matches_finite_differences() -> None:
    rng = np.random.default_rng(2)
    m = _motor()
    inner = _linear_inner(m, rng)
    net = NetTorqueTransition(inner, m, lambda x, u, A: inner.B)
    x = rng.normal(size=m.N)
    x[4 * m.n + 1] = 15.0
    u = rng.normal(size=m.n)
    xn, A = net.step(x, u)
    s = net.spring(x)[0]
    np.testing.assert_allclose(xn, inner.A @ x + inner.B @ (u + s), rtol=1e-14)
    np.testing.assert_allclose(A, _fd_jacobian(lambda y: net.step(y, u)[0], x), atol=1e-6)
    np.testing.assert_allclose(net.inverse(xn, u), x, atol=1e-8)


def test_input_state_transition_matches_finite_differences() -> None:
    rng = np.random.default_rng(3)
    m = _motor()
    inner = _linear_inner(m, rng)
    aug = InputStateTransition(inner, m, 100.0, lambda x, u, A: inner.B)
    xa = rng.normal(size=m.N + m.n)
    ignored = rng.normal(size=m.n)
    xn, A = aug.step(xa, ignored)
    np.testing.assert_allclose(xn[: m.N], inner.A @ xa[: m.N] + inner.B @ xa[m.N :])
    np.testing.assert_array_equal(xn[m.N :], xa[m.N :])
    np.testing.assert_allclose(A, _fd_jacobian(lambda y: aug.step(y, ignored)[0], xa), atol=1e-7)
    Q = aug.process_noise(xa, ignored)
    np.testing.assert_allclose(np.diag(Q)[m.N :], 100.0**2 * m.T)
    np.testing.assert_allclose(aug.inverse(xn, ignored), xa, atol=1e-10)


def _motor_run(T: float, steps: int, Fm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """qmd samples and spring torques of ``Mm qmdd = u - Fm qmd - tau(t)``, u held per step
    (solve_ivp at rtol 1e-12), and the held u."""
    Mm = 0.5
    u = 3.0 * np.sin(0.7 * np.arange(steps))  # a new value every step

    def tau(t: float) -> float:
        return 2.0 * np.sin(3.0 * t) + 0.5 * t

    qmd = [0.3]
    for k in range(steps):
        sol = solve_ivp(
            lambda t, y, k=k: [(u[k] - Fm * y[0] - tau(t)) / Mm],
            (k * T, (k + 1) * T),
            [qmd[-1]],
            rtol=1e-12,
            atol=1e-14,
        )
        qmd.append(sol.y[0, -1])
    t = np.arange(steps + 1) * T
    return np.array(qmd)[:, None], np.array([tau(ti) for ti in t])[:, None], u


@pytest.mark.parametrize("Fm", [0.0, 4.0])
def test_reconstruct_input_is_second_order(Fm: float) -> None:
    errs = []
    for T in (0.02, 0.01):
        steps = round(0.2 / T)
        qmd, tau, u = _motor_run(T, steps, Fm)
        m = MotorParams(Ks=[10.0], Mm=[0.5], Fm=[Fm], T=T)
        u_hat = reconstruct_input(qmd, tau, m)[:-1, 0]
        errs.append(np.max(np.abs(u_hat - u)))
    assert errs[0] / errs[1] > 3.5  # the trapezoid rule: error ~ T^2
    assert errs[1] < 1e-3 * np.max(np.abs(u))


def test_input_noise_std_matches_monte_carlo() -> None:
    rng = np.random.default_rng(4)
    m = _motor(n=2, p=0)
    qd_std, tau_std = 0.01, 0.05
    K = 200_000
    v = qd_std * rng.standard_normal((K, 2))
    e = tau_std * rng.standard_normal((K, 2))
    err = reconstruct_input(v, e, m)[:-1]  # the clean signals are 0
    spec = EffortSpec(kind="joint_torque", joint_torque_std=tau_std, input_model="reconstruct")
    np.testing.assert_allclose(err.std(axis=0), input_noise_std(spec, m, qd_std), rtol=0.01)
    none = EffortSpec(kind="none", input_model="reconstruct")
    err_none = reconstruct_input(v, 0 * e, m)[:-1]
    np.testing.assert_allclose(err_none.std(axis=0), input_noise_std(none, m, qd_std), rtol=0.01)
    assert np.all(input_noise_std(EffortSpec(kind="none"), m, qd_std) == 0.0)  # as states


def test_estimator_inputs_per_kind() -> None:
    m = _motor(n=2, p=0)
    rng = np.random.default_rng(5)
    z = rng.normal(size=(10, 4))
    tau = rng.normal(size=(10, 2))
    applied = estimator_inputs(EffortSpec(), z, tau, m, 0.01)
    np.testing.assert_array_equal(applied.u, tau)
    jt = estimator_inputs(
        EffortSpec(kind="joint_torque", input_model="reconstruct"), z, tau, m, 0.01
    )
    np.testing.assert_array_equal(jt.z_encoder, np.hstack([z, tau]))
    np.testing.assert_allclose(jt.u, reconstruct_input(z[:, 2:], tau, m))
    state = estimator_inputs(EffortSpec(kind="none"), z, None, m, 0.01)
    assert state.z_encoder.shape == (10, 4) and not state.u.any()
    with pytest.raises(ShapeError, match='kind = "none"'):
        estimator_inputs(EffortSpec(kind="joint_torque"), z, None, m, 0.01)
    with pytest.raises(ShapeError, match="one row per encoder sample"):
        estimator_inputs(EffortSpec(), z, tau[:5], m, 0.01)
    with pytest.raises(ConfigError, match="joint_torque"):
        EffortSpec(kind="torque")
    with pytest.raises(ConfigError, match="input_model"):
        EffortSpec(kind="none", input_model="guess")


def test_wrap_models_starts_the_input_at_the_spring_torque() -> None:
    rng = np.random.default_rng(6)
    m = _motor(n=2, p=2)
    inner = _linear_inner(m, rng)
    meas = SpringTorqueMeasurement(m, 1e-6, 1e-4, 1e-2)
    x0 = rng.normal(size=m.N)
    P0 = np.eye(m.N)
    plain = EffortModels(inner, meas, meas, x0, P0)
    out = wrap_models(EffortSpec(kind="joint_torque"), m, plain, lambda *a: inner.B)
    n = m.n
    Ks = m.stiffness(x0[4 * n :])
    np.testing.assert_allclose(
        out.x0[m.N :], Ks * (x0[2 * n : 3 * n] - x0[:n]) + m.Fm * x0[3 * n : 4 * n]
    )
    assert out.P0.shape == (m.N + n, m.N + n)
    z, H = out.encoder.predict(out.x0)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(z, meas.predict(x0)[0])
    assert H.shape == (3 * n, m.N + n) and not H[:, m.N :].any()


def test_wrap_models_keeps_the_applied_models_and_wraps_a_reconstructed_net_torque() -> None:
    rng = np.random.default_rng(7)
    m = _motor(n=2, p=2)
    inner = _linear_inner(m, rng)
    meas = SpringTorqueMeasurement(m, 1e-6, 1e-4, 1e-2)
    plain = EffortModels(inner, meas, meas, rng.normal(size=m.N), np.eye(m.N))
    assert wrap_models(EffortSpec(), m, plain) is plain
    net = wrap_models(EffortSpec(kind="none", input_model="reconstruct"), m, plain)
    assert isinstance(net.model, NetTorqueTransition) and net.model.inner is inner
    assert net.encoder is meas and net.camera is meas
    assert net.x0 is plain.x0 and net.P0 is plain.P0


def test_trapezoid_input_gain_is_exact_for_the_motor_double_integrator() -> None:
    """A decoupled motor ``Mm qmdd = u - Fm qmd``: the exact discrete input gain is known."""
    from scipy.linalg import expm

    m = MotorParams(Ks=[0.0], Mm=[0.5], Fm=[0.0], T=1e-3)  # no spring, no friction
    Ac = np.zeros((4, 4))
    Ac[2, 3] = 1.0  # qm' = qmd
    A = expm(Ac * m.T)
    B = trapezoid_input_gain(m)(np.zeros(4), np.zeros(1), A)
    np.testing.assert_allclose(B[2:, 0], [m.T**2 / 2 / 0.5, m.T / 0.5], rtol=1e-12)


# ---------------------------------------------------------------- with the paper's 2-link arm


@pytest.fixture(scope="module")
def paper(libraries):  # type: ignore[no-untyped-def]
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario

    libraries.get("paper_2link")  # compiled once per session
    sc = load_scenario("paper-sim")
    return sc, library_for(sc)


def test_refilter_applied_reproduces_the_runs_estimator(paper) -> None:  # type: ignore[no-untyped-def]
    from amsfe_sym.sim.effort import refilter, simulated_effort
    from amsfe_sym.sim.loop import run

    sc, lib = paper
    sc = sc.with_overrides(duration=0.6, seed=11, estimator="replay")
    res = run(sc, lib)  # the Python loop: its estimator is the Python replay
    effort = simulated_effort(res, "applied", np.random.default_rng(0), 0.05)
    r = refilter(sc, res, effort, EffortSpec(), "replay")
    np.testing.assert_array_equal(r.x_hat, res.x_hat)
    assert r.frames_applied > 0


@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "input_model"),
    [
        ("applied", "state"),
        ("joint_torque", "state"),
        ("joint_torque", "reconstruct"),
        ("none", "state"),
    ],
)
def test_each_kind_is_consistent_over_seeds(  # type: ignore[no-untyped-def]
    paper, kind: str, input_model: str
) -> None:
    """Link-angle NEES averaged over M seeds lies in its two-sided 99 % chi-square band at
    most steps, and the estimate is close: seeds 500-505, never used to choose a design."""
    from amsfe_sym.sim.effort import refilter, simulated_effort
    from amsfe_sym.sim.loop import run

    sc, lib = paper
    logging.disable(logging.WARNING)
    try:
        series, rmse = [], []
        for seed in range(500, 506):
            sc_s = sc.with_overrides(duration=3.0, seed=seed)
            res = run(sc_s, lib, runtime="compiled")
            effort = simulated_effort(res, kind, np.random.default_rng(seed), 0.05)
            spec = EffortSpec(kind=kind, input_model=input_model)
            r = refilter(sc_s, res, effort, spec, "replay")
            w = slice(res.t.size // 5, None)
            series.append(r.nees_q[w])
            rmse.append(np.sqrt(np.mean(r.e_q[w] ** 2)))
    finally:
        logging.disable(logging.NOTSET)
    M, n = len(series), lib.n
    avg = np.mean(series, axis=0)
    lo, hi = chi2.ppf([0.005, 0.995], M * n) / M
    inside = np.mean((avg >= lo) & (avg <= hi))
    print(f"{kind}/{input_model}: {inside:.3f} in band, RMSE max {max(rmse):.2e}")
    assert inside > 0.9, f"{kind}/{input_model}: {inside:.2f} of the steps in the band"
    assert max(rmse) < 0.02  # [rad]: the camera alone (none) keeps it within ~1 degree


def test_reconstruct_input_holds_over_missing_samples() -> None:
    m = MotorParams(Ks=[10.0], Mm=[0.5], Fm=[1.0], T=1e-3)
    qmd = np.linspace(0.0, 1.0, 8)[:, None]
    tau = np.ones_like(qmd)
    clean = reconstruct_input(qmd, tau, m)
    qmd[3] = np.nan  # rows 2 and 3 use it
    u = reconstruct_input(qmd, tau, m)
    assert np.isfinite(u).all()
    np.testing.assert_array_equal(u[[2, 3]], clean[[1, 1]])
    np.testing.assert_array_equal(u[4:], clean[4:])


@pytest.mark.slow
def test_the_band_catches_a_misstated_sensor_noise(paper) -> None:  # type: ignore[no-untyped-def]
    """The test above can fail: a log whose torque sensor is 10x noisier than the filter is
    told (0.05 N m logged, 0.005 assumed) leaves the link NEES out of its band."""
    from amsfe_sym.sim.effort import refilter, simulated_effort
    from amsfe_sym.sim.loop import run

    sc, lib = paper
    logging.disable(logging.WARNING)
    try:
        series = []
        for seed in range(510, 513):
            sc_s = sc.with_overrides(duration=2.0, seed=seed)
            res = run(sc_s, lib, runtime="compiled")
            effort = simulated_effort(res, "joint_torque", np.random.default_rng(seed), 0.05)
            spec = EffortSpec(kind="joint_torque", joint_torque_std=0.005)
            r = refilter(sc_s, res, effort, spec, "encoders")
            series.append(r.nees_q[res.t.size // 5 :])
    finally:
        logging.disable(logging.NOTSET)
    M, n = len(series), lib.n
    avg = np.mean(series, axis=0)
    lo, hi = chi2.ppf([0.005, 0.995], M * n) / M
    assert np.mean((avg >= lo) & (avg <= hi)) < 0.5


@pytest.mark.parametrize("estimator", ["oosm", "replay"])
def test_compiled_and_python_agree_on_an_applied_log(paper, estimator: str) -> None:  # type: ignore[no-untyped-def]
    """The one kind the C estimators take: the same estimates as the Python reference."""
    from amsfe_sym.sim.effort import refilter, simulated_effort
    from amsfe_sym.sim.loop import run

    sc, lib = paper
    sc = sc.with_overrides(duration=0.5, seed=12)
    res = run(sc, lib, runtime="compiled")
    effort = simulated_effort(res, "applied", np.random.default_rng(0), 0.05)
    py = refilter(sc, res, effort, EffortSpec(), estimator)
    c = refilter(sc, res, effort, EffortSpec(), estimator, compiled=True)
    assert py.frames_applied == c.frames_applied > 0
    np.testing.assert_allclose(c.x_hat, py.x_hat, rtol=0, atol=1e-9)


def test_trapezoid_input_gain_matches_finite_differences(paper) -> None:  # type: ignore[no-untyped-def]
    """dF/du of the compiled rk4 step: the trapezoid rule against central differences."""
    from amsfe_sym.runtime.models import CompiledTransition, noise_covariance
    from amsfe_sym.sim.builders import motor_params

    _sc, lib = paper
    model = CompiledTransition(lib, noise_covariance(lib, 0.1, 0.1, 0.0))
    gain = trapezoid_input_gain(motor_params(lib))
    rng = np.random.default_rng(7)
    n = lib.n
    for _ in range(3):
        x = np.concatenate([rng.uniform(-1, 1, 4 * n), lib.theta_true])
        u = rng.uniform(-20, 20, n)
        _xn, A = model.step(x, u)
        B = gain(x, u, A)
        B_fd = _fd_jacobian(lambda v, x=x: model.step(x, v)[0].copy(), u, h=1e-3)
        assert np.max(np.abs(B - B_fd)) < 1e-4 * np.max(np.abs(B_fd))
        impulse = lib.T * model.gamma(x, u)[:, n : 2 * n]
        assert np.max(np.abs(impulse - B_fd)) > 10 * np.max(np.abs(B - B_fd))


def test_effort_spec_from_a_log_spec_table() -> None:
    from amsfe_sym.estimation.effort import effort_spec

    assert effort_spec({}) == EffortSpec()
    spec = effort_spec({"kind": "joint_torque", "joint_torque_std": 0.1, "input_rate_std": 30})
    assert spec == EffortSpec(kind="joint_torque", joint_torque_std=0.1, input_rate_std=30.0)
    with pytest.raises(ConfigError, match="unknown \\['knd'\\]"):
        effort_spec({"knd": "none"})
    with pytest.raises(ConfigError, match="a number"):
        effort_spec({"joint_torque_std": "0.1"})
    with pytest.raises(ConfigError, match="positive"):
        effort_spec({"joint_torque_std": -1.0})


def test_a_scaled_effort_is_in_newton_metres() -> None:
    """A UR-style log of motor currents [A] with a torque constant x gear ratio [N m/A]."""
    m = _motor(n=2, p=0)
    rng = np.random.default_rng(8)
    z = rng.normal(size=(6, 4))
    amps = rng.normal(size=(6, 2))
    scaled = estimator_inputs(EffortSpec(scale=13.5), z, amps, m, 0.01)
    np.testing.assert_allclose(scaled.u, 13.5 * amps, rtol=1e-15)
    with pytest.raises(ConfigError, match="scale"):
        EffortSpec(scale=0.0)
