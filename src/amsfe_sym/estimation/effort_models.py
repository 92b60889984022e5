"""The estimator's models for a log's kind of effort (docs/explanation/effort.md).

- :class:`SpringTorqueMeasurement`: encoders plus joint torque sensors (``joint_torque``);
- :class:`InputStateTransition`: the unknown input carried as random-walk states, and
  :class:`PaddedMeasurement` for the measurements of the robot's states in it;
- :class:`NetTorqueTransition`: the input is the net motor torque (``none``, reconstructed);
- :func:`trapezoid_input_gain`: ``dF/du`` of a held torque;
- :func:`wrap_models`: the models of an estimator for an
  :class:`~amsfe_sym.estimation.effort.EffortSpec`.

Pure numpy; the robot enters through :class:`~amsfe_sym.estimation.effort.MotorParams`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.estimation.effort import EffortSpec, MotorParams
from amsfe_sym.estimation.models import MeasurementModel, TransitionModel

__all__ = [
    "EffortModels",
    "InputGain",
    "InputStateTransition",
    "NetTorqueTransition",
    "PaddedMeasurement",
    "SpringTorqueMeasurement",
    "trapezoid_input_gain",
    "wrap_models",
]


class SpringTorqueMeasurement:
    """Encoders plus joint torque sensors: ``z = [qm, qmd, Ks (qm - q)] + v`` (eqs. (5), (1b)).

    A :class:`~amsfe_sym.estimation.models.MeasurementModel`.  With a joint's stiffness a
    theta parameter, ``h = theta_i (qm_j - q_j)`` is bilinear; its jacobian
    (``d/dq = -theta_i``, ``d/dqm = theta_i``, ``d/dtheta_i = qm_j - q_j``) is exact.

    Args:
        motor: Actuators and layout.
        q_var: Variance of qm [rad^2] (scalar or per joint).
        qd_var: Variance of qmd [rad^2/s^2].
        tau_var: Variance of the joint torque [N^2 m^2].
    """

    def __init__(
        self, motor: MotorParams, q_var: ArrayLike, qd_var: ArrayLike, tau_var: ArrayLike
    ) -> None:
        n, N = motor.n, motor.N
        self.motor = motor
        self.dim = 3 * n
        self.R = np.diag(
            np.concatenate(
                [
                    np.broadcast_to(np.asarray(v, dtype=float), (n,))
                    for v in (q_var, qd_var, tau_var)
                ]
            )
        )
        self._H = np.zeros((3 * n, N))
        self._H[:n, 2 * n : 3 * n] = np.eye(n)
        self._H[n : 2 * n, 3 * n : 4 * n] = np.eye(n)
        self._rows = np.arange(2 * n, 3 * n)
        self._cols_q = np.arange(n)
        self._cols_qm = np.arange(2 * n, 3 * n)

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(h(x), dh/dx)``: ``[qm, qmd, Ks (qm - q)]`` and its exact jacobian."""
        m = self.motor
        n = m.n
        Ks = m.stiffness(x[4 * n : m.N])
        delta = x[2 * n : 3 * n] - x[:n]
        H = self._H.copy()
        H[self._rows, self._cols_q] = -Ks
        H[self._rows, self._cols_qm] = Ks
        for j in np.flatnonzero(m.stiffness_theta >= 0):
            H[2 * n + j, 4 * n + m.stiffness_theta[j]] = delta[j]
        z = np.concatenate([x[2 * n : 4 * n], Ks * delta])
        return z, H


#: ``(x, u, A) -> dF/du`` (N, n): the input gain of a step, given its state jacobian ``A``.
InputGain = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]


def trapezoid_input_gain(motor: MotorParams) -> InputGain:
    """``dF/du`` of a step with the torque held over it, by the trapezoid rule.

    A torque held over ``[0, T]`` is the integral of impulses ``u ds / Mm`` on the motor rate
    (eq. (1b), motor rows), each carried to the end of the step by the transition matrix:
    ``dF/du = int_0^T Phi(T, s) ds e_qmd / Mm``, and with the trapezoid rule
    ``(T / 2) (A[:, qmd] + e_qmd) / Mm`` (``Phi(T, 0) e_qmd = A[:, qmd]``, ``Phi(T, T) = I``):
    free (``A`` is at hand), second order in T, exact on ``qm`` for the double integrator.
    Against central differences of the compiled rk4 step it is 2e-5 off (max relative) on the
    paper's arm (``test_trapezoid_input_gain_matches_finite_differences``); the impulse at the
    start of the step, ``T Gamma_m`` of eq. (4), is 4e-3 off there and twice the true value on
    the ``qm`` rows.
    """
    n, T = motor.n, motor.T
    cols = slice(3 * n, 4 * n)
    rows = np.arange(3 * n, 4 * n)

    def gain(x: FloatArray, u: FloatArray, A: FloatArray) -> FloatArray:
        B = A[: motor.N, cols].copy()
        B[rows, np.arange(n)] += 1.0
        result: FloatArray = B * (T / 2 / motor.Mm)
        return result

    return gain


