"""``cloning``: stochastic cloning of the state at each camera exposure.

At each scheduled exposure step ``kappa`` (``kappa % l == phase``), after the encoder update,
the state is augmented with a copy of itself:

    xa = [x; c],   Pa = [[P, P], [P, P]],

so the clone ``c = x(kappa|kappa)`` is perfectly correlated with the state. Predictions move
only the state: with ``A = dF/dx``,

    P_xx <- A P_xx A^T + Qd,   P_xc <- A P_xc,   P_cc <- P_cc

(the clone is static and gets no process noise). Every later encoder update acts on the whole
augmented state through ``Ha = [H, 0]``, so it also refines the clones (smoothing). When the
frame of ``kappa`` arrives, ``Ha = [0, .., Hc(c), .., 0]`` updates the state through the
cross-covariance, and the clone is dropped. A clone whose frame has not come
``camera_max_delay`` steps after its exposure is dropped (a lost frame). Several clones may
be in flight (delay > period). Updates use the Joseph form on the augmented state.

Linear-Gaussian: exactly the in-order Kalman filter (the tests check this to 1e-9). Cost: the
augmented covariance has ``(1 + m) nx`` rows, ``m`` the clones in flight (about ``d / l + 1``).
A frame exposed at a step that was not scheduled has no clone: it is rejected with a warning.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation.base import Estimator, StepInputs, StepReport
from amsfe_sym.estimation.ekf import joseph_update, measure, predict, require_positive_definite

__all__ = ["CloningEstimator"]


class CloningEstimator(Estimator):
    """Exact (linear-Gaussian) late-frame handling by stochastic cloning.

    Raises:
        ConfigError: If ``config.camera_period`` is ``None`` (the exposures to clone at must
            be known).
    """

    name: ClassVar[str] = "cloning"
    needs_history: ClassVar[bool] = True

    def _setup(self) -> None:
        if self.config.camera_period is None:
            raise ConfigError(
                describe(
                    "FilterConfig.camera_period for 'cloning'",
                    "the camera period l in steps",
                    "None",
                    "set camera_period (and camera_phase, camera_max_delay) so the estimator "
                    "knows at which steps to clone the state",
                )
            )
        max_delay = self.config.camera_max_delay
        self._max_delay = (
            self.config.buffer_steps
            if max_delay is None
            else min(max_delay, self.config.buffer_steps)
        )
        self._xa: FloatArray = self.x.copy()
        self._Pa: FloatArray = self.P.copy()
        self._clones: list[int] = []  # exposure step of each clone, in block order
        if self._scheduled(self.k):
            self._add_clone(self.k)
        self._sync()

    @property
    def clones_in_flight(self) -> tuple[int, ...]:
        """Exposure steps of the clones currently carried."""
        return tuple(self._clones)

    def augmented_estimate(self) -> tuple[FloatArray, FloatArray]:
        """Return copies of the augmented ``(xa, Pa)`` (state first, then clones)."""
        return self._xa.copy(), self._Pa.copy()

    # ------------------------------------------------------------------ internals
    def _sync(self) -> None:
        n = self.nx
        self.x = self._xa[:n]
        self.P = self._Pa[:n, :n]

    def _add_clone(self, kappa: int) -> None:
        n, na = self.nx, self._xa.shape[0]
        Pa = np.empty((na + n, na + n))
        Pa[:na, :na] = self._Pa
        Pa[na:, :na] = self._Pa[:n, :]
        Pa[:na, na:] = self._Pa[:, :n]
        Pa[na:, na:] = self._Pa[:n, :n]
        self._xa = np.concatenate([self._xa, self._xa[:n]])
        self._Pa = Pa
        self._clones.append(kappa)

    def _drop_clone(self, index: int) -> None:
        n = self.nx
        start = n * (1 + index)
        keep = np.r_[0:start, start + n : self._xa.shape[0]]
        self._xa = self._xa[keep]
        self._Pa = self._Pa[np.ix_(keep, keep)]
        del self._clones[index]

    def _predict_augmented(self, u: FloatArray) -> None:
        n = self.nx
        pred = predict(self.model, self._xa[:n], self._Pa[:n, :n], u)
        self._xa[:n] = pred.x
        if self._clones:
            cross = pred.A @ self._Pa[:n, n:]  # P_xc <- A P_xc
            self._Pa[:n, n:] = cross
            self._Pa[n:, :n] = cross.T
        self._Pa[:n, :n] = pred.P

    def _update_augmented(
        self,
        z: FloatArray,
        offset: int,
        H_block: FloatArray,
        z_hat: FloatArray,
        R: FloatArray,
        gate: float,
    ) -> tuple[bool, float]:
        Ha = np.zeros((H_block.shape[0], self._xa.shape[0]))
        Ha[:, offset : offset + self.nx] = H_block
        result = joseph_update(self._xa, self._Pa, z - z_hat, Ha, R, gate)
        if result.accepted:
            self._xa, self._Pa = result.x, result.P
        return result.accepted, result.nis

    def _step(self, step: StepInputs, report: StepReport) -> None:
        u, z_encoder, frames = step.u, step.z_encoder, step.frames
        k_new = self.k + 1
        n = self.nx
        self._predict_augmented(u)
        if z_encoder is not None:
            z_hat, H = measure(self.encoder, self._xa[:n])
            accepted, nis = self._update_augmented(
                z_encoder, 0, H, z_hat, self.R_encoder, self._gate_encoder
            )
            report.encoder_nis = nis
            report.encoder_accepted = accepted
            if not accepted:
                report.rejections.append(
                    f"encoder gated out: NIS {nis:.4g} > {self._gate_encoder:.4g}"
                )
        if self._scheduled(k_new):
            self._add_clone(k_new)
        for frame in frames:
            kappa = frame.exposure_step
            if kappa not in self._clones:
                why = (
                    "was not a scheduled exposure"
                    if not self._scheduled(kappa)
                    else "has no clone left (already used, or older than camera_max_delay)"
                )
                report.reject(f"camera frame kappa={kappa} {why}; rejected")
                continue
            index = self._clones.index(kappa)
            offset = n * (1 + index)
            z_hat, Hc = measure(self.camera, self._xa[offset : offset + n])
            accepted, nis = self._update_augmented(
                frame.z, offset, Hc, z_hat, self.R_camera, self._gate_camera
            )
            report.frame_result(kappa, accepted, nis, self._gate_camera)
            self._drop_clone(index)
        for index in range(len(self._clones) - 1, -1, -1):
            if k_new - self._clones[index] >= self._max_delay:
                self._drop_clone(index)
        report.clones = len(self._clones)
        self._sync()

    def _check_covariance(self) -> None:
        super()._check_covariance()
        n = self.nx
        for index, kappa in enumerate(self._clones):
            start = n * (1 + index)
            block = self._Pa[start : start + n, start : start + n]
            require_positive_definite(block, f"cloning: covariance of the clone of step {kappa}")
