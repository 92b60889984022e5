"""Core extended-Kalman-filter steps shared by every estimator.

Pure functions on arrays; no state. Equation numbers are the paper's (Sec. 3.1):

- :func:`predict`: eqs. (13)-(14), ``x- = F(x, u)``, ``P- = A P A^T + Qd``.
- :func:`joseph_update`: eqs. (15)-(16) for the gain and the state, and the Joseph form
  ``P = (I - K H) P- (I - K H)^T + K R K^T`` instead of the paper's eq. (17)
  ``(I - K H) P-``: it is algebraically equal for the optimal gain, but stays symmetric and
  positive semi-definite under rounding (a deliberate deviation, see
  ``docs/explanation/estimation-algorithms.md``).
- Innovation gating: the normalised innovation squared ``NIS = nu^T S^-1 nu`` is compared
  with a chi-square quantile computed once by :func:`gate_threshold`.

The innovation covariance is factorised with Cholesky, calling LAPACK ``potrf``/``potrs``
directly (scipy's ``cho_factor``/``cho_solve`` wrappers cost ~5-15 us a call, more than the
factorisation of a small matrix); no explicit inverse is formed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, EstimatorError, ShapeError, describe
from amsfe_sym.estimation.models import MeasurementModel, TransitionModel

__all__ = [
    "PredictResult",
    "UpdateResult",
    "cholesky_lower",
    "cholesky_solve",
    "gate_threshold",
    "joseph_update",
    "measure",
    "predict",
    "require_positive_definite",
    "symmetrize",
    "validate_spd",
]


_POTRF, _POTRS = sla.get_lapack_funcs(("potrf", "potrs"), dtype=np.float64)


def cholesky_lower(A: FloatArray) -> FloatArray | None:
    """Lower Cholesky factor of a symmetric matrix, or ``None`` if it is not positive definite.

    LAPACK ``potrf`` does not detect NaN: check finiteness first where it matters.
    """
    c, info = _POTRF(A, lower=1, clean=1)
    return c if info == 0 else None


def cholesky_solve(L: FloatArray, b: FloatArray) -> FloatArray:
    """Solve ``(L L^T) x = b`` for a vector or a matrix ``b`` (LAPACK ``potrs``)."""
    x, _ = _POTRS(L, b, lower=1)
    return x


def chi2_ppf(probability: ArrayLike, dof: float) -> FloatArray:
    """Quantile of the chi-square distribution with ``dof`` degrees of freedom:
    ``2 gammaincinv(dof / 2, p)``, what ``scipy.stats.chi2.ppf`` computes (equal to it,
    tests/estimation/test_estimation_ekf.py), from ``scipy.special``, which imports in ~0.2 s where
    ``scipy.stats`` takes ~0.7-1 s (paid by every ``amsfe estimate``)."""
    from scipy.special import gammaincinv

    out: FloatArray = 2.0 * np.asarray(gammaincinv(0.5 * dof, probability), dtype=np.float64)
    return out


def gate_threshold(probability: float | None, dim: int) -> float:
    """Chi-square gate on the NIS of a ``dim``-dimensional innovation.

    Args:
        probability: Probability mass of ``chi2(dim)`` accepted, in (0, 1); ``None`` disables
            the gate (threshold ``inf``).
        dim: Measurement dimension (degrees of freedom).

    Returns:
        The threshold ``chi2.ppf(probability, dim)``; an innovation is rejected when its
        NIS exceeds it.
    """
    if probability is None:
        return math.inf
    return float(chi2_ppf(probability, dim))


def symmetrize(P: FloatArray) -> FloatArray:
    """Return ``(P + P^T) / 2``."""
    result: FloatArray = 0.5 * (P + P.T)
    return result


def validate_spd(name: str, M: object, n: int) -> FloatArray:
    """Check a user-given covariance at construction time.

    Args:
        name: What the matrix is, for the message (``"P0"``, ``"encoder R"``).
        M: The matrix (array-like).
        n: Expected size.

    Returns:
        A float64 copy, exactly symmetrised.

    Raises:
        ShapeError: If it is not ``(n, n)``.
        ConfigError: If it is not finite, not symmetric, or not positive definite (the message
            gives the smallest eigenvalue).
    """
    arr = np.array(M, dtype=np.float64)
    if arr.shape != (n, n):
        raise ShapeError(describe(name, f"shape ({n}, {n})", f"shape {arr.shape}", "fix its size"))
    if not np.isfinite(arr).all():
        raise ConfigError(
            describe(name, "finite entries", "NaN or inf", f"give {name} finite values")
        )
    scale = max(1.0, float(np.max(np.abs(arr))))
    asym = float(np.max(np.abs(arr - arr.T)))
    if asym > 1e-9 * scale:
        raise ConfigError(
            describe(
                name,
                "a symmetric matrix",
                f"max |M - M^T| = {asym:.3g}",
                f"use ({name} + {name}.T) / 2",
            )
        )
    arr = symmetrize(arr)
    eig_min = float(np.linalg.eigvalsh(arr)[0])
    if eig_min <= 0.0:
        raise ConfigError(
            describe(
                name,
                "a positive definite matrix",
                f"smallest eigenvalue {eig_min:.6g}",
                f"make every eigenvalue of {name} > 0 (a variance of 0 is not allowed)",
            )
        )
    return arr


def require_positive_definite(P: FloatArray, what: str) -> None:
    """Raise :class:`EstimatorError` unless ``P`` is finite and Cholesky-factorisable.

    One Cholesky factorisation (``O(n^3 / 3)``); eigenvalues are computed only to write the
    message when the check fails.
    """
    if not np.isfinite(P).all():
        raise EstimatorError(
            describe(
                what,
                "a finite covariance",
                "NaN or inf entries",
                "check the model's step/jacobian/process_noise for non-finite output",
            )
        )
    if cholesky_lower(P) is None:
        eig_min = float(np.linalg.eigvalsh(symmetrize(P))[0])
        raise EstimatorError(
            describe(
                what,
                "a positive definite covariance",
                f"smallest eigenvalue {eig_min:.3g}",
                "make the process noise Qd positive definite, check the jacobians, or scale "
                "the state so that its covariances are not many orders of magnitude apart",
            )
        )


@dataclass(slots=True)
class PredictResult:
    """Output of :func:`predict`.

    Attributes:
        x: Predicted state ``x(k+1|k)``.
        P: Predicted covariance ``P(k+1|k)``.
        A: Transition jacobian ``dF/dx`` at ``x(k|k)``.
        Q: Process noise ``Qd`` added by the step.
    """

    x: FloatArray
    P: FloatArray
    A: FloatArray
    Q: FloatArray


def _check_output(
    what: str,
    outputs: dict[str, tuple[FloatArray, tuple[int, ...]]],
    finite: tuple[str, ...],
    shape_fix: str,
    finite_fix: str,
) -> None:
    """Refuse a model's outputs (name -> (array, expected shape)): a wrong shape raises
    :class:`ShapeError`, NaN or inf in one of those named in ``finite`` :class:`EstimatorError`."""
    if any(a.shape != shape for a, shape in outputs.values()):
        raise ShapeError(
            describe(
                what,
                ", ".join(f"{k} {shape}" for k, (_, shape) in outputs.items()),
                ", ".join(f"{k} {a.shape}" for k, (a, _) in outputs.items()),
                shape_fix,
            )
        )
    if not all(np.isfinite(outputs[k][0]).all() for k in finite):
        raise EstimatorError(
            describe(what, "finite " + " and ".join(finite), "NaN or inf", finite_fix)
        )


def predict(model: TransitionModel, x: FloatArray, P: FloatArray, u: FloatArray) -> PredictResult:
    """EKF prediction, paper eqs. (13)-(14).

    Args:
        model: Transition model.
        x: Posterior ``x(k|k)``, shape ``(nx,)``.
        P: Posterior ``P(k|k)``, shape ``(nx, nx)``.
        u: Input applied over ``[k, k+1]``.

    Returns:
        ``x(k+1|k) = F(x, u)``, ``P(k+1|k) = A P A^T + Qd``, with ``A`` and ``Qd``.

    Raises:
        ShapeError: If the model returns arrays of the wrong shape.
        EstimatorError: If the model returns non-finite values.
    """
    nx = x.shape[0]
    x_next, A = model.step(x, u)
    Q = model.process_noise(x, u)
    _check_output(
        "transition model output",
        {"x_next": (x_next, (nx,)), "A": (A, (nx, nx)), "Qd": (Q, (nx, nx))},
        ("x_next", "A"),
        "make step() and process_noise() return arrays of the model's nx",
        "check the state and input passed to step() (the state may have diverged)",
    )
    P_next = symmetrize(A @ P @ A.T + Q)
    return PredictResult(x=np.asarray(x_next, dtype=np.float64), P=P_next, A=A, Q=Q)


def measure(model: MeasurementModel, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Evaluate ``h(x)`` and ``dh/dx`` with shape checks.

    Raises:
        ShapeError: If the model's outputs do not have shapes ``(dim,)`` and ``(dim, nx)``.
        EstimatorError: If they are not finite.
    """
    z_hat, H = model.predict(x)
    dim = model.dim
    _check_output(
        "measurement model output",
        {"z_hat": (z_hat, (dim,)), "H": (H, (dim, x.shape[0]))},
        ("z_hat", "H"),
        "make predict() return h(x) and dh/dx of the model's dim",
        "check the measurement model at the current state (it may have diverged)",
    )
    return z_hat, H