class NetTorqueTransition:
    """A transition whose input is the net motor torque ``u_net = u - Ks (qm - q)`` (``none``).

    A :class:`~amsfe_sym.estimation.models.TransitionModel` around ``inner`` (the robot's
    ``F(x, u)`` of eqs. (1a)-(1d), (4)): ``F_net(x, u_net) = F(x, u_net + s(x))`` with the
    spring torque ``s(x) = Ks (qm - q)`` of the state (``Ks`` from theta where it is a
    parameter), and its jacobian ``dF/dx + (dF/du) ds/dx``, ``dF/du`` from ``input_gain``
    (default :func:`trapezoid_input_gain`).

    Args:
        inner: The robot's transition.
        motor: Actuators and layout.
        input_gain: ``(x, u, A) -> dF/du`` (N, n), ``A = dF/dx`` at ``(x, u)``.
        inverse_iterations: Newton steps of :meth:`inverse`.
    """

    def __init__(
        self,
        inner: TransitionLike,
        motor: MotorParams,
        input_gain: InputGain | None = None,
        inverse_iterations: int = 4,
    ) -> None:
        self.inner = inner
        self.motor = motor
        self.input_gain = input_gain or trapezoid_input_gain(motor)
        self.inverse_iterations = inverse_iterations
        self.nx: int = motor.N
        self.nu: int = motor.n

    def spring(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``s(x) = Ks (qm - q)`` [N m] and ``ds/dx`` (n, N)."""
        m = self.motor
        n = m.n
        Ks = m.stiffness(x[4 * n : m.N])
        delta = x[2 * n : 3 * n] - x[:n]
        D = np.zeros((n, m.N))
        j = np.arange(n)
        D[j, j] = -Ks
        D[j, 2 * n + j] = Ks
        for i in np.flatnonzero(m.stiffness_theta >= 0):
            D[i, 4 * n + m.stiffness_theta[i]] = delta[i]
        return Ks * delta, D

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(F(x, u + s(x)), dF/dx + dF/du ds/dx)``."""
        s, D = self.spring(x)
        ut = u + s
        xn, A = self.inner.step(x, ut)
        return xn, A + self.input_gain(x, ut, A) @ D

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        """``x`` with ``F(x, u + s(x)) = x_next`` (eq. 22): Newton steps with :meth:`step`'s
        jacobian from the inner inverse at ``s(x_next)``."""
        x = self.inner.inverse(x_next, u + self.spring(x_next)[0])
        for _ in range(self.inverse_iterations):
            xn, A = self.step(x, u)
            x = x - np.linalg.solve(A, xn - x_next)
        return x

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """The inner model's ``Qd`` at ``(x, u + s(x))``."""
        return self.inner.process_noise(x, u + self.spring(x)[0])


class TransitionLike(Protocol):
    """What :class:`NetTorqueTransition` needs of the model it wraps."""

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]: ...

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray: ...

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray: ...


