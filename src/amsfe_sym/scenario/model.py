"""The scenario's value objects: a resolved, validated scenario (docs/reference/scenarios.md)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class PlantConfig:
    """The simulated truth.

    Attributes:
        q0, qd0: Initial link angles [rad] and rates [rad/s].
        motor0: ``"equilibrium"`` (qm0 = q0 + Ks^-1 g(q0): the springs hold the arm still),
            ``"link"`` (qm0 = q0), or explicit ``qm0`` / ``qmd0``.
        qm0, qmd0: Explicit motor state (used when ``motor0 = "explicit"``).
        link_torque_std, motor_torque_std: White disturbance torques [N m], held per step.
    """

    q0: tuple[float, ...]
    qd0: tuple[float, ...]
    motor0: str = "equilibrium"
    qm0: tuple[float, ...] = ()
    qmd0: tuple[float, ...] = ()
    link_torque_std: float = 0.0
    motor_torque_std: float = 0.0


@dataclass(frozen=True)
class EncoderSettings:
    """Encoder noise: ``q_std`` [rad], ``qd_std`` [rad/s], ``counts_per_rev`` (0 = none)."""

    q_std: float = 1e-3
    qd_std: float = 1e-2
    counts_per_rev: int = 0


@dataclass(frozen=True)
class CameraSettings:
    """Camera timing and noise.

    ``period`` (l) and ``delay`` (d) [steps]: ``None`` (the key left out, or ``"robot"``)
    takes the robot spec's; :func:`camera_timing` resolves and checks them.
    ``stamp_offset`` [s]: what the simulated camera's stamps add to the exposure time in a
    written log (``amsfe simulate --bag``: header stamp = exposure + stamp_offset), the time
    offset ``amsfe calibrate`` finds (docs/calibrate.md); the run itself is unchanged.
    """

    pixel_std: float = 0.5
    round_to_pixel: bool = True
    drop_probability: float = 0.0
    jitter_steps: int = 0
    period: int | None = None
    delay: int | None = None
    phase: int = 0
    stamp_offset: float = 0.0


@dataclass(frozen=True)
class EstimateInit:
    """The estimator's start: ``q``, ``qd``; ``motor`` = ``"encoders"`` (first encoder
    sample) or ``"link"``; ``theta`` (empty = the robot spec's initial); 1-sigma ``std`` of
    each block [same units]."""

    q: tuple[float, ...]
    qd: tuple[float, ...]
    motor: str = "encoders"
    theta: tuple[float, ...] = ()
    std: Mapping[str, float] = field(
        default_factory=lambda: {"q": 0.5, "qd": 0.5, "qm": 0.01, "qmd": 0.1, "theta": 0.2}
    )


@dataclass(frozen=True)
class FilterSettings:
    """The filter's noise model and options.

    Attributes:
        link_torque_std, motor_torque_std: Q of eq. (3) as torque standard deviations
            [N m] held over one step (w = sigma T).
        theta_rate_std: Random-walk intensity of theta [unit/s] (theta+ = theta + T w).
        paper_torque_std: With the paper's discrete model (the library's integrator
            ``"paper"``, eqs. (1a)-(1d)): the link and motor torque standard deviations [N m]
            the filter assumes instead (0: the two above).  The explicit map's systematic
            T^2/2 acceleration error per step is model error the plant's white torques do
            not cover (docs/explanation/control.md, "The paper's integrator in the loop").
        encoder_q_std, encoder_qd_std, camera_pixel_std: R [rad, rad/s, px]; 0 means
            "the sensor's true noise, including quantization and rounding".
        gate_probability: Chi-square gate on camera innovations (0 disables).
        camera_iterations: Iterated-EKF steps of the camera update (naive, replay); 1 = EKF.
        buffer_steps: History kept for late frames [steps].
        backward_map: ``oosm``'s backward map of eq. (24): ``"linearised"`` about the stored
            forward pass, or ``"inverse"`` through the generated inverse transition (eq. (22)).
    """

    link_torque_std: float = 0.1
    motor_torque_std: float = 0.1
    theta_rate_std: float = 0.05
    paper_torque_std: float = 0.0
    encoder_q_std: float = 0.0
    encoder_qd_std: float = 0.0
    camera_pixel_std: float = 0.0
    gate_probability: float = 0.9999
    camera_iterations: int = 1
    buffer_steps: int = 1000
    backward_map: str = "linearised"


@dataclass(frozen=True)
class Scenario:
    """A complete simulation set-up (see ``docs/reference/scenarios.md``).

    ``integrator`` overrides the robot spec's discrete model for the estimator ("" keeps the
    robot's); the library is then generated under ``<robot>_<integrator>``.
    """

    name: str
    robot: str
    duration: float
    integrator: str
    seed: int
    estimator: str
    controller: str
    trajectory: Mapping[str, Any]
    plant: PlantConfig
    estimate0: EstimateInit
    encoders: EncoderSettings = EncoderSettings()
    camera: CameraSettings = CameraSettings()
    filter: FilterSettings = FilterSettings()
    controller_gains: Mapping[str, Any] = field(default_factory=dict)
    compare: tuple[str, ...] = ()
    description: str = ""
    source: Path | None = None

    def with_overrides(self, **kw: Any) -> Scenario:
        """Copy with top-level fields replaced (``None`` values are ignored)."""
        return replace(self, **{k: v for k, v in kw.items() if v is not None})

    def gains_for(self, controller: str | None = None) -> dict[str, Any]:
        """The gains of ``controller`` (default the scenario's): ``[controller_gains.NAME]``
        over any flat keys of ``[controller_gains]`` (which apply to every controller)."""
        name = controller or self.controller
        flat = {k: v for k, v in self.controller_gains.items() if not isinstance(v, Mapping)}
        own = self.controller_gains.get(name, {})
        return {**flat, **own} if isinstance(own, Mapping) else flat

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``config.toml`` (robot path resolved so the run is self-contained)."""
        d = asdict(self)
        d.pop("source")
        return d


#: The tables of a scenario's TOML and the value object each is read into (the field of
#: :class:`Scenario` of the same name).
SECTIONS: dict[str, Any] = {
    "plant": PlantConfig,
    "estimate0": EstimateInit,
    "encoders": EncoderSettings,
    "camera": CameraSettings,
    "filter": FilterSettings,
}
