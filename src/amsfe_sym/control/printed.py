"""The paper's laws as printed: (37) ``amsfe-paper`` and the baseline (54) ``dtsmc-paper``,
on the generated laws; docs/explanation/control.md says why they fail on the paper's arm (law (37)
as
printed hides u: PAPER-NOTES section 4), which is why the cascades of
:mod:`amsfe_sym.control.sliding` exist."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.control.base import LawInputs, register
from amsfe_sym.control.sliding import PAPER_GAINS, _SlidingBase
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.signals.trajectory import Trajectory

__all__ = ["AmsfePaper", "DtsmcPaper"]


class _Printed(_SlidingBase):
    """Laws (37) / (54) as printed: ``Mhat/T [Fhat + ...]`` on one state vector.

    Gain ``qmd_next`` says how Fhat's motor velocity at k+1 is estimated: ``"predict"`` from
    (1c) with the previous torque u(k-1), or ``"hold"`` (qmd(k+1) = qmd(k)).  With the true
    qmd(k+1) the law's u cancels (PAPER-NOTES section 4), so some such reading is forced.
    """

    gain_defaults: ClassVar[dict[str, Any]] = {**PAPER_GAINS, "qmd_next": "predict"}

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(lib, trajectory, gains)
        self._choice("qmd_next", ("predict", "hold"), "see docs/explanation/control.md")
        self._u_prev = np.zeros(self.n)
        self._vt_prev: FloatArray | None = None

    def _law_inputs(
        self, x_hat: FloatArray, z_enc: FloatArray
    ) -> tuple[list[FloatArray], FloatArray]:
        """The law's leading inputs and the state vector [q, qd, qm, qmd, theta] they mean."""
        return [x_hat], x_hat

    def _pick(self, x_true: FloatArray, theta_true: FloatArray, x_hat: FloatArray) -> FloatArray:
        return x_hat

    def torque(self, tick: LawInputs) -> FloatArray:
        k, t, x_true, theta_true, x_hat, z_enc = tick[:6]
        n = self.n
        lead, x = self._law_inputs(self._pick(x_true, theta_true, x_hat), z_enc)
        q, qm, qmd = x[:n], x[2 * n : 3 * n], x[3 * n : 4 * n]
        q_d, qd_d, _ = self.reference(k, t)
        if self.gains["qmd_next"] == "predict":  # (1c) with u(k-1)
            Ks = self.lib.stiffness(x[4 * n :])
            qmd_next = qmd + self.T * (self._u_prev - self._fm * qmd - Ks * (qm - q)) / self._mm
        else:
            qmd_next = qmd
        if self._vt_prev is None:  # first tick: no v_t(k-1) yet
            self._vt_prev = qd_d - self._g["Lt"] * (q - q_d)
        u, s, vt, _e_next, bound = self._law.call_into(
            *lead, qmd_next, q_d, qd_d, self._vt_prev, *self._gain_args()
        )
        self._vt_prev = vt.copy()
        self.s, self.bound = s.copy(), bound.copy()
        return u.copy()

    def saturate(self, u: FloatArray) -> tuple[FloatArray, bool]:
        applied, clipped = super().saturate(u)
        self._u_prev = applied.copy()
        return applied, clipped


@register
class AmsfePaper(_Printed):
    """``amsfe-paper``: law (37) as printed, on the fusion estimate."""

    name = "amsfe-paper"
    law = "control_amsfe_paper"
    gain_defaults: ClassVar[dict[str, Any]] = {**_Printed.gain_defaults, "state": "estimate"}

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(lib, trajectory, gains)
        self._choice(
            "state",
            ("estimate", "true"),
            "'estimate' (the fusion estimate) or 'true' (an oracle): docs/explanation/control.md",
        )

    def _pick(self, x_true: FloatArray, theta_true: FloatArray, x_hat: FloatArray) -> FloatArray:
        if self.gains["state"] == "true":  # isolates the law from the estimator
            return np.concatenate([x_true[: 4 * self.n], theta_true])
        return x_hat


@register
class DtsmcPaper(_Printed):
    """``dtsmc-paper``: the baseline (54) as printed, on the raw motor encoders
    (q = qm, qd = qmd: the paper's "DTSMC without estimator"), theta at its initial value."""

    name = "dtsmc-paper"
    law = "control_dtsmc_paper"
    has_lt = False

    def _law_inputs(
        self, x_hat: FloatArray, z_enc: FloatArray
    ) -> tuple[list[FloatArray], FloatArray]:
        n, th = self.n, self.lib.theta_initial
        return [z_enc, th], np.concatenate([z_enc[:n], z_enc[n:], z_enc, th])
