"""``replay``: rewind to the exposure step, insert the frame, re-filter up to now.

A ring buffer holds, for the last ``buffer_steps + 1`` steps ``j``: the posterior
``x(j|j), P(j|j)``, the input applied over ``[j, j+1]``, the encoder sample taken at ``j``,
and every usable frame exposed at ``j`` that has been delivered. When frames exposed before
the current step arrive, the filter restarts from the stored posterior at the earliest of
their exposure steps ``kappa``, applies them there (after that step's encoder update, which
the stored posterior already holds), and re-runs predict, encoder update and the frames of
each later step (old and new) up to now, overwriting the stored posteriors.

Linear-Gaussian: exactly the in-order Kalman filter that would have applied each frame at its
exposure step (the tests check this to 1e-9). Nonlinear: the EKF in order, re-linearised
along the corrected trajectory (the best this family of filters can do). Cost: one filter
step per replayed step, i.e. up to ``d`` extra steps per frame. Gating is re-evaluated on
replay, as the in-order filter would, so a frame gated out once may be accepted later.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import EstimatorError
from amsfe_sym.estimation.base import Estimator, StepInputs, StepReport

__all__ = ["ReplayEstimator"]


class ReplayEstimator(Estimator):
    """Exact (linear-Gaussian) late-frame handling by rewind and re-filtering."""

    name: ClassVar[str] = "replay"
    needs_history: ClassVar[bool] = True

    def _setup(self) -> None:
        size = self.config.buffer_steps + 1
        self._size = size
        self._xs = np.empty((size, self.nx))
        self._Ps = np.empty((size, self.nx, self.nx))
        self._us: list[FloatArray | None] = [None] * size
        self._zs: list[FloatArray | None] = [None] * size
        self._frames: list[list[FloatArray]] = [[] for _ in range(size)]
        self._store(self.k)

    def _store(self, j: int) -> None:
        s = j % self._size
        self._xs[s] = self.x
        self._Ps[s] = self.P

    def _apply_frames(self, kappa: int, zs: list[FloatArray], report: StepReport | None) -> None:
        for z in zs:
            result = self._frame_update_now(z)
            if report is not None:
                report.frame_result(kappa, result.accepted, result.nis, self._gate_camera)

    def _step(self, step: StepInputs, report: StepReport) -> None:
        u, z_encoder, frames = step.u, step.z_encoder, step.frames
        k, k_new, size = self.k, self.k + 1, self._size
        self._us[k % size] = u
        self._zs[k_new % size] = z_encoder
        self._frames[k_new % size] = []  # the slot held step k_new - size, now forgotten
        new: dict[int, list[FloatArray]] = {}
        for frame in frames:  # sorted by exposure step
            new.setdefault(frame.exposure_step, []).append(frame.z)
        start = min(new, default=k_new)
        if start <= k:  # rewind to the earliest exposure among the late frames
            s = start % size
            self.x = self._xs[s].copy()
            self.P = self._Ps[s].copy()
            self._apply_frames(start, new[start], report)
            self._frames[s].extend(new.pop(start))
            self._store(start)
            report.replayed_steps = k - start
        else:
            start = k
        for j in range(start, k_new):  # re-filter j -> j+1 up to now
            s_next = (j + 1) % size
            u_j = self._us[j % size]
            if u_j is None:  # cannot happen inside the buffer window
                raise EstimatorError(f"replay: no stored input for step {j}")
            self._predict(u_j)
            self._encoder_update(self._zs[s_next], report if j + 1 == k_new else None)
            self._apply_frames(j + 1, self._frames[s_next], None)
            fresh = new.pop(j + 1, None)
            if fresh is not None:
                self._apply_frames(j + 1, fresh, report)
                self._frames[s_next].extend(fresh)
            self._store(j + 1)
