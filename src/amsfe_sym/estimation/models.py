"""What an estimator needs from a model, as small Protocols, plus linear implementations.

The estimators in this package never import CasADi or Pinocchio: they see the robot only
through :class:`TransitionModel` (the discrete transition ``F`` of the paper's eqs. (1a)-(1d),
(4), its jacobian, its inverse, eq. (22), and the process noise of eq. (3)) and
:class:`MeasurementModel` (``h`` of eqs. (5)-(9) and its jacobian). The compiled C functions
of ``generated/<name>/`` can be wrapped to satisfy them; :class:`LinearModel` and
:class:`LinearMeasurement` satisfy them for linear-Gaussian systems (tests, examples, and
any user with a linear plant).

Array conventions: every vector is a 1-D ``float64`` array, every matrix a 2-D one; a state
has ``nx`` entries, in the order of the paper's eq. (2) for the robot models.
"""

from __future__ import annotations

import warnings
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import ModelError, ShapeError, describe

__all__ = [
    "CameraFrame",
    "LinearMeasurement",
    "LinearModel",
    "MeasurementModel",
    "TransitionModel",
]


@runtime_checkable
class TransitionModel(Protocol):
    """Discrete transition ``x(k+1) = F(x(k), u(k)) + w(k)`` (paper eqs. (1a)-(1d), (4)).

    ``nx`` may be a plain attribute or a read-only property.
    """

    @property
    def nx(self) -> int:
        """State dimension ``N = 4n + p`` (paper eq. (2))."""
        ...

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(F(x, u), dF/dx)``: the next state ``(nx,)`` and its jacobian ``(nx, nx)``.

        Args:
            x: State at step k, shape ``(nx,)``.
            u: Input applied over ``[k, k+1]`` (motor torques [N m] for the robot models).
        """
        ...

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        """Return ``x`` with ``F(x, u) = x_next``: the backward map of the paper's eq. (22).

        Raises:
            ConvergenceError: An iterative inverse did not converge; estimators refuse the
                frame that needed it (counted, estimate untouched).
        """
        ...

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Return ``Qd = Gamma Qw Gamma^T`` ``(nx, nx)``: the covariance the step adds (eq. (3))."""
        ...


@runtime_checkable
class MeasurementModel(Protocol):
    """Measurement ``z = h(x) + v``, ``v ~ N(0, R)`` (paper eqs. (5)-(9)).

    ``dim`` and ``R`` may be plain attributes or read-only properties. Estimators read and
    validate ``R`` once, at construction.
    """

    @property
    def dim(self) -> int:
        """Measurement dimension."""
        ...

    @property
    def R(self) -> FloatArray:
        """Noise covariance ``(dim, dim)``, SPD, in the measurement's units."""
        ...

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(h(x), dh/dx)``: prediction ``(dim,)`` and jacobian ``(dim, nx)``."""
        ...


def _as_matrix(name: str, value: ArrayLike, shape: tuple[int, int] | None = None) -> FloatArray:
    arr = np.array(value, dtype=np.float64)
    if arr.ndim != 2 or (shape is not None and arr.shape != shape):
        expected = f"shape {shape}" if shape is not None else "a 2-D array"
        raise ShapeError(
            describe(name, expected, f"shape {arr.shape}", f"pass {name} as a {expected} matrix")
        )
    return arr


class LinearModel:
    """Linear transition ``x(k+1) = A x(k) + B u(k) + w(k)``, ``w ~ N(0, Q)``.

    Satisfies :class:`TransitionModel`. ``A`` must be invertible (the backward map of eq. (22)
    is ``A^-1 (x_next - B u)``); its LU factorisation is computed once, here.

    Args:
        A: State matrix ``(nx, nx)``, invertible.
        B: Input matrix ``(nx, nu)``; ``nu`` may be 0.
        Q: Process-noise covariance ``(nx, nx)`` added by each step.

    Raises:
        ShapeError: If the shapes disagree.
        ModelError: If ``A`` is singular.
    """

    def __init__(self, A: ArrayLike, B: ArrayLike, Q: ArrayLike) -> None:
        self.A = _as_matrix("A", A)
        nx = self.A.shape[0]
        if self.A.shape != (nx, nx):
            raise ShapeError(
                describe("A", "a square matrix", f"shape {self.A.shape}", "pass A as (nx, nx)")
            )
        self.B = _as_matrix("B", B)
        if self.B.shape[0] != nx:
            raise ShapeError(
                describe("B", f"{nx} rows", f"shape {self.B.shape}", "pass B as (nx, nu)")
            )
        self.Q = _as_matrix("Q", Q, (nx, nx))
        self.nx: int = nx
        self.nu: int = self.B.shape[1]
        with warnings.catch_warnings():  # a singular A warns; it is refused just below
            warnings.simplefilter("ignore", sla.LinAlgWarning)
            self._lu = sla.lu_factor(self.A, check_finite=True)
        if np.any(np.diag(self._lu[0]) == 0.0):
            raise ModelError(
                describe("A", "an invertible matrix", "a singular one", "make A invertible")
            )

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(A x + B u, A)``."""
        return self.A @ x + self.B @ u, self.A

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        """Return ``A^-1 (x_next - B u)`` (the exact backward map, eq. (22))."""
        result: FloatArray = sla.lu_solve(self._lu, x_next - self.B @ u, check_finite=False)
        return result

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Return ``Q`` (constant)."""
        return self.Q


class LinearMeasurement:
    """Linear measurement ``z = H x + offset + v``, ``v ~ N(0, R)``.

    Satisfies :class:`MeasurementModel`.

    Args:
        H: Measurement matrix ``(dim, nx)``.
        R: Noise covariance ``(dim, dim)``; validated as SPD by the estimator that uses it.
        offset: Constant ``(dim,)`` added to ``H x``; zero when omitted.
    """

    def __init__(self, H: ArrayLike, R: ArrayLike, offset: ArrayLike | None = None) -> None:
        self.H = _as_matrix("H", H)
        self.dim: int = self.H.shape[0]
        self.R = _as_matrix("R", R, (self.dim, self.dim))
        self.offset = np.zeros(self.dim) if offset is None else np.array(offset, dtype=np.float64)
        if self.offset.shape != (self.dim,):
            raise ShapeError(
                describe("offset", f"shape ({self.dim},)", f"shape {self.offset.shape}", "match H")
            )

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(H x + offset, H)``."""
        return self.H @ x + self.offset, self.H
