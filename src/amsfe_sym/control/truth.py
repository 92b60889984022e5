"""A reference tracking controller on the true state and the true model.

Cascaded computed torque for the flexible-joint arm (Spong's singular-perturbation view):

1. link loop: the spring torque the link needs,
   ``tau = M(q) (qdd_d + Kd (qd_d - qd) + Kp (q_d - q)) + b(q, qd)``;
2. motor set point that produces it: ``qm_d = q + Ks^-1 tau``;
3. motor loop: ``u = Ks (qm - q) + Fm qmd + Mm (qmdd_d + Kpm (qm_d - qm) + Kdm (qmd_d - qmd))``
   with ``qmd_d`` and ``qmdd_d`` the backward differences of ``qm_d`` over the control steps
   (on a soft arm ``Ks^-1 tau`` moves by radians at the trajectory's frequency, so leaving
   these feedforward terms out costs 10-30 % amplitude error on paper-sim).

It reads the true state and uses the true theta, so it isolates the estimator in
estimation studies; it is not a controller one could run on hardware.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.control.base import Controller, LawInputs, register
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.signals.trajectory import Trajectory

__all__ = ["TruthComputedTorque"]


@register
class TruthComputedTorque(Controller):
    """``truth-ct``: cascaded computed torque on the true state (see the module docstring).

    Gains: ``link_bandwidth`` w_l [rad/s] (Kp = w_l^2, Kd = 2 w_l), ``motor_bandwidth``
    w_m [rad/s] (Kpm = w_m^2, Kdm = 2 w_m); the motor loop must be several times faster.
    """

    name = "truth-ct"
    gain_defaults: ClassVar[dict[str, Any]] = {"link_bandwidth": 5.0, "motor_bandwidth": 40.0}

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(lib, trajectory, gains)
        act = lib.manifest.actuators
        self.Mm = np.array(act.Mm, dtype=float)
        self.Fm = np.array(act.Fm, dtype=float)
        wl = float(self.gains["link_bandwidth"])
        wm = float(self.gains["motor_bandwidth"])
        self.Kp, self.Kd = wl * wl, 2.0 * wl
        self.Kpm, self.Kdm = wm * wm, 2.0 * wm
        self._M = lib.function("mass_matrix")
        self._b = lib.function("bias")
        self.n = lib.n
        self.T = lib.T
        self._prev: tuple[int, FloatArray, FloatArray] | None = None  # (k, qm_d, qmd_d)

    def c_parameters(self) -> dict[str, Any] | None:
        return {
            "gains": {},
            "p": 1.0,
            "link_bandwidth": float(self.gains["link_bandwidth"]),
            "motor_bandwidth": float(self.gains["motor_bandwidth"]),
        }

    def torque(self, tick: LawInputs) -> FloatArray:
        k, t, x_true, theta_true = tick.k, tick.t, tick.x_true, tick.theta_true
        n = self.n
        q, qd, qm, qmd = x_true[:n], x_true[n : 2 * n], x_true[2 * n : 3 * n], x_true[3 * n :]
        q_d, qd_d, qdd_d = self.reference(k, t)
        Ks = self.lib.stiffness(theta_true)
        M = self._M.call_into(q, theta_true)[0]
        b = self._b.call_into(q, qd, theta_true)[0]
        acc = qdd_d + self.Kd * (qd_d - qd) + self.Kp * (q_d - q)
        tau = M @ acc + b
        qm_d = q + tau / Ks
        if self._prev is not None and self._prev[0] == k - 1:
            qmd_d = (qm_d - self._prev[1]) / self.T
            qmdd_d = (qmd_d - self._prev[2]) / self.T
        else:  # first step (or a gap): no history to difference
            qmd_d, qmdd_d = qd.copy(), np.zeros(n)
        self._prev = (k, qm_d, qmd_d)
        u: FloatArray = (
            Ks * (qm - q)
            + self.Fm * qmd
            + self.Mm * (qmdd_d + self.Kpm * (qm_d - qm) + self.Kdm * (qmd_d - qmd))
        )
        return u
