"""Adapters from a generated library to the estimator's model protocols.

:class:`CompiledTransition` is a :class:`~amsfe_sym.estimation.models.TransitionModel`
(eqs. 3, 4, 13, 14, 22) and :class:`EncoderMeasurement` / :class:`CameraMeasurement` are
:class:`~amsfe_sym.estimation.models.MeasurementModel` s (eqs. 5-9), all evaluated by the
compiled C functions through the preallocated ctypes binding.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, ConvergenceError, ShapeError, describe
from amsfe_sym.runtime.library import ModelLibrary

__all__ = [
    "CameraMeasurement",
    "CompiledTransition",
    "EncoderMeasurement",
    "inverse_not_converged",
    "noise_covariance",
]


def noise_covariance(
    lib: ModelLibrary,
    link_torque_std: ArrayLike,
    motor_torque_std: ArrayLike,
    theta_rate_std: ArrayLike,
) -> FloatArray:
    """Covariance Qw of the process noise w = [w_l, w_m, w_theta] of eq. (3).

    The noise enters as impulses over one step: a white link (motor) torque of standard
    deviation sigma [N m] held over T gives w_l = sigma T [N m s].  theta follows
    theta+ = theta + T w_theta with w_theta of standard deviation ``theta_rate_std``
    [unit/s] per step.

    Returns:
        Diagonal (2n + p) x (2n + p) matrix.
    """
    n, p, T = lib.n, lib.p, lib.T
    sl = np.broadcast_to(np.asarray(link_torque_std, dtype=float), (n,))
    sm = np.broadcast_to(np.asarray(motor_torque_std, dtype=float), (n,))
    st = np.broadcast_to(np.asarray(theta_rate_std, dtype=float), (p,))
    return np.diag(np.concatenate([(sl * T) ** 2, (sm * T) ** 2, st**2]))


def inverse_not_converged(residual: float, limit: float) -> str:
    """The message of a refused inverse transition (eq. 22): its generated ``residual``
    max|F(x, u) - x_next| is above ``limit`` (shared by the Python and the C runtime paths)."""
    return describe(
        "transition_inverse (eq. 22)",
        f"a residual max|F(x, u) - x_next| <= {limit:.1e}",
        f"{residual:.3g} (the unrolled iterations did not converge)",
        "raise [model] inverse_iterations, shorten T or soften Ks in the spec",
    )


class CompiledTransition:
    """x+ = F(x, u), A = dF/dx, F^-1 and Gamma Qw Gamma^T from the compiled library.

    One call of the fused ``transition_step`` gives x+, A and Gamma; ``process_noise``
    reuses that Gamma when called with the same (x, u), as the EKF predict does.  An rk4
    library beyond 2 joints has it chained in C (``transition_step_chain``, the same values
    to 1e-13, faster than the MX graph), which is called instead, as the C estimators do.

    Args:
        lib: The generated library.
        Qw: Covariance of w = [w_l, w_m, w_theta], (2n + p) x (2n + p) (see
            :func:`noise_covariance`).
        inverse_tol: Relative tolerance on the inverse's residual (see :meth:`inverse`).
    """

    def __init__(self, lib: ModelLibrary, Qw: ArrayLike, inverse_tol: float = 1e-10) -> None:
        self.lib = lib
        self.inverse_tol = inverse_tol
        chained = "transition_step_chain" in lib.manifest.functions
        self._step = lib.function("transition_step_chain" if chained else "transition_step")
        self._gain = lib.function("noise_gain")
        self._inv = lib.function("transition_inverse")
        m = 2 * lib.n + lib.p
        Q = np.asarray(Qw, dtype=float)
        if Q.shape != (m, m):
            raise ShapeError(
                describe("Qw", f"shape ({m}, {m})", str(Q.shape), "see noise_covariance")
            )
        if not np.allclose(Q, Q.T) or np.min(np.linalg.eigvalsh(Q)) < 0:
            raise ConfigError(
                describe(
                    "Qw",
                    "a symmetric positive semi-definite matrix",
                    str(np.diag(Q)),
                    "build it with noise_covariance() from standard deviations >= 0",
                )
            )
        self.Qw = Q
        self._last_x = np.full(lib.N, np.nan)
        self._last_u = np.full(lib.n, np.nan)
        self._G = np.zeros((lib.N, m))

    @property
    def nx(self) -> int:
        return self.lib.N

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        xn, A, G = self._step.call_into(x, u)
        self._last_x[:] = x
        self._last_u[:] = u
        self._G[:] = G
        return xn.copy(), A.copy()

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        """x = F^-1(x_next, u) (eq. 22), refused unless the generated iterations converged.

        Raises:
            ConvergenceError: The generated ``residual`` output, max|F(x, u) - x_next|, is
                above ``inverse_tol * max(1, max|x_next|)`` (or not finite).
        """
        x, res = self._inv.call_into(x_next, u)
        limit = self.inverse_tol * max(1.0, float(np.max(np.abs(x_next), initial=0.0)))
        if not res[0] <= limit:  # also catches NaN
            raise ConvergenceError(inverse_not_converged(float(res[0]), limit))
        return x.copy()

    def gamma(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Noise gain Gamma(x, u) = dF/dw (eq. 4)."""
        if np.array_equal(x, self._last_x) and np.array_equal(u, self._last_u):
            return self._G
        return self._gain.call_into(x, u)[0]

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        G = self.gamma(x, u)
        Q: FloatArray = G @ self.Qw @ G.T
        return Q


class EncoderMeasurement:
    """Motor encoders: z_m = [qm, qmd] + noise (eq. 5), linear in x.

    Args:
        lib: The generated library (for the state layout).
        q_var: Variance of qm [rad^2] (scalar or per joint).
        qd_var: Variance of qmd [rad^2/s^2].
    """

    def __init__(self, lib: ModelLibrary, q_var: ArrayLike, qd_var: ArrayLike) -> None:
        n, N = lib.n, lib.N
        self.dim = 2 * n
        self.H = np.zeros((2 * n, N))
        self.H[:n, lib.layout["qm"]] = np.eye(n)
        self.H[n:, lib.layout["qmd"]] = np.eye(n)
        self.R = np.diag(
            np.concatenate(
                [
                    np.broadcast_to(np.asarray(q_var, float), (n,)),
                    np.broadcast_to(np.asarray(qd_var, float), (n,)),
                ]
            )
        )

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.H @ x, self.H


class CameraMeasurement:
    """The pinhole camera y = I_k(q) (eq. 8), evaluated by the compiled ``camera_measure``.

    Args:
        lib: The generated library.
        pixel_var: Pixel variance [px^2] (scalar, or 2 values for u and v).
    """

    def __init__(self, lib: ModelLibrary, pixel_var: ArrayLike) -> None:
        if lib.manifest.camera_depends_on_theta:
            raise ConfigError(
                describe(
                    "camera model",
                    "a camera map independent of theta",
                    "one that depends on theta",
                    "not supported by this measurement model",
                )
            )
        self.dim = 2
        self.R = np.diag(np.broadcast_to(np.asarray(pixel_var, float), (2,)).copy())
        self._f = lib.function("camera_measure")
        self._q = lib.layout["q"]
        self._th = lib.layout["theta"]
        self._H = np.zeros((2, lib.N))

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        y, J, _depth = self._f.call_into(x[self._q], x[self._th])
        H = self._H.copy()
        H[:, self._q] = J
        return y.copy(), H
