"""``naive``: a late frame is used as if the image had been taken now.

``h_c`` and its jacobian are evaluated at the current posterior ``x(k|k)`` and a standard
Joseph-form update is applied, ignoring that the image shows the arm as it was at
``kappa < k``. Wrong by construction (the error grows with the delay and the speed); it is
the strawman that shows what the out-of-sequence machinery buys.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.estimation.base import Estimator, StepReport
from amsfe_sym.estimation.models import CameraFrame

__all__ = ["NaiveEstimator"]


class NaiveEstimator(Estimator):
    """EKF that applies every delivered frame at the current step, whatever its age."""

    name: ClassVar[str] = "naive"

    def _step(
        self,
        u: NDArray[np.float64],
        z_encoder: NDArray[np.float64] | None,
        frames: list[CameraFrame],
        report: StepReport,
    ) -> None:
        self._predict(u)
        self._encoder_update(z_encoder, report)
        for frame in frames:
            result = self._frame_update_now(frame.z)
            report.frame_result(frame.exposure_step, result.accepted, result.nis, self._gate_camera)
