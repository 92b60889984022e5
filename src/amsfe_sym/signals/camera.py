"""The simulated camera: the slow, late link-side measurement ``z_c = h_c(q) + v_c`` [px]
(paper eqs. 7-11), with exposure, noise, rounding, image bounds, drops, jitter and a delivery
queue.  See :mod:`amsfe_sym.signals` for the conventions shared by every sensor."""

from __future__ import annotations

import heapq
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import ConfigError, MeasurementError, ShapeError, describe

if TYPE_CHECKING:
    from amsfe_sym.load.spec import CameraSpec

from amsfe_sym.arrays import FloatArray
from amsfe_sym.signals.checks import _is_int, _positive_int

__all__ = ["Camera", "CameraConfig", "CameraFrame", "CameraStats"]


# --------------------------------------------------------------------------------------
# camera, eqs. (7)-(11)


@dataclass(frozen=True)
class CameraConfig:
    """Camera timing, noise and image size.

    Attributes:
        period: ``l``, steps between two exposures (eq. 11), >= 1.
        delay: ``d``, steps from an exposure to its delivery, >= 0 (independent of ``l``).
        pixel_std: Standard deviation of the pixel noise [px] on each axis, >= 0.
        width: Image width [px]; a frame is inside when ``0 <= u < width``.
        height: Image height [px]; a frame is inside when ``0 <= v < height``.
        phase: Exposures happen at steps ``k`` with ``k % period == phase``,
            ``0 <= phase < period``.
        round_to_pixel: Round the noisy pixel to the nearest integer (adds a uniform error
            of variance 1/12 px^2 per axis, included in :attr:`variance`).
        drop_probability: Probability that an exposed frame is lost, in [0, 1).
        jitter_steps: Extra delivery delay drawn uniformly from the integers
            ``0 .. jitter_steps``, so a frame arrives ``d .. d + jitter_steps`` steps after
            its exposure.  With ``jitter_steps >= period`` a later frame can arrive before an
            earlier one: frames are then delivered OUT OF ORDER across steps (within one step
            they are sorted by exposure step) and the estimator must cope.

    Raises:
        ConfigError: any value outside the ranges above.
    """

    period: int
    delay: int
    pixel_std: float
    width: int = 640
    height: int = 512
    phase: int = 0
    round_to_pixel: bool = True
    drop_probability: float = 0.0
    jitter_steps: int = 0

    def __post_init__(self) -> None:
        _positive_int(self.period, "CameraConfig.period (l, steps between exposures)", 1)
        _positive_int(self.delay, "CameraConfig.delay (d, steps exposure -> delivery)", 0)
        _positive_int(self.width, "CameraConfig.width [px]", 1)
        _positive_int(self.height, "CameraConfig.height [px]", 1)
        _positive_int(self.jitter_steps, "CameraConfig.jitter_steps", 0)
        if not _is_int(self.phase) or not 0 <= int(self.phase) < int(self.period):
            raise ConfigError(
                describe(
                    "CameraConfig.phase",
                    f"an integer in [0, period) = [0, {self.period})",
                    repr(self.phase),
                    "use phase = k0 % period for a first exposure at step k0",
                )
            )
        std = self.pixel_std
        if (
            not isinstance(std, numbers.Real)
            or isinstance(std, bool)
            or not (math.isfinite(float(std)) and float(std) >= 0.0)
        ):
            raise ConfigError(
                describe(
                    "CameraConfig.pixel_std [px]", "a finite number >= 0", repr(std), "e.g. 1.0"
                )
            )
        p = self.drop_probability
        if not isinstance(p, numbers.Real) or isinstance(p, bool) or not 0.0 <= float(p) < 1.0:
            raise ConfigError(
                describe(
                    "CameraConfig.drop_probability",
                    "a number in [0, 1)",
                    repr(p),
                    "use 0 for a camera that never loses a frame",
                )
            )
        if not isinstance(self.round_to_pixel, bool):
            raise ConfigError(
                describe(
                    "CameraConfig.round_to_pixel",
                    "true or false",
                    repr(self.round_to_pixel),
                    "write round_to_pixel = true or round_to_pixel = false",
                )
            )
        # store plain Python numbers (numpy scalars would leak into reprs and hashes)
        for name in ("period", "delay", "width", "height", "phase", "jitter_steps"):
            object.__setattr__(self, name, int(getattr(self, name)))
        object.__setattr__(self, "pixel_std", float(std))
        object.__setattr__(self, "drop_probability", float(p))

    @property
    def variance(self) -> float:
        """Effective pixel variance per axis [px^2]: ``pixel_std^2`` (+ 1/12 if rounded).

        The diagonal of ``R_c`` for the estimator (eq. 10).
        """
        return self.pixel_std**2 + (1.0 / 12.0 if self.round_to_pixel else 0.0)

    @classmethod
    def from_spec(cls, spec: CameraSpec, pixel_std: float, **overrides: Any) -> CameraConfig:
        """Build from a robot spec's camera section (period, delay, width, height).

        Args:
            spec: The robot's :class:`amsfe_sym.load.spec.CameraSpec`.
            pixel_std: Pixel noise standard deviation [px] (not part of the robot spec).
            **overrides: Any other field of :class:`CameraConfig` (e.g. ``phase``).
        """
        values: dict[str, Any] = {
            "period": spec.period,
            "delay": spec.delay,
            "width": spec.width,
            "height": spec.height,
            "pixel_std": pixel_std,
        }
        values.update(overrides)
        return cls(**values)


