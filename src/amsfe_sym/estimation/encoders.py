"""``encoders``: the EKF with encoder updates only (paper Sec. 3.1, eqs. (13)-(17)).

Camera frames are counted as ignored. This is the baseline every camera-aided estimator
should beat, and the estimator the paper runs between two vision samples.
"""

from __future__ import annotations

from typing import ClassVar

from amsfe_sym.estimation.base import Estimator, StepInputs, StepReport
from amsfe_sym.estimation.models import CameraFrame

__all__ = ["EncodersEstimator"]


class EncodersEstimator(Estimator):
    """EKF on the encoder measurements alone; frames are ignored (counted in the report)."""

    name: ClassVar[str] = "encoders"
    uses_frames: ClassVar[bool] = False

    def _step(self, step: StepInputs, report: StepReport) -> None:
        u, z_encoder, frames = step.u, step.z_encoder, step.frames
        self._predict(u)
        self._encoder_update(z_encoder, report)
        self._frames_now(frames, report)

    def _frames_now(self, frames: list[CameraFrame], report: StepReport) -> None:
        """Use the frames delivered at this step, after the encoder update: none here
        (:class:`~amsfe_sym.estimation.naive.NaiveEstimator` applies them)."""
