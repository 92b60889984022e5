"""Estimator base class: configuration, per-step report, input checks, common EKF steps.

An estimator holds the posterior ``x(k|k), P(k|k)`` of step ``k``. :meth:`Estimator.step`
advances it to ``k + 1``: predict with the input applied over ``[k, k+1]`` (paper eqs.
(13)-(14)), update with the encoder sample taken at ``k + 1`` (eqs. (15)-(16), Joseph form),
then use every camera frame delivered at ``k + 1``; how a late frame is used is what tells
the estimators apart (see ``docs/explanation/estimation-algorithms.md``).

Everything a step is given is checked before anything is changed: wrong shapes raise
:class:`~amsfe_sym.errors.ShapeError`, a frame from the future raises
:class:`~amsfe_sym.errors.MeasurementError`; a measurement holding NaN or inf, or a frame
older than the history kept, is rejected with a logged warning and counted in the
:class:`StepReport`, and the estimate is left as if it had not been given.
"""

from __future__ import annotations

import logging
import math
import operator
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import (
    ConfigError,
    EstimatorError,
    MeasurementError,
    ShapeError,
    describe,
)
from amsfe_sym.estimation.config import BACKWARD_MAPS, DEFAULT_CONFIG, FilterConfig
from amsfe_sym.estimation.ekf import (
    PredictResult,
    UpdateResult,
    gate_threshold,
    joseph_update,
    measure,
    predict,
    require_positive_definite,
    validate_spd,
)
from amsfe_sym.estimation.models import CameraFrame, MeasurementModel, TransitionModel