@dataclass
class CameraStats:
    """Counters of what happened to the exposed frames.

    ``exposed == delivered + dropped + out_of_image + in_flight`` at all times (the last is
    :attr:`Camera.in_flight`).

    Attributes:
        exposed: Exposures taken.
        delivered: Frames returned by :meth:`Camera.tick`.
        dropped: Frames lost at random (``drop_probability``).
        out_of_image: Frames not delivered because the point was not seen: the true
            projection is NaN/inf (e.g. behind the camera) or outside the image, or the
            noisy (rounded) pixel fell outside the image.  Checked before the drop, so a
            frame counts in one category only.
        out_of_image_true: Of ``out_of_image``, those whose TRUE projection was NaN, inf or
            outside the image.
        out_of_order: Delivered frames exposed before a frame delivered at an earlier step
            (possible only with ``jitter_steps > 0``).
    """

    exposed: int = 0
    delivered: int = 0
    dropped: int = 0
    out_of_image: int = 0
    out_of_image_true: int = 0
    out_of_order: int = 0


@dataclass(order=True)
class _Pending:
    delivery_step: int
    exposure_step: int
    z: FloatArray = field(compare=False)


class Camera:
    """A camera seeing the tracked point: slow (period ``l``) and late (delay ``d``).

    Call :meth:`tick` once per step with the TRUE link angles.  At an exposure step
    (``k % period == phase``) it projects them with ``project`` (the map ``h_c`` of eqs.
    7-9), adds Gaussian pixel noise (eq. 10), rounds to whole pixels if asked, decides
    whether the frame is lost, draws the delivery jitter, and queues the frame for step
    ``k + delay + jitter``.  :meth:`tick` returns the frames due at this step.

    Args:
        config: Timing, noise, image size.
        project: Map from the true link angles ``q`` [rad], shape (n,), to the pixel
            ``[u, v]`` [px], shape (2,).  It may return NaN when the point cannot be seen
            (e.g. behind the camera); such frames count as out of image.
        rng: The only source of randomness.  Per exposure it draws, in this order, 2
            standard normals (noise), 1 uniform (drop), 1 integer (jitter), whatever the
            configuration and the frame's fate.
    """

    def __init__(
        self,
        config: CameraConfig,
        project: Callable[[FloatArray], ArrayLike],
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self.project = project
        self._rng = rng
        self._queue: list[_Pending] = []
        self._last_step: int | None = None
        self._last_delivered_exposure: int | None = None
        self.stats = CameraStats()

    @property
    def in_flight(self) -> int:
        """Frames exposed and queued but not yet delivered."""
        return len(self._queue)

    def is_exposure_step(self, k: int) -> bool:
        """True when an image is taken at step ``k``."""
        return k % self.config.period == self.config.phase

    def tick(self, k: int, q_true: ArrayLike) -> list[CameraFrame]:
        """Advance the camera to step ``k``; return the frames delivered at ``k``.

        Args:
            k: The current step; must increase strictly from call to call (steps skipped
                between calls take no exposure; frames due in them arrive at ``k``).
            q_true: TRUE link angles at step ``k`` [rad], shape (n,).

        Returns:
            Frames whose delivery step is ``<= k``, sorted by exposure step.  A frame
            exposed at ``k`` with ``delay = 0`` (and no jitter) is returned by this call.

        Raises:
            ConfigError: ``k`` is not an integer or not larger than the previous step.
            ShapeError: ``project`` does not return 2 values.
            MeasurementError: ``q_true`` holds NaN or inf.
        """
        if not _is_int(k):
            raise ConfigError(describe("Camera.tick k", "an integer step", repr(k), "pass int(k)"))
        k = int(k)
        if self._last_step is not None and k <= self._last_step:
            raise ConfigError(
                describe(
                    "Camera.tick k",
                    f"a step > {self._last_step} (the previous call)",
                    str(k),
                    "call tick once per step with increasing k, or build a new Camera",
                )
            )
        self._last_step = k
        if self.is_exposure_step(k):
            self._expose(k, q_true)
        due: list[_Pending] = []
        while self._queue and self._queue[0].delivery_step <= k:
            due.append(heapq.heappop(self._queue))
        due.sort(key=lambda p: p.exposure_step)
        frames: list[CameraFrame] = []
        for p in due:
            last = self._last_delivered_exposure
            if last is not None and p.exposure_step < last:
                self.stats.out_of_order += 1
            self._last_delivered_exposure = (
                p.exposure_step if last is None else max(last, p.exposure_step)
            )
            frames.append(CameraFrame(p.exposure_step, p.z, delivery_step=k))
        self.stats.delivered += len(frames)
        return frames

    def _expose(self, k: int, q_true: ArrayLike) -> None:
        cfg = self.config
        q = np.asarray(q_true, dtype=float)
        if q.ndim != 1 or q.size == 0:
            raise ShapeError(
                describe("Camera.tick q_true [rad]", "shape (n,)", f"shape {q.shape}", "pass q")
            )
        if not np.all(np.isfinite(q)):
            raise MeasurementError(
                describe(
                    "Camera.tick q_true [rad]",
                    "finite values",
                    np.array2string(q, precision=4),
                    "the true state diverged or was not initialised; check the plant",
                )
            )
        y = np.asarray(self.project(q), dtype=float)
        if y.shape != (2,):
            raise ShapeError(
                describe(
                    "Camera project(q) result [px]",
                    "shape (2,): one pixel [u, v]",
                    f"shape {y.shape}",
                    "make the projection return the pixel of the tracked point",
                )
            )
        # Draw everything first, always, so the stream does not depend on the frame's fate.
        noise = self._rng.standard_normal(2)
        u_drop = self._rng.random()
        jitter = int(self._rng.integers(0, cfg.jitter_steps + 1))
        self.stats.exposed += 1

        if not self._inside(y):
            self.stats.out_of_image += 1
            self.stats.out_of_image_true += 1
            return
        z = y + cfg.pixel_std * noise
        if cfg.round_to_pixel:
            z = np.round(z)
        if not self._inside(z):
            self.stats.out_of_image += 1
            return
        if u_drop < cfg.drop_probability:
            self.stats.dropped += 1
            return
        z.setflags(write=False)
        heapq.heappush(self._queue, _Pending(k + cfg.delay + jitter, k, z))

    def draw_batch(self, exposures: int) -> tuple[FloatArray, FloatArray, NDArray[np.int32]]:
        """The random draws of the next ``exposures`` exposures, in :meth:`tick`'s order
        (2 normals, 1 uniform, 1 jitter each): noise (E, 2), uniforms (E,), jitters (E,)
        [steps].  For the compiled loop; the stream is used up."""
        noise = np.zeros((exposures, 2))
        uniform = np.zeros(exposures)
        jitter = np.zeros(exposures, dtype=np.int32)
        for e in range(exposures):
            noise[e] = self._rng.standard_normal(2)
            uniform[e] = self._rng.random()
            jitter[e] = int(self._rng.integers(0, self.config.jitter_steps + 1))
        return noise, uniform, jitter

    def _inside(self, y: FloatArray) -> bool:
        cfg = self.config
        return bool(np.all(np.isfinite(y)) and 0.0 <= y[0] < cfg.width and 0.0 <= y[1] < cfg.height)
