"""EKF building blocks: agreement with filterpy, Joseph form, gating, A1 against Bar-Shalom.

Tolerances: filterpy computes the same Joseph-form formulas with an explicit inverse of S
(we use a Cholesky solve); on O(1) matrices of size 5 the two differ by a few ulp, so 1e-12
absolute is a safe yet tight bound. The A1 example reproduces numbers printed to 3 decimals.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, ShapeError
from amsfe_sym.estimation import (
    A1Correction,
    EncodersEstimator,
    FilterConfig,
    LinearMeasurement,
    LinearModel,
    gate_threshold,
    joseph_update,
    predict,
)
from amsfe_sym.estimation.ekf import validate_spd
from amsfe_sym.estimation.oosm import a1_correct, a1_retrodict, al1_retrodict

FloatArray = NDArray[np.float64]


def random_spd(rng: np.random.Generator, n: int, floor: float = 0.1) -> FloatArray:
    L = rng.standard_normal((n, n))
    return L @ L.T / n + floor * np.eye(n)


class SinMeasurement:
    """A nonlinear measurement: z = [sin(x0) + x2, x1^2 / 2]."""

    dim = 2

    def __init__(self, R: FloatArray) -> None:
        self.R = R

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        z = np.array([math.sin(x[0]) + x[2], 0.5 * x[1] ** 2])
        H = np.zeros((2, x.shape[0]))
        H[0, 0] = math.cos(x[0])
        H[0, 2] = 1.0
        H[1, 1] = x[1]
        return z, H


def test_predict_update_match_filterpy() -> None:
    rng = np.random.default_rng(20240601)
    nx, nu = 5, 2
    A = np.eye(nx) + 0.1 * rng.standard_normal((nx, nx))
    B = rng.standard_normal((nx, nu))
    Q = random_spd(rng, nx, 0.01)
    P0 = random_spd(rng, nx)
    x0 = rng.standard_normal(nx)
    u = rng.standard_normal(nu)
    R = random_spd(rng, 2, 0.05)
    meas = SinMeasurement(R)
    model = LinearModel(A, B, Q)
    z = meas.predict(A @ x0 + B @ u)[0] + rng.normal(0.0, 0.3, 2)

    ref = ExtendedKalmanFilter(dim_x=nx, dim_z=2, dim_u=nu)
    ref.x = x0.reshape(-1, 1).copy()
    ref.P = P0.copy()
    ref.F = A
    ref.B = B
    ref.Q = Q
    ref.R = R
    ref.predict(u.reshape(-1, 1))
    ref.update(
        z.reshape(-1, 1),
        lambda xc: meas.predict(xc.ravel())[1],
        lambda xc: meas.predict(xc.ravel())[0].reshape(-1, 1),
    )

    pred = predict(model, x0, P0, u)
    z_hat, H = meas.predict(pred.x)
    upd = joseph_update(pred.x, pred.P, z - z_hat, H, R)
    assert upd.accepted
    np.testing.assert_allclose(upd.x, ref.x.ravel(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(upd.P, ref.P, rtol=0, atol=1e-12)

    # The same step through the estimator interface.
    est = EncodersEstimator(
        model,
        meas,
        LinearMeasurement(np.eye(nx)[:1], [[1.0]]),
        x0,
        P0,
        FilterConfig(gate_probability=None),
    )
    report = est.step(u, z)
    assert report.encoder_accepted
    x, P = est.estimate()
    np.testing.assert_allclose(x, ref.x.ravel(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(P, ref.P, rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 7), m=st.integers(1, 4))
def test_joseph_update_keeps_p_symmetric_positive_definite(seed: int, n: int, m: int) -> None:
    rng = np.random.default_rng(seed)
    P = random_spd(rng, n, 1e-3)
    R = random_spd(rng, m, 1e-3)
    H = rng.standard_normal((m, n))
    nu = rng.standard_normal(m)
    upd = joseph_update(np.zeros(n), P, nu, H, R)
    assert np.array_equal(upd.P, upd.P.T)
    np.linalg.cholesky(upd.P)
    # Posterior never exceeds the prior (Loewner order): P - P+ is PSD.
    assert np.linalg.eigvalsh(P - upd.P)[0] > -1e-10 * np.abs(P).max()


def test_gate_threshold_and_rejection() -> None:
    assert gate_threshold(None, 3) == math.inf
    # chi2(2) has survival exp(-t/2): the 0.9999 quantile is -2 ln(1e-4).
    assert gate_threshold(0.9999, 2) == pytest.approx(-2.0 * math.log(1e-4), rel=1e-12)
    P = np.eye(2)
    R = np.eye(2)
    gate = gate_threshold(0.9999, 2)  # 18.42
    inside = joseph_update(np.zeros(2), P, np.array([2.0, 2.0]), np.eye(2), R, gate)  # NIS 4
    outside = joseph_update(np.zeros(2), P, np.array([10.0, 0.0]), np.eye(2), R, gate)  # NIS 50
    assert inside.accepted and inside.nis == pytest.approx(4.0)
    assert not outside.accepted and outside.nis == pytest.approx(50.0)
    assert outside.x is not None and np.array_equal(outside.P, P)


def test_validate_spd_messages() -> None:
    with pytest.raises(ConfigError, match=r"P0.*smallest eigenvalue -1"):
        validate_spd("P0", np.diag([1.0, -1.0]), 2)
    with pytest.raises(ConfigError, match="symmetric"):
        validate_spd("R", [[1.0, 0.5], [0.0, 1.0]], 2)
    with pytest.raises(ConfigError, match="finite"):
        validate_spd("R", [[np.nan, 0.0], [0.0, 1.0]], 2)
    with pytest.raises(ShapeError, match=r"shape \(3, 3\)"):
        validate_spd("R", np.eye(2), 3)


def test_a1_reproduces_bar_shalom_2002_table_1() -> None:
    """Bar-Shalom (2002) Example 1: scalar random walk, OOSM half-way through the interval.

    Q = R = 1, P(k-1|k-1) = 1, so P(k|k-1) = 2, S(k) = 3, P(k|k) = 2/3; Q(k, kappa) = 0.5.
    Table I (optimal column): P(kappa|k) = 0.750, W = 0.286, P(k|kappa) = 0.524, which also
    equals chronological processing (k-1, kappa, k). F = 1, so Fb = 1 and G = Hc = 1.
    """
    P_prior = np.array([[2.0]])
    S = np.array([[3.0]])
    P_post = np.array([[2.0 / 3.0]])
    nu = np.array([0.7])  # any value: the covariances do not depend on it
    last = joseph_update(np.zeros(1), P_prior, nu, np.eye(1), np.eye(1))
    assert last.accepted
    np.testing.assert_allclose(last.P, P_post, rtol=1e-14)
    np.testing.assert_allclose(last.S_chol @ last.S_chol.T, S, rtol=1e-14)
    retro = a1_retrodict(last.x, last.P, np.array([[0.5]]), last)
    P_retro = retro.M  # Fb = 1
    assert P_retro[0, 0] == pytest.approx(0.75, abs=1e-12)
    corr = a1_correct(last.x, last.P, retro, np.eye(1), np.array([0.3]), np.eye(1), math.inf)
    assert isinstance(corr, A1Correction) and corr.accepted and corr.W is not None
    assert corr.W[0, 0] == pytest.approx(0.5 / 1.75, abs=1e-12)  # 0.286
    assert corr.P[0, 0] == pytest.approx(2.0 / 3.0 - 0.25 / 1.75, abs=1e-12)  # 0.524
    assert round(corr.W[0, 0], 3) == 0.286 and round(corr.P[0, 0], 3) == 0.524
    # Chronological processing: predict half a step (0.5), update, predict, update.
    p = 1.0 + 0.5
    p = p - p * p / (p + 1.0)
    p = p + 0.5
    p = p - p * p / (p + 1.0)
    assert corr.P[0, 0] == pytest.approx(p, abs=1e-12)
    # The retrodicted state: x(kappa|k) = x(k|k) - Q H^T S^-1 nu.
    np.testing.assert_allclose(retro.v_hat, 0.5 / 3.0 * nu, rtol=1e-14)


def test_a1_without_intervening_update_is_the_plain_prediction() -> None:
    """No encoder update at k: v_hat = 0, Pvv = Pxv = Q, so P(kappa|k) = Fb (P - Q) Fb^T."""
    rng = np.random.default_rng(7)
    P = random_spd(rng, 3, 1.0)
    Q = random_spd(rng, 3, 0.01) * 0.1
    x = rng.standard_normal(3)
    retro = a1_retrodict(x, P, Q, None)
    np.testing.assert_array_equal(retro.x_shift, x)
    np.testing.assert_allclose(retro.M, P - Q, rtol=0, atol=1e-15)
    np.testing.assert_allclose(retro.C, P - Q, rtol=0, atol=1e-15)


def test_linear_model_inverse_inverts_step() -> None:
    rng = np.random.default_rng(3)
    A = np.eye(4) + 0.3 * rng.standard_normal((4, 4))
    model = LinearModel(A, rng.standard_normal((4, 2)), np.eye(4))
    x = rng.standard_normal(4)
    u = rng.standard_normal(2)
    x_next, jac = model.step(x, u)
    np.testing.assert_array_equal(jac, A)
    np.testing.assert_allclose(model.inverse(x_next, u), x, rtol=0, atol=1e-12)


def test_linear_model_rejects_bad_shapes_and_singular_a() -> None:
    from amsfe_sym.errors import ModelError

    with pytest.raises(ShapeError, match="square"):
        LinearModel(np.ones((2, 3)), np.ones((2, 1)), np.eye(2))
    with pytest.raises(ShapeError, match="rows"):
        LinearModel(np.eye(2), np.ones((3, 1)), np.eye(2))
    with pytest.raises(ModelError, match="invertible"):
        LinearModel(np.zeros((2, 2)), np.ones((2, 1)), np.eye(2))


def test_al1_is_one_lumped_rts_step() -> None:
    """Al1's retrodicted covariance equals the RTS smoother over the lag as one transition:
    Phi P(kappa|k) Phi^T = Phi [P(kappa|kappa) + J (P(k|k) - P(k|kappa)) J^T] Phi^T with
    J = P(kappa|kappa) Phi^T P(k|kappa)^-1, and the cross-covariance
    C = P(k|k) P(k|kappa)^-1 Phi P(kappa|kappa) Phi^T (an independent derivation)."""
    rng = np.random.default_rng(11)
    n = 4
    Phi = np.eye(n) + 0.2 * rng.standard_normal((n, n))
    P_kap = random_spd(rng, n, 0.2)
    Q = random_spd(rng, n, 0.05) * 0.3
    P_pred = Phi @ P_kap @ Phi.T + Q
    H = rng.standard_normal((2, n))
    upd = joseph_update(np.zeros(n), P_pred, rng.standard_normal(2), H, random_spd(rng, 2))
    retro = al1_retrodict(upd.x, upd.P, Q, np.zeros(n), P_pred)
    J = P_kap @ Phi.T @ np.linalg.inv(P_pred)
    P_smooth = P_kap + J @ (upd.P - P_pred) @ J.T
    np.testing.assert_allclose(retro.M, Phi @ P_smooth @ Phi.T, rtol=0, atol=1e-12)
    C_ref = upd.P @ np.linalg.inv(P_pred) @ Phi @ P_kap @ Phi.T
    np.testing.assert_allclose(retro.C, C_ref, rtol=0, atol=1e-12)
    # With a single update at k (no update inside the lag), Al1 is A1.
    a1 = a1_retrodict(upd.x, upd.P, Q, upd)
    np.testing.assert_allclose(retro.M, a1.M, rtol=0, atol=1e-12)
    np.testing.assert_allclose(retro.C, a1.C, rtol=0, atol=1e-12)
    np.testing.assert_allclose(retro.x_shift, a1.x_shift, rtol=0, atol=1e-12)


def test_chi2_ppf_equals_scipy_stats() -> None:
    """The gate's chi-square quantile from scipy.special equals scipy.stats.chi2.ppf exactly
    (the gates, NEES bands and NIS bands of every run use it)."""
    from scipy.stats import chi2

    from amsfe_sym.estimation.ekf import chi2_ppf

    for dof in (1, 2, 3, 4, 9, 14, 21, 29, 1800):
        for p in (1e-9, 0.025, 0.5, 0.95, 0.975, 0.9999, 1 - 1e-9):
            assert float(chi2_ppf(p, dof)) == float(chi2.ppf(p, dof)), (p, dof)