class InputStateTransition:
    """The input carried as states: ``xa = [x, u]``, ``u`` a random walk (``joint_torque``,
    ``none`` with ``input_model = "state"``).

    A :class:`~amsfe_sym.estimation.models.TransitionModel` of size ``N + n``:
    ``F_a([x, u]) = [F(x, u), u]`` (eqs. (1a)-(1d), (4) with u held over the step), jacobian
    ``[[dF/dx, dF/du], [0, I]]``, process noise ``blockdiag(Qd(x, u), input_rate_std^2 T I)``.
    The input the estimator's ``step`` is given is ignored (pass zeros).  ``dF/du`` is
    ``input_gain`` (default :func:`trapezoid_input_gain`).

    Args:
        inner: The robot's transition (N states).
        motor: Actuators and layout.
        input_rate_std: Diffusion of the random walk [N m / sqrt(s)].
        input_gain: ``(x, u, A) -> dF/du`` (N, n), ``A = dF/dx`` at ``(x, u)``.
    """

    def __init__(
        self,
        inner: TransitionLike,
        motor: MotorParams,
        input_rate_std: float,
        input_gain: InputGain | None = None,
    ) -> None:
        self.inner = inner
        self.motor = motor
        self.input_gain = input_gain or trapezoid_input_gain(motor)
        N, n = motor.N, motor.n
        self.nx: int = N + n
        self.nu: int = n
        self._Qu = np.eye(n) * input_rate_std**2 * motor.T
        self._A = np.zeros((N + n, N + n))
        self._A[N:, N:] = np.eye(n)
        self._Q = np.zeros((N + n, N + n))

    @property
    def input_variance(self) -> FloatArray:
        """The random walk's process noise per step, ``input_rate_std^2 T I`` [N^2 m^2]."""
        return self._Qu.copy()

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``([F(x, u_s), u_s], [[A, B], [0, I]])`` with ``u_s`` the input states."""
        N = self.motor.N
        xs, us = x[:N], x[N:]
        xn, A = self.inner.step(xs, us)
        Aa = self._A.copy()
        Aa[:N, :N] = A
        Aa[:N, N:] = self.input_gain(xs, us, A)
        return np.concatenate([xn, us]), Aa

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        """``[F^-1(x+, u_s), u_s]`` (eq. 22; the input states do not move)."""
        N = self.motor.N
        return np.concatenate([self.inner.inverse(x_next[:N], x_next[N:]), x_next[N:]])

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """``blockdiag(Qd(x, u_s), input_rate_std^2 T I)``."""
        N = self.motor.N
        Q = self._Q.copy()
        Q[:N, :N] = self.inner.process_noise(x[:N], x[N:])
        Q[N:, N:] = self._Qu
        return Q


class _Measurement(Protocol):
    @property
    def dim(self) -> int: ...

    @property
    def R(self) -> FloatArray: ...

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]: ...


class PaddedMeasurement:
    """A measurement of the first ``N`` states seen from a state with ``extra`` more (the
    input states of :class:`InputStateTransition`): the same ``h``, ``H`` with zero columns."""

    def __init__(self, inner: _Measurement, N: int, extra: int) -> None:
        self.inner = inner
        self.N = N
        self.extra = extra
        self.dim: int = int(inner.dim)
        self.R: FloatArray = np.asarray(inner.R, dtype=float)

    def predict(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(h(x[:N]), [H, 0])``."""
        z, H = self.inner.predict(x[: self.N])
        return z, np.hstack([H, np.zeros((H.shape[0], self.extra))])


@dataclass(frozen=True)
class EffortModels:
    """The models and initial posterior of an estimator for a kind of effort.

    Attributes:
        model: The transition (the robot's, or wrapped).
        encoder: The encoder measurement model (``[qm, qmd]`` or ``[qm, qmd, tau_J]``).
        camera: The camera measurement model.
        x0: Initial mean, (nx,) (``N``, or ``N + n`` with the input states).
        P0: Initial covariance, (nx, nx).
    """

    model: TransitionModel
    encoder: MeasurementModel
    camera: MeasurementModel
    x0: FloatArray
    P0: FloatArray

    def estimator_args(self) -> dict[str, Any]:
        """The estimator constructor's arguments these give, by their names (``model``,
        ``encoder``, ``camera``, ``x0``, ``P0``), for
        :func:`~amsfe_sym.estimation.registry.make_estimator`."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def wrap_models(
    spec: EffortSpec,
    motor: MotorParams,
    plain: EffortModels,
    input_gain: InputGain | None = None,
    u0: FloatArray | None = None,
) -> EffortModels:
    """Wrap an estimator's models ``plain`` (the robot's, for the applied torque) for ``spec``
    (``plain.encoder`` is already the right one: :class:`SpringTorqueMeasurement` for
    ``joint_torque``).

    - ``applied``, or ``none`` reconstructed: unchanged, but ``none`` runs the
      :class:`NetTorqueTransition`;
    - input as states: :class:`InputStateTransition`, the measurements padded, ``x0`` extended
      with ``u0`` [N m] (default ``Ks (qm0 - q0) + Fm qmd0``, the torque that holds the spring
      at the initial estimate with the motor at constant speed; the builder passes the
      gravity torque ``g(q0) + Fm qmd0`` instead, which a wrong ``q0`` moves far less on a
      stiff joint), ``P0`` with ``spec.input_std0^2``.
    """
    if not spec.input_as_state:  # applied, or none reconstructed
        if spec.kind == "none":
            return replace(plain, model=NetTorqueTransition(plain.model, motor, input_gain))
        return plain
    n, N = motor.n, motor.N
    x0 = plain.x0
    if u0 is None:
        Ks = motor.stiffness(x0[4 * n : N])
        u0 = Ks * (x0[2 * n : 3 * n] - x0[:n]) + motor.Fm * x0[3 * n : 4 * n]
    P = np.zeros((N + n, N + n))
    P[:N, :N] = plain.P0
    P[N:, N:] = np.eye(n) * spec.input_std0**2
    return EffortModels(
        InputStateTransition(plain.model, motor, spec.input_rate_std, input_gain),
        PaddedMeasurement(plain.encoder, N, n),
        PaddedMeasurement(plain.camera, N, n),
        np.concatenate([x0, u0]),
        P,
    )
