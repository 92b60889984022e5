"""The estimators' shared settings (:class:`FilterConfig`): gates, history buffer, camera
schedule, backward map; checked where they are made, since the C runtime's parameter blocks
hold them as C ``int`` and ``double``."""

from __future__ import annotations

from dataclasses import dataclass

from amsfe_sym.core.values import BACKWARD_MAPS
from amsfe_sym.errors import ConfigError, describe, unknown_name

__all__ = ["BACKWARD_MAPS", "C_INT_MAX", "DEFAULT_CONFIG", "FilterConfig"]


@dataclass(frozen=True)
class FilterConfig:
    """Settings shared by the estimators.

    Attributes:
        gate_probability: Chi-square gate on every camera innovation: a frame whose NIS
            exceeds ``chi2.ppf(gate_probability, dim)`` is rejected. ``None`` disables it.
        encoder_gate_probability: The same gate for encoder samples; ``None`` (the default)
            disables it.  Encoders are the filter's primary, outlier-free sensor: a filter that
            gates them out after a transient (a poor prior, a large late-frame correction)
            runs open loop and never recovers, which we measured on paper-sim.
        camera_iterations: Gauss-Newton iterations of the camera update applied at the
            current state (``naive``, ``replay``): 1 is the plain EKF update; more is the
            iterated EKF, which relinearizes the pinhole map at the updated estimate.  It
            matters for a large first correction from a poor prior; for a linear h every
            iteration gives the same result.
        buffer_steps: History kept for late frames [steps]: a frame with
            ``k - kappa > buffer_steps`` is rejected (replay, oosm, cloning).
        camera_period: Camera period ``l`` [steps] (paper eq. (11)). Required by ``cloning``,
            which clones the state at each scheduled exposure.
        camera_phase: Exposures happen at steps ``k`` with ``k % camera_period == camera_phase``.
        camera_max_delay: Largest delay ``d`` + jitter [steps] a frame may have; ``cloning``
            drops a clone this many steps after its exposure (a dropped frame). ``None``
            means ``buffer_steps``.
        backward_map: How ``oosm`` maps the current estimate back to the exposure time
            (eq. (24)): ``"linearised"`` (default) linearises the backward map about the
            filter's stored forward pass (one linear solve per frame); ``"inverse"`` is the
            paper's form, ``L`` applications of the model's inverse transition (eq. (22)) with
            the jacobian of the backward map taken at the points it passes through.  See
            ``docs/explanation/estimation-algorithms.md``.
    """

    gate_probability: float | None = 0.9999
    encoder_gate_probability: float | None = None
    camera_iterations: int = 1
    buffer_steps: int = 1000
    camera_period: int | None = None
    camera_phase: int = 0
    camera_max_delay: int | None = None
    backward_map: str = "linearised"

    def __post_init__(self) -> None:
        for name in ("gate_probability", "encoder_gate_probability"):
            p = getattr(self, name)
            if p is not None and not (0.0 < p < 1.0):
                raise ConfigError(
                    describe(name, "a probability in (0, 1) or None", repr(p), "e.g. 0.9999")
                )
        _check_int("camera_iterations", self.camera_iterations, 1, "1 = plain EKF, 2-5 = IEKF")
        _check_int("buffer_steps", self.buffer_steps, 1, "keep at least delay + jitter steps")
        if self.camera_period is not None:
            _check_int("camera_period", self.camera_period, 1, "give l in steps, or None")
            _check_int(
                "camera_phase",
                self.camera_phase,
                0,
                "use exposure_step % camera_period",
                high=self.camera_period - 1,
            )
        if self.camera_max_delay is not None:
            _check_int("camera_max_delay", self.camera_max_delay, 0, "give d + max jitter")
        if self.backward_map not in BACKWARD_MAPS:
            raise unknown_name("backward_map", self.backward_map, BACKWARD_MAPS)


#: The largest value of a C ``int`` (the C runtime's parameter blocks hold these settings).
C_INT_MAX = 2**31 - 1


def _check_int(name: str, value: object, low: int, fix: str, high: int = C_INT_MAX) -> None:
    """Refuse anything but an integer (not a bool) in ``[low, high]``: the C parameter
    blocks are C ``int``, so a larger value would wrap silently there."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(describe(name, f"an integer in [{low}, {high}]", repr(value), fix))


DEFAULT_CONFIG = FilterConfig()
