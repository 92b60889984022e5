"""``naive``: a late frame is used as if the image had been taken now.

``h_c`` and its jacobian are evaluated at the current posterior ``x(k|k)`` and a standard
Joseph-form update is applied, ignoring that the image shows the arm as it was at
``kappa < k``. Wrong by construction (the error grows with the delay and the speed); it is
the strawman that shows what the out-of-sequence machinery buys.
"""

from __future__ import annotations

from typing import ClassVar

from amsfe_sym.estimation.base import StepReport
from amsfe_sym.estimation.encoders import EncodersEstimator
from amsfe_sym.estimation.models import CameraFrame

__all__ = ["NaiveEstimator"]


class NaiveEstimator(EncodersEstimator):
    """EKF that applies every delivered frame at the current step, whatever its age (the
    encoder EKF's step, then every frame as if taken now)."""

    name: ClassVar[str] = "naive"
    uses_frames: ClassVar[bool] = True

    def _frames_now(self, frames: list[CameraFrame], report: StepReport) -> None:
        for frame in frames:
            result = self._frame_update_now(frame.z)
            report.frame_result(frame.exposure_step, result.accepted, result.nis, self._gate_camera)