@dataclass(slots=True)
class UpdateResult:
    """Output of :func:`joseph_update`.

    Attributes:
        accepted: False when the gate rejected the innovation (``x``, ``P`` are then the
            inputs, unchanged).
        nis: Normalised innovation squared ``nu^T S^-1 nu`` (dimensionless).
        x: Posterior state.
        P: Posterior covariance.
        nu: Innovation ``z - h(x-)``.
        S_chol: Lower Cholesky factor of ``S = H P- H^T + R``.
        H: Measurement jacobian used.
        P_prior: The prior covariance ``P-`` the update started from.
    """

    accepted: bool
    nis: float
    x: FloatArray
    P: FloatArray
    nu: FloatArray
    S_chol: FloatArray
    H: FloatArray
    P_prior: FloatArray


def joseph_update(
    x: FloatArray,
    P: FloatArray,
    nu: FloatArray,
    H: FloatArray,
    R: FloatArray,
    gate: float = math.inf,
) -> UpdateResult:
    """Kalman update in Joseph form (paper eqs. (15)-(16); Joseph form replaces eq. (17)).

    ``S = H P H^T + R``, ``K = P H^T S^-1``, ``x+ = x + K nu``,
    ``P+ = (I - K H) P (I - K H)^T + K R K^T``.

    Args:
        x: Prior state ``(n,)``.
        P: Prior covariance ``(n, n)``.
        nu: Innovation ``z - h(x)``, ``(m,)``.
        H: Measurement jacobian ``(m, n)``.
        R: Measurement noise covariance ``(m, m)``.
        gate: NIS threshold (see :func:`gate_threshold`); ``inf`` accepts everything.

    Returns:
        The :class:`UpdateResult`; when ``nis > gate`` it is not accepted and carries the
        unchanged prior.

    Raises:
        EstimatorError: If ``S`` is not positive definite.
    """
    PHt = P @ H.T
    S = symmetrize(H @ PHt + R)
    S_chol = cholesky_lower(S)
    if S_chol is None:
        raise EstimatorError(
            describe(
                "innovation covariance S = H P H^T + R",
                "positive definite",
                "a matrix Cholesky cannot factorise",
                "check R and the measurement jacobian for huge values",
            )
        )
    S_inv_nu = cholesky_solve(S_chol, nu)
    nis = float(nu @ S_inv_nu)
    if not nis <= gate:  # also rejects a NaN NIS
        return UpdateResult(False, nis, x, P, nu, S_chol, H, P)
    K = cholesky_solve(S_chol, PHt.T).T
    x_post = x + PHt @ S_inv_nu
    # The Joseph form, expanded: (I - K H) P (I - K H)^T + K R K^T
    # = P - K H P - P H^T K^T + K S K^T = P + V K^T + K V^T with V = K S / 2 - P H^T, for any
    # K (so it keeps the Joseph form's first-order insensitivity to an error in K); no N x N x N
    # product (N^2 m instead of 2 N^3 for an m-dimensional measurement).
    VKt = (K @ (0.5 * S) - PHt) @ K.T
    P_post = symmetrize(P + VKt + VKt.T)
    return UpdateResult(True, nis, x_post, P_post, nu, S_chol, H, P)