__all__ = [
    "BACKWARD_MAPS",
    "DEFAULT_CONFIG",
    "Estimator",
    "FilterConfig",
    "StepInputs",
    "StepReport",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class StepInputs:
    """The checked inputs of one :meth:`Estimator.step` (what ``_step`` receives).

    Attributes:
        u: Input over ``[k, k+1]`` [N m], shape (n,).
        z_encoder: Finite encoder measurement at ``k+1`` (eq. 5), or ``None``.
        frames: Camera frames delivered at ``k+1`` that passed the screening, in delivery
            order.
    """

    u: FloatArray
    z_encoder: FloatArray | None
    frames: list[CameraFrame]


@dataclass
class StepReport:
    """What one :meth:`Estimator.step` did.

    Attributes:
        k: Step index of the new posterior.
        encoder_accepted: An encoder update was applied.
        encoder_nis: NIS of the encoder innovation (``None`` when there was no usable sample).
        frames_applied: Camera frames delivered this step and applied.
        frames_rejected: Frames delivered this step and refused (NaN/inf, older than the
            buffer, no clone, gated out, numerically unusable); see ``rejections``.
        frames_ignored: Frames delivered this step that this estimator never uses (``encoders``).
        frame_nis: NIS of each delivered frame that reached the update (applied or gated).
        rejections: One human-readable reason per rejected measurement.
        replayed_steps: ``replay`` only: steps re-filtered because of late frames.
        clones: ``cloning`` only: clones in flight after the step.
    """

    k: int
    encoder_accepted: bool = False
    encoder_nis: float | None = None
    frames_applied: int = 0
    frames_rejected: int = 0
    frames_ignored: int = 0
    frame_nis: list[float] = field(default_factory=list)
    rejections: list[str] = field(default_factory=list)
    replayed_steps: int = 0
    clones: int = 0
    used: list[int] = field(default_factory=list)

    def reject(self, reason: str, *, warn: bool = True) -> None:
        """Count one rejected frame and record why (a logged warning unless ``warn``)."""
        self.frames_rejected += 1
        self.rejections.append(reason)
        if warn:
            logger.warning("step %d: %s", self.k, reason)
        else:
            logger.info("step %d: %s", self.k, reason)

    def frame_result(self, kappa: int, accepted: bool, nis: float, gate: float) -> None:
        """Record the outcome of a frame update (applied, or rejected by the gate)."""
        self.frame_nis.append(nis)
        self.used.append(kappa)  # fused or gated: a repeat of it is a duplicate
        if accepted:
            self.frames_applied += 1
        else:
            self.reject(
                f"camera frame kappa={kappa} gated out: NIS {nis:.4g} > {gate:.4g}", warn=False
            )


class Estimator(ABC):
    """Base of the estimators: common bookkeeping, input checks, EKF predict and encoder update.

    Args:
        model: Transition model (``x(k+1) = F(x(k), u(k))``), see :class:`TransitionModel`.
        encoder: Encoder measurement model, sampled every step (paper eq. (9), ``i = m``).
        camera: Camera measurement model (eq. (9), ``i = c``).
        x0: Initial posterior mean ``x(k0|k0)``, shape ``(nx,)``.
        P0: Initial posterior covariance ``(nx, nx)``, symmetric positive definite.
        config: Gate, buffer and camera schedule, see :class:`FilterConfig`.
        k0: Step index of ``x0``.

    Raises:
        ShapeError: If ``x0``, ``P0`` or an ``R`` has the wrong shape.
        ConfigError: If ``x0`` is not finite, or ``P0`` or an ``R`` is not symmetric positive
            definite (the message names the matrix and its smallest eigenvalue).

    Attributes:
        k: Step index of the current posterior.
        x: Current posterior mean ``x(k|k)``.
        P: Current posterior covariance ``P(k|k)``.
    """

    name: ClassVar[str]
    uses_frames: ClassVar[bool] = True
    #: Whether late frames are served from a history of ``buffer_steps`` steps (then the
    #: buffer must cover the camera's largest delay).
    needs_history: ClassVar[bool] = False

    def __init__(
        self,
        model: TransitionModel,
        encoder: MeasurementModel,
        camera: MeasurementModel,
        x0: ArrayLike,
        P0: ArrayLike,
        config: FilterConfig = DEFAULT_CONFIG,
        k0: int = 0,
    ) -> None:
        if not isinstance(config, FilterConfig):
            raise ConfigError(
                describe(
                    "config", "a FilterConfig", type(config).__name__, "pass FilterConfig(...)"
                )
            )
        self.model = model
        self.encoder = encoder
        self.camera = camera
        self.config = config
        self.nx: int = int(model.nx)
        x = np.array(x0, dtype=np.float64)
        if x.shape != (self.nx,):
            raise ShapeError(
                describe("x0", f"shape ({self.nx},)", f"shape {x.shape}", "match the model's nx")
            )
        if not np.isfinite(x).all():
            raise ConfigError(
                describe("x0", "finite values", "NaN or inf", "fix the initial state")
            )
        self.x: FloatArray = x
        self._seen: set[int] = set()  # exposure steps of the frames used
        self.P: FloatArray = validate_spd("P0", P0, self.nx)
        self.R_encoder = validate_spd("encoder R", encoder.R, int(encoder.dim))
        self.R_camera = validate_spd("camera R", camera.R, int(camera.dim))
        self.k: int = operator.index(k0)
        self.k0: int = self.k
        self._gate_encoder = gate_threshold(config.encoder_gate_probability, int(encoder.dim))
        self._gate_camera = gate_threshold(config.gate_probability, int(camera.dim))
        self._ungated_outlier: tuple[int, float] | None = None  # (kappa, NIS), gate off
        self._outlier_nis = gate_threshold(DEFAULT_CONFIG.gate_probability, int(camera.dim))
        nu = getattr(model, "nu", None)
        self._nu: int | None = nu if isinstance(nu, int) else None
        self._setup()

    def _setup(self) -> None:  # noqa: B027 - an optional hook, not an abstract method
        """Subclass hook run at the end of ``__init__`` (checked inputs in ``self``): check
        estimator-specific configuration and allocate history buffers."""

    # ------------------------------------------------------------------ public API
    def step(
        self,
        u: ArrayLike,
        z_encoder: ArrayLike | None,
        frames: Sequence[CameraFrame] = (),
    ) -> StepReport:
        """Advance ``k -> k+1``.

        Predict with ``u`` (the input applied over ``[k, k+1]``), update with the encoder
        measurement taken at ``k+1`` (``None``: no encoder sample), then apply every camera
        frame delivered at ``k+1`` (their ``exposure_step <= k+1``).

        Args:
            u: Input over ``[k, k+1]``, 1-D.
            z_encoder: Encoder measurement at ``k+1``, shape ``(encoder.dim,)``, or ``None``.
            frames: Camera frames delivered at ``k+1``, in any order.

        Returns:
            The :class:`StepReport` of the step.

        Raises:
            ShapeError: If ``u``, ``z_encoder`` or a frame has the wrong shape.
            MeasurementError: If a frame's exposure step is after ``k+1``.
            EstimatorError: If ``u`` is not finite, or the covariance loses positive
                definiteness.
        """
        k_new = self.k + 1
        u_arr = self._check_input(u)
        z_enc = self._check_encoder(z_encoder)
        checked = self._check_frame_shapes(frames, k_new)
        report = StepReport(k=k_new)
        if z_enc is not None and not np.isfinite(z_enc).all():
            logger.warning("step %d: encoder measurement holds NaN or inf; not used", k_new)
            report.rejections.append("encoder measurement holds NaN or inf")
            z_enc = None
        usable = self._screen_frames(checked, k_new, report)
        try:
            self._step(StepInputs(u_arr, z_enc, usable), report)
            self._seen.update(report.used)
            self._note_ungated_outliers(report)
            self.k = k_new
            self._check_covariance()
        except EstimatorError as exc:
            raise self._with_cause(exc, k_new) from exc
        return report

    def _note_ungated_outliers(self, report: StepReport) -> None:
        """Gate off: note the frame fused with the largest NIS beyond the default gate's, the
        cause to name if the filter breaks down (docs/explanation/estimation-algorithms.md)."""
        for kappa, nis in zip(report.used, report.frame_nis, strict=False):
            worst = self._ungated_outlier[1] if self._ungated_outlier else self._outlier_nis
            if self._gate_camera == math.inf and nis > worst:
                self._ungated_outlier = (kappa, float(nis))

    def _with_cause(self, exc: EstimatorError, k: int) -> EstimatorError:
        """``exc``, or one line naming the outlier fused with the gate off and the fix."""
        if (outlier := self._ungated_outlier) is None:
            return exc
        kappa, nis = outlier
        found = str(exc).split(". Fix:")[0]
        return EstimatorError(
            describe(
                f"{self.name} at step {k}",
                "a usable estimate",
                f"it broke down ({found}) after camera frame kappa={kappa} was fused with "
                f"NIS {nis:.3g} ({math.sqrt(nis):.3g} standard deviations) because the camera "
                "gate is off (gate_probability = 0 fuses every outlier)",
                "turn the gate on (filter.gate_probability = 0.9999, the default) or remove "
                "the outlier from the data",
            )
        )

    def estimate(self) -> tuple[FloatArray, FloatArray]:
        """Return copies of the current posterior ``(x(k|k), P(k|k))``."""
        return self.x.copy(), self.P.copy()

    # ------------------------------------------------------------------ subclass hook
    @abstractmethod
    def _step(self, step: StepInputs, report: StepReport) -> None:
        """Do the step; ``self.k`` is still the old index. Inputs are already checked."""

    # ------------------------------------------------------------------ checks
    def _check_input(self, u: ArrayLike) -> FloatArray:
        u_arr = np.asarray(u, dtype=np.float64)
        if u_arr.ndim != 1 or (self._nu is not None and u_arr.shape[0] != self._nu):
            expected = f"shape ({self._nu},)" if self._nu is not None else "a 1-D array"
            raise ShapeError(
                describe("u", expected, f"shape {u_arr.shape}", "pass the input as a 1-D vector")
            )
        if not np.isfinite(u_arr).all():
            raise EstimatorError(
                describe(
                    "u", "finite input", "NaN or inf", "the prediction needs the input applied"
                )
            )
        return u_arr

    def _check_encoder(self, z: ArrayLike | None) -> FloatArray | None:
        if z is None:
            return None
        z_arr = np.asarray(z, dtype=np.float64)
        if z_arr.shape != (self.encoder.dim,):
            raise ShapeError(
                describe(
                    "z_encoder",
                    f"shape ({self.encoder.dim},)",
                    f"shape {z_arr.shape}",
                    "pass None when there is no encoder sample",
                )
            )
        return z_arr

    def _check_frame_shapes(self, frames: Sequence[CameraFrame], k_new: int) -> list[CameraFrame]:
        checked: list[CameraFrame] = []
        dim = self.camera.dim
        for frame in frames:
            try:
                kappa = operator.index(frame.exposure_step)
            except (AttributeError, TypeError):
                raise MeasurementError(
                    describe(
                        "camera frame",
                        "a CameraFrame with an integer exposure_step",
                        repr(frame),
                        "build frames with CameraFrame(exposure_step=int, z=array)",
                    )
                ) from None
            z = np.asarray(frame.z, dtype=np.float64)
            if z.shape != (dim,):
                raise ShapeError(
                    describe(
                        f"camera frame z (kappa={kappa})",
                        f"shape ({dim},)",
                        f"shape {z.shape}",
                        "match the camera model's dim",
                    )
                )
            if kappa > k_new:
                raise MeasurementError(
                    describe(
                        "camera frame exposure_step",
                        f"<= {k_new} (the step being entered)",
                        f"{kappa}, a frame from the future",
                        "stamp frames with the step at which the image was taken",
                    )
                )
            checked.append(CameraFrame(exposure_step=kappa, z=z))
        return checked

    def _screen_frames(
        self, frames: list[CameraFrame], k_new: int, report: StepReport
    ) -> list[CameraFrame]:
        """Drop (with a warning, counted) frames with NaN/inf or older than the history."""
        if not self.uses_frames:
            report.frames_ignored = len(frames)
            return []
        usable: list[CameraFrame] = []
        oldest = max(k_new - self.config.buffer_steps, self.k0)
        self._seen = {s for s in self._seen if s >= oldest}
        for frame in frames:
            kappa = frame.exposure_step
            if not np.isfinite(frame.z).all():
                report.reject(f"camera frame kappa={kappa} holds NaN or inf")
            elif kappa in self._seen or any(f.exposure_step == kappa for f in usable):
                report.reject(
                    f"camera frame kappa={kappa} is a duplicate: a frame of this exposure was "
                    "used already (measurements are idempotent)"
                )
            elif kappa < oldest:
                report.reject(
                    f"camera frame kappa={kappa} is older than the history kept "
                    f"(oldest usable exposure {oldest}; buffer_steps={self.config.buffer_steps})"
                )
            else:
                usable.append(frame)
        usable.sort(key=lambda f: f.exposure_step)
        return usable

    def _check_covariance(self) -> None:
        require_positive_definite(self.P, f"{self.name}: P({self.k}|{self.k})")

    # ------------------------------------------------------------------ common EKF steps
    def _predict(self, u: FloatArray) -> PredictResult:
        result = predict(self.model, self.x, self.P, u)
        self.x, self.P = result.x, result.P
        return result

    def _encoder_update(
        self, z: FloatArray | None, report: StepReport | None
    ) -> UpdateResult | None:
        """Encoder update of ``self.x, self.P``; returns the result (``None``: no sample)."""
        if z is None:
            return None
        z_hat, H = measure(self.encoder, self.x)
        result = joseph_update(self.x, self.P, z - z_hat, H, self.R_encoder, self._gate_encoder)
        if result.accepted:
            self.x, self.P = result.x, result.P
        if report is not None:
            report.encoder_nis = result.nis
            report.encoder_accepted = result.accepted
            if not result.accepted:
                reason = f"encoder gated out: NIS {result.nis:.4g} > {self._gate_encoder:.4g}"
                report.rejections.append(reason)
                logger.info("step %d: %s", report.k, reason)
        return result

    def _frame_update_now(self, z: FloatArray) -> UpdateResult:
        """Camera update of ``self.x, self.P`` with ``h`` evaluated at the current state.

        With ``config.camera_iterations > 1`` this is the iterated EKF (Bell and Cathey
        1993): ``x_{i+1} = x- + K_i (z - h(x_i) - H_i (x- - x_i))`` with ``H_i`` and ``K_i``
        at ``x_i``; the gate uses the first (plain EKF) innovation, the covariance the last
        linearization (Joseph form).
        """
        x_prior = self.x
        z_hat, H = measure(self.camera, x_prior)
        result = joseph_update(x_prior, self.P, z - z_hat, H, self.R_camera, self._gate_camera)
        if not result.accepted:
            return result
        first_nis = result.nis
        for _ in range(self.config.camera_iterations - 1):
            xi = result.x
            z_hat, H = measure(self.camera, xi)
            nu = z - z_hat - H @ (x_prior - xi)
            result = joseph_update(x_prior, self.P, nu, H, self.R_camera)
        result.nis = first_nis
        self.x, self.P = result.x, result.P
        return result

    def _scheduled(self, k: int) -> bool:
        period = self.config.camera_period
        return period is not None and k % period == self.config.camera_phase

    def __repr__(self) -> str:
        return f"{type(self).__name__}(k={self.k}, nx={self.nx})"
