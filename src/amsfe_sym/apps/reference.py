"""Reference models: numeric Pinocchio + numpy twins of the generated functions.

The one home of the Pinocchio numerics the toolkit compares its generated code with:

- :class:`PinocchioOracle`: every generated function from Pinocchio's ``crba``, ``nle``,
  ``computeCoriolisMatrix``, frame placements and ``aba`` (``amsfe check`` and the tests);
- :class:`PinocchioModel`: a fast numeric EKF model (semi-implicit transition from
  ``computeABADerivatives``, frame-jacobian camera, RK4 plant) that ``amsfe bench`` times;
- :func:`spong_rk4`: the continuous Spong model integrated with RK4 on ``pin.aba``, shared
  by both.

Only ``check``, ``bench`` and the tests import this module (it needs Pinocchio).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.load import Robot

__all__ = ["PinocchioModel", "PinocchioOracle", "skew", "spong_rk4"]

FloatArray = NDArray[np.float64]
Array = FloatArray


def spong_rk4(
    model: Any,
    data: Any,
    to_pin_q: Callable[[FloatArray], FloatArray],
    Ks: FloatArray,
    Fm: FloatArray,
    Mm: FloatArray,
    xp: FloatArray,
    u: FloatArray,
    tau_d: FloatArray,
    duration: float,
    steps: int,
) -> FloatArray:
    """``steps`` RK4 steps over ``duration`` [s] of the continuous Spong model on ``pin.aba``.

    ``xp = [q, qd, qm, qmd]``; the links see the spring torque Ks (qm - q) plus
    ``tau_d[:n]``, the motors ``u + tau_d[n:] - Fm qmd - Ks (qm - q)`` [N m].
    """
    n = Ks.size

    def rhs(s: FloatArray) -> FloatArray:
        q, qd, qm, qmd = s[:n], s[n : 2 * n], s[2 * n : 3 * n], s[3 * n :]
        delta = qm - q
        qdd = pin.aba(model, data, to_pin_q(q), qd, Ks * delta + tau_d[:n])
        qmdd = (u + tau_d[n:] - Fm * qmd - Ks * delta) / Mm
        return np.concatenate([qd, qdd, qmd, qmdd])

    h = duration / steps
    s = np.array(xp, dtype=float)
    for _ in range(steps):
        k1 = rhs(s)
        k2 = rhs(s + 0.5 * h * k1)
        k3 = rhs(s + 0.5 * h * k2)
        k4 = rhs(s + h * k3)
        s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s


class PinocchioOracle:
    """Pinocchio-based numeric reference of every generated function (``amsfe check``).

    Each call builds the Pinocchio model at the given theta: slow, simple, and independent
    of the symbolic layer.

    Args:
        robot: The loaded robot.
    """

    def __init__(self, robot: Robot) -> None:
        self.r = robot
        self.n = robot.n
        self.T = robot.spec.model.T

    def model(self, theta: Array) -> tuple[pin.Model, pin.Data]:
        m = self.r.pin_model_at(theta)
        return m, m.createData()

    def M(self, q: Array, theta: Array) -> Array:
        m, d = self.model(theta)
        M = pin.crba(m, d, self.r.to_pin_q(q))
        return np.triu(M) + np.triu(M, 1).T

    def nle(self, q: Array, qd: Array, theta: Array) -> Array:
        m, d = self.model(theta)
        return np.asarray(pin.nle(m, d, self.r.to_pin_q(q), qd))

    def g(self, q: Array, theta: Array) -> Array:
        m, d = self.model(theta)
        return np.asarray(pin.computeGeneralizedGravity(m, d, self.r.to_pin_q(q)))

    def f_link(self, q: Array, qd: Array, theta: Array) -> Array:
        m, d = self.model(theta)
        C = pin.computeCoriolisMatrix(m, d, self.r.to_pin_q(q), qd)
        return np.asarray(C.T @ qd) - self.g(q, theta)

    def point(self, q: Array, theta: Array) -> Array:
        m, d = self.model(theta)
        pin.framesForwardKinematics(m, d, self.r.to_pin_q(q))
        return np.asarray(d.oMf[self.r.tracked_frame_id].act(self.r.tracked_offset))

    def split(self, x: Array) -> tuple[Array, Array, Array, Array, Array]:
        n = self.n
        return x[:n], x[n : 2 * n], x[2 * n : 3 * n], x[3 * n : 4 * n], x[4 * n :]

    def transition(self, x: Array, u: Array) -> Array:
        q, qd, qm, qmd, th = self.split(x)
        T, r, n = self.T, self.r, self.n
        Ks = r.stiffness_at(th)
        delta = qm - q
        if r.spec.model.integrator == "rk4":
            xp = self.rk4(x[: 4 * n], u, th, np.zeros(2 * n), T, r.spec.model.model_substeps)
            return np.concatenate([xp, th])
        if r.spec.model.integrator == "paper":
            q1 = q + T * qd
            mom = self.M(q, th) @ qd + T * (Ks * delta + self.f_link(q, qd, th))
            qd1 = np.linalg.solve(self.M(q1, th), mom)
            qm1 = qm + T * qmd
            qmd1 = qmd + T * (u - r.Fm * qmd - Ks * delta) / r.Mm
        else:
            qd1 = qd + T * np.linalg.solve(self.M(q, th), Ks * delta - self.nle(q, qd, th))
            q1 = q + T * qd1
            qmd1 = qmd + T * (u - r.Fm * qmd - Ks * delta) / r.Mm
            qm1 = qm + T * qmd1
        return np.concatenate([q1, qd1, qm1, qmd1, th])

    def noise_gain(self, x: Array, u: Array) -> Array:
        n, p, T = self.n, self.r.p, self.T
        q, qd, _, _, th = self.split(x)
        G = np.zeros((4 * n + p, 2 * n + p))
        if self.r.spec.model.integrator == "rk4":
            # impulses at the start of the step, then the model's RK4 steps: central differences
            m = self.r.spec.model.model_substeps
            Minv = np.linalg.inv(self.M(q, th))
            h = 1e-6
            for i in range(2 * n):
                dx = np.zeros(4 * n)
                if i < n:
                    dx[n : 2 * n] = Minv[:, i] * h
                else:
                    dx[3 * n + i - n] = h / self.r.Mm[i - n]
                xp = x[: 4 * n]
                zero = np.zeros(2 * n)
                G[: 4 * n, i] = (
                    self.rk4(xp + dx, u, th, zero, T, m) - self.rk4(xp - dx, u, th, zero, T, m)
                ) / (2 * h)
            G[4 * n :, 2 * n :] = T * np.eye(p)
            return G
        mm = np.diag(1.0 / self.r.Mm)
        if self.r.spec.model.integrator == "paper":
            G[n : 2 * n, :n] = np.linalg.inv(self.M(q + T * qd, th))
            G[3 * n : 4 * n, n : 2 * n] = mm
        else:
            Minv = np.linalg.inv(self.M(q, th))
            G[:n, :n] = T * Minv
            G[n : 2 * n, :n] = Minv
            G[2 * n : 3 * n, n : 2 * n] = T * mm
            G[3 * n : 4 * n, n : 2 * n] = mm
        G[4 * n :, 2 * n :] = T * np.eye(p)
        return G

    def plant_step(self, xp: Array, u: Array, theta: Array, tau_d: Array) -> Array:
        S = self.r.spec.model.plant_substeps
        return self.rk4(xp, u, theta, tau_d, self.T, S)

    def rk4(
        self, xp: Array, u: Array, theta: Array, tau_d: Array, duration: float, steps: int
    ) -> Array:
        """``steps`` RK4 steps over ``duration`` [s] of the Spong model, on pin.aba."""
        m, d = self.model(theta)
        r = self.r
        return spong_rk4(
            m, d, r.to_pin_q, r.stiffness_at(theta), r.Fm, r.Mm, xp, u, tau_d, duration, steps
        )


class PinocchioModel:
    """Numeric Pinocchio + numpy equivalents of the generated functions, cached for speed
    (``amsfe bench`` times them next to the generated code).

    The transition is a semi-implicit Euler step (the ``semi_implicit`` integrator) built on
    ``pin.computeABADerivatives``, which returns qdd = ABA(q, qd, tau), its derivatives and
    M^-1 in one pass; x+, A = dF/dx (without the d/dtheta column) and Gamma are assembled in
    numpy.  It is what a hand-written numeric EKF model would do, and it satisfies the
    estimator's ``TransitionModel`` protocol, so :func:`amsfe_sym.estimation.ekf.predict`
    can run on it.

    Args:
        robot: The loaded robot (:func:`amsfe_sym.load.load_robot`).
        Qw: Process-noise covariance of w = [w_l, w_m, w_theta].
    """

    def __init__(self, robot: Robot, Qw: FloatArray) -> None:
        self.pin = pin
        self.robot = robot
        self.n, self.p, self.N = robot.n, robot.p, robot.N
        self.T = float(robot.spec.model.T)
        self.model = robot.pin_model_at(robot.theta_true)
        self.data = self.model.createData()
        self.Ks = robot.stiffness_at(robot.theta_true)
        self.Mm, self.Fm = robot.Mm, robot.Fm
        self.Qw = Qw
        self.identity_q = self.model.nq == self.n
        self.frame = robot.tracked_frame_id
        self.offset = robot.tracked_offset
        cam = robot.camera
        self.R_cw, self.c, self.K = cam.R_cw, cam.position, cam.K
        self._A = np.zeros((self.N, self.N))
        self._G = np.zeros((self.N, 2 * self.n + self.p))

    def q_pin(self, q: FloatArray) -> FloatArray:
        return q if self.identity_q else np.asarray(self.robot.to_pin_q(q))

    def mass_matrix(self, q: FloatArray) -> FloatArray:
        return np.asarray(self.pin.crba(self.model, self.data, self.q_pin(q)))

    def transition_step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, ...]:
        """x+, A, Gamma of one semi-implicit Euler step (eqs. 1, 3, 4 in that form)."""
        n, T, Ks, Mm, Fm = self.n, self.T, self.Ks, self.Mm, self.Fm
        q, qd, qm, qmd = x[:n], x[n : 2 * n], x[2 * n : 3 * n], x[3 * n : 4 * n]
        delta = qm - q
        dq_dq, dq_dv, Minv = self.pin.computeABADerivatives(
            self.model, self.data, self.q_pin(q), qd, Ks * delta
        )
        qdd = self.data.ddq
        qmdd = (u - Fm * qmd - Ks * delta) / Mm
        qd1 = qd + T * qdd
        qmd1 = qmd + T * qmdd
        xn = np.concatenate([q + T * qd1, qd1, qm + T * qmd1, qmd1, x[4 * n :]])
        MK = Minv * Ks  # d qdd / d qm (columns scaled by Ks)
        dqd_dq = T * (dq_dq - MK)
        dqd_dqd = np.eye(n) + T * dq_dv
        dqd_dqm = T * MK
        A, G = self._A, self._G
        A[:] = 0.0
        s = slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n), slice(3 * n, 4 * n)
        A[s[1], s[0]], A[s[1], s[1]], A[s[1], s[2]] = dqd_dq, dqd_dqd, dqd_dqm
        A[s[0], s[0]] = np.eye(n) + T * dqd_dq
        A[s[0], s[1]], A[s[0], s[2]] = T * dqd_dqd, T * dqd_dqm
        A[s[3], s[0]] = np.diag(T * Ks / Mm)
        A[s[3], s[2]] = np.diag(-T * Ks / Mm)
        A[s[3], s[3]] = np.diag(1.0 - T * Fm / Mm)
        A[s[2]] = T * A[s[3]]
        A[s[2], s[2]] += np.eye(n)
        A[4 * n :, 4 * n :] = np.eye(self.p)
        G[s[1], :n] = Minv
        G[s[0], :n] = T * Minv
        G[s[3], n : 2 * n] = np.diag(1.0 / Mm)
        G[s[2], n : 2 * n] = np.diag(T / Mm)
        G[4 * n :, 2 * n :] = T * np.eye(self.p)
        return xn, A.copy(), G.copy()

    # the TransitionModel protocol (for ekf.predict)
    @property
    def nx(self) -> int:
        return self.N

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        xn, A, self._last_G = self.transition_step(x, u)
        return xn, A

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        raise NotImplementedError("the Pinocchio comparison model has no inverse transition")

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        G = self._last_G
        Q: FloatArray = G @ self.Qw @ G.T
        return Q

    def camera_measure(self, q: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """Pixels y, dy/dq and depth of the tracked point (eqs. 6-8) from Pinocchio's frame
        jacobian and a numpy pinhole."""
        pin = self.pin
        J = pin.computeFrameJacobian(
            self.model, self.data, self.q_pin(q), self.frame, pin.LOCAL_WORLD_ALIGNED
        )
        oMf = self.data.oMf[self.frame]
        lever = oMf.rotation @ self.offset
        r = oMf.translation + lever
        Jr = J[:3] - skew(lever) @ J[3:]
        pc = self.R_cw @ (r - self.c)
        fx, fy = self.K[0, 0], self.K[1, 1]
        y = np.array([fx * pc[0] / pc[2] + self.K[0, 2], fy * pc[1] / pc[2] + self.K[1, 2]])
        dy_dpc = np.array(
            [
                [fx / pc[2], 0.0, -fx * pc[0] / pc[2] ** 2],
                [0.0, fy / pc[2], -fy * pc[1] / pc[2] ** 2],
            ]
        )
        return y, dy_dpc @ self.R_cw @ Jr, float(pc[2])

    def plant_step(
        self, xp: FloatArray, u: FloatArray, tau_d: FloatArray, substeps: int
    ) -> FloatArray:
        """``substeps`` RK4 steps over T of the continuous plant on ``pin.aba``."""
        return spong_rk4(
            self.model,
            self.data,
            self.q_pin,
            self.Ks,
            self.Fm,
            self.Mm,
            xp,
            u,
            tau_d,
            self.T,
            substeps,
        )


def skew(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
