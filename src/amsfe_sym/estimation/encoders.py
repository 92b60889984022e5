"""``encoders``: the EKF with encoder updates only (paper Sec. 3.1, eqs. (13)-(17)).

Camera frames are counted as ignored. This is the baseline every camera-aided estimator
should beat, and the estimator the paper runs between two vision samples.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.estimation.base import Estimator, StepReport
from amsfe_sym.estimation.models import CameraFrame

__all__ = ["EncodersEstimator"]


class EncodersEstimator(Estimator):
    """EKF on the encoder measurements alone; frames are ignored (counted in the report)."""

    name: ClassVar[str] = "encoders"
    uses_frames: ClassVar[bool] = False

    def _step(
        self,
        u: NDArray[np.float64],
        z_encoder: NDArray[np.float64] | None,
        frames: list[CameraFrame],
        report: StepReport,
    ) -> None:
        self._predict(u)
        self._encoder_update(z_encoder, report)
        self._frames_now(frames, report)

    def _frames_now(self, frames: list[CameraFrame], report: StepReport) -> None:
        """Use the frames delivered at this step, after the encoder update: none here
        (:class:`~amsfe_sym.estimation.naive.NaiveEstimator` applies them)."""
