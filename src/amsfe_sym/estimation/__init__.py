"""State estimation for the elastic-joint arm: EKF with fast encoders and late camera frames.

Pure numpy/scipy. The model enters through two small Protocols, :class:`TransitionModel`
and :class:`MeasurementModel`, so compiled C functions and the linear models of the tests
plug in alike. Five estimators share one interface (:class:`Estimator`):

- ``encoders``: encoder updates only;
- ``naive``: a late frame is used as if taken now;
- ``oosm``: the paper's out-of-sequence update (Bar-Shalom's A1 over the whole lag);
- ``replay``: rewind to the exposure step and re-filter (exact for linear-Gaussian);
- ``cloning``: stochastic cloning of the state at each exposure (exact for linear-Gaussian).

See ``docs/explanation/estimation-algorithms.md`` for the maths.

May import: errors, core.camera_frame; numpy and scipy only (the robot is seen through
the TransitionModel / MeasurementModel protocols).
"""

from amsfe_sym.estimation.base import DEFAULT_CONFIG, Estimator, FilterConfig, StepReport
from amsfe_sym.estimation.cloning import CloningEstimator
from amsfe_sym.estimation.ekf import (
    PredictResult,
    UpdateResult,
    gate_threshold,
    joseph_update,
    predict,
)
from amsfe_sym.estimation.encoders import EncodersEstimator
from amsfe_sym.estimation.models import (
    CameraFrame,
    LinearMeasurement,
    LinearModel,
    MeasurementModel,
    TransitionModel,
)
from amsfe_sym.estimation.naive import NaiveEstimator
from amsfe_sym.estimation.oosm import (
    A1Correction,
    A1Retrodiction,
    OosmAl1Estimator,
    OosmEstimator,
    a1_correct,
    a1_retrodict,
    al1_retrodict,
)
from amsfe_sym.estimation.registry import ESTIMATORS, make_estimator
from amsfe_sym.estimation.replay import ReplayEstimator

__all__ = [
    "DEFAULT_CONFIG",
    "ESTIMATORS",
    "A1Correction",
    "A1Retrodiction",
    "CameraFrame",
    "CloningEstimator",
    "EncodersEstimator",
    "Estimator",
    "FilterConfig",
    "LinearMeasurement",
    "LinearModel",
    "MeasurementModel",
    "NaiveEstimator",
    "OosmAl1Estimator",
    "OosmEstimator",
    "PredictResult",
    "ReplayEstimator",
    "StepReport",
    "TransitionModel",
    "UpdateResult",
    "a1_correct",
    "a1_retrodict",
    "al1_retrodict",
    "gate_threshold",
    "joseph_update",
    "make_estimator",
    "predict",
]
