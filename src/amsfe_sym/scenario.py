"""Scenarios: everything a simulation run needs beyond the robot, in one TOML file.

Shipped scenarios live in ``scenarios/`` (``paper-sim``, ``paper-exp``); copy one and edit
it.  Every key is documented in ``docs/scenarios.md``.  A run saves its resolved scenario
as ``config.toml``, which ``amsfe simulate <run>/config.toml`` re-runs exactly.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from amsfe_sym._toml import dump_toml, tomllib
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.spec import INTEGRATORS, data_dir

__all__ = [
    "CameraTiming",
    "Scenario",
    "apply_sets",
    "camera_timing",
    "dump_toml",
    "find_scenario",
    "load_scenario",
    "scenarios_dir",
]


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
    """

    pixel_std: float = 0.5
    round_to_pixel: bool = True
    drop_probability: float = 0.0
    jitter_steps: int = 0
    period: int | None = None
    delay: int | None = None
    phase: int = 0


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
        encoder_q_std, encoder_qd_std, camera_pixel_std: R [rad, rad/s, px]; 0 means
            "the sensor's true noise, including quantization and rounding".
        gate_probability: Chi-square gate on camera innovations (0 disables).
        camera_iterations: Iterated-EKF steps of the camera update (naive, replay); 1 = EKF.
        buffer_steps: History kept for late frames [steps].
    """

    link_torque_std: float = 0.1
    motor_torque_std: float = 0.1
    theta_rate_std: float = 0.05
    encoder_q_std: float = 0.0
    encoder_qd_std: float = 0.0
    camera_pixel_std: float = 0.0
    gate_probability: float = 0.9999
    camera_iterations: int = 1
    buffer_steps: int = 1000


@dataclass(frozen=True)
class Scenario:
    """A complete simulation set-up (see ``docs/scenarios.md``).

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


def scenarios_dir() -> Path:
    """Folder of shipped scenarios (``$AMSFE_SCENARIOS_DIR`` overrides)."""
    return data_dir("scenarios", "AMSFE_SCENARIOS_DIR")


def find_scenario(name_or_path: str | os.PathLike[str]) -> Path:
    """A scenario name (``paper-sim``), a ``.toml`` path, or a run folder's ``config.toml``."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    if p.is_dir() and (p / "config.toml").is_file():
        return p / "config.toml"
    shipped = scenarios_dir() / f"{name_or_path}.toml"
    if shipped.is_file():
        return shipped
    known = sorted(f.stem for f in scenarios_dir().glob("*.toml"))
    raise ConfigError(
        describe(
            f"scenario {str(name_or_path)!r}",
            "a shipped scenario name, a .toml file or a run folder",
            "nothing by that name",
            f"use one of {known}",
        )
    )


_SECTIONS: dict[str, Any] = {
    "plant": PlantConfig,
    "estimate0": EstimateInit,
    "encoders": EncoderSettings,
    "camera": CameraSettings,
    "filter": FilterSettings,
}
#: ``[camera]`` keys whose "the robot's" value is ``None`` (key left out, or ``"robot"``).
_ROBOT_DEFAULT = ("period", "delay")
_TOP = {
    "name",
    "robot",
    "integrator",
    "duration",
    "seed",
    "estimator",
    "controller",
    "trajectory",
    "controller_gains",
    "compare",
    "description",
    *_SECTIONS,
}


def load_scenario(name_or_path: str | os.PathLike[str]) -> Scenario:
    """Parse and validate a scenario file.

    Raises:
        ConfigError: unknown keys, bad values, non-positive noise where a covariance must be
            positive definite, a camera delay longer than the filter's buffer, ...
    """
    path = find_scenario(name_or_path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}). Fix: correct the syntax.") from exc
    return parse_scenario(data, path)


def parse_scenario(data: Mapping[str, Any], path: Path) -> Scenario:
    """Build a :class:`Scenario` from parsed TOML."""
    where = str(path)
    unknown = sorted(set(data) - _TOP)
    if unknown:
        raise ConfigError(
            describe(
                where,
                f"keys among {sorted(_TOP)}",
                f"unknown {unknown}",
                "remove or rename them (docs/scenarios.md)",
            )
        )
    for key in ("robot", "plant", "estimate0", "trajectory"):
        if key not in data:
            raise ConfigError(describe(where, f"a {key!r} entry", "none", f"add {key}"))
    sections: dict[str, Any] = {}
    for key, cls in _SECTIONS.items():
        raw = dict(data.get(key, {}))
        fields = {f.name for f in dataclasses.fields(cls)}
        bad = sorted(set(raw) - fields)
        if bad:
            raise ConfigError(
                describe(
                    f"{where} [{key}]",
                    f"keys among {sorted(fields)}",
                    f"unknown {bad}",
                    "remove or rename them (docs/scenarios.md)",
                )
            )
        types = {f.name: str(f.type) for f in dataclasses.fields(cls)}
        raw = {
            k: _robot_default(f"{where} [camera] {k}", k, v)
            if key == "camera" and k in _ROBOT_DEFAULT
            else _typed(v, types[k], f"{where} [{key}] {k}")
            for k, v in raw.items()
        }
        sections[key] = cls(**raw)
    top = {
        k: _typed(data[k], str(f.type), f"{where}: {k}")
        for f in dataclasses.fields(Scenario)
        if (k := f.name) in data and k not in _SECTIONS and k != "compare"
    }
    robot = top["robot"]
    if not Path(robot).is_absolute() and (path.parent / robot).exists():
        robot = str((path.parent / robot).resolve())
    sc = Scenario(
        name=top.get("name", path.stem),
        robot=robot,
        integrator=top.get("integrator", ""),
        duration=top.get("duration", 10.0),
        seed=top.get("seed", 0),
        estimator=top.get("estimator", "oosm"),
        controller=top.get("controller", "truth-ct"),
        trajectory=top["trajectory"],
        controller_gains=top.get("controller_gains", {}),
        compare=_names(data.get("compare", []), f"{where}: compare"),
        description=top.get("description", ""),
        source=path,
        **sections,
    )
    validate(sc, where)
    return sc


def _names(value: Any, what: str) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
        raise ConfigError(
            describe(what, "a list of controller names", repr(value), 'e.g. ["amsfe", "dtsmc"]')
        )
    return tuple(value)


def _typed(v: Any, ann: str, what: str) -> Any:
    """``v`` as the type the dataclass field annotation ``ann`` names, or a one-line
    :class:`ConfigError` (a string where a number is expected is not read letter by letter)."""

    def number(x: Any) -> bool:
        return isinstance(x, int | float) and not isinstance(x, bool)

    def bad(expected: str, fix: str) -> ConfigError:
        kind = "a string" if isinstance(v, str) else type(v).__name__
        return ConfigError(describe(what, expected, f"{v!r} ({kind})", fix))

    key = what.rsplit(" ", 1)[-1]
    if ann == "float":
        if not number(v):
            raise bad("a number", f"write a number without quotes, e.g. {key} = 1.0")
        return float(v)
    if ann == "int":
        if isinstance(v, float) and v.is_integer():
            raise bad("an integer", f"write {key} = {int(v)}")
        if not isinstance(v, int) or isinstance(v, bool):
            raise bad("an integer", f"write a whole number without quotes, e.g. {key} = 0")
        return v
    if ann == "bool":
        if not isinstance(v, bool):
            raise bad("true or false", f"write {key} = true or {key} = false")
        return v
    if ann == "str":
        if not isinstance(v, str):
            raise bad("a string", f'quote it, e.g. {key} = "{v}"')
        return v
    if ann.startswith("tuple"):
        if not isinstance(v, list) or not all(number(x) for x in v):
            raise bad("a list of numbers", f"write e.g. {key} = [0.0, 0.0] (one per joint)")
        return tuple(float(x) for x in v)
    if ann.startswith("Mapping") or ann.startswith("dict"):
        if not isinstance(v, Mapping):
            raise bad("a table", f"write e.g. {key} = {{ ... }} or a [{key}] section")
        return dict(v)
    return v


def _robot_default(where: str, key: str, v: Any) -> int | None:
    """A ``[camera] period``/``delay`` entry: ``"robot"`` -> None, else an integer."""
    if v == "robot":
        return None
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(
            describe(
                where, 'an integer or "robot"', repr(v), f'write {key} = "robot" or leave it out'
            )
        )
    if key == "period" and v == 0:
        raise ConfigError(
            describe(
                where,
                "an integer >= 1",
                "0 (the old way to say 'the robot's period')",
                'leave period out (or write "robot"); note that delay = 0 now means no delay',
            )
        )
    return v


def validate(sc: Scenario, where: str = "scenario") -> None:
    """Value checks that need no robot: positive durations, noise, probabilities."""

    def positive(v: float, what: str, allow_zero: bool = False, fix: str = "") -> None:
        ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
        if not ok:
            default_fix = (
                "use a standard deviation >= 0 (0 = none)"
                if allow_zero
                else "use a standard deviation > 0 (a covariance must be positive definite)"
            )
            raise ConfigError(
                describe(
                    f"{where}: {what}",
                    "a finite number " + (">= 0" if allow_zero else "> 0"),
                    repr(v),
                    fix or default_fix,
                )
            )

    positive(sc.duration, "duration", fix="set the simulated time in seconds, e.g. duration = 10.0")
    if sc.seed < 0:
        raise ConfigError(
            describe(f"{where}: seed", "an integer >= 0", repr(sc.seed), "write seed = 0")
        )
    for k, v in sc.estimate0.std.items():
        if not isinstance(v, int | float) or isinstance(v, bool):
            raise ConfigError(
                describe(
                    f"{where}: [estimate0] std.{k}",
                    "a number",
                    repr(v),
                    f"write std.{k} = 0.1 (no quotes)",
                )
            )
    if sc.integrator and sc.integrator not in INTEGRATORS:
        raise ConfigError(
            describe(
                f"{where}: integrator",
                "'' (the robot's) or one of " + ", ".join(INTEGRATORS),
                repr(sc.integrator),
                'write integrator = "rk4" (or "" for the robot spec\'s)',
            )
        )
    f = sc.filter
    positive(f.link_torque_std, "[filter] link_torque_std")
    positive(f.motor_torque_std, "[filter] motor_torque_std")
    positive(f.theta_rate_std, "[filter] theta_rate_std", allow_zero=True)
    for name in ("encoder_q_std", "encoder_qd_std", "camera_pixel_std"):
        positive(getattr(f, name), f"[filter] {name}", allow_zero=True)
    positive(sc.encoders.q_std, "[encoders] q_std", allow_zero=True)
    positive(sc.encoders.qd_std, "[encoders] qd_std", allow_zero=True)
    positive(sc.camera.pixel_std, "[camera] pixel_std", allow_zero=True)
    positive(sc.plant.link_torque_std, "[plant] link_torque_std", allow_zero=True)
    positive(sc.plant.motor_torque_std, "[plant] motor_torque_std", allow_zero=True)
    for k, v in sc.estimate0.std.items():
        positive(float(v), f"[estimate0] std.{k}")
    if sc.plant.motor0 not in ("equilibrium", "link", "explicit"):
        raise ConfigError(
            describe(
                f"{where}: [plant] motor0",
                "equilibrium | link | explicit",
                repr(sc.plant.motor0),
                'write motor0 = "equilibrium" (springs hold the arm still at t = 0)',
            )
        )
    if sc.estimate0.motor not in ("encoders", "link"):
        raise ConfigError(
            describe(
                f"{where}: [estimate0] motor",
                "encoders | link",
                repr(sc.estimate0.motor),
                'write motor = "encoders" (motor states from the first encoder sample)',
            )
        )


@dataclass(frozen=True)
class CameraTiming:
    """The camera's resolved timing (paper Sec. 3.2, eq. 11), all in steps of T.

    Attributes:
        period: l, steps between exposures (>= 1).
        delay: d, steps from exposure to delivery (>= 0; 0 = delivered at once).
        phase: Exposures at steps k with ``k % period == phase``.
        jitter_steps: Largest extra random delay.
    """

    period: int
    delay: int
    phase: int
    jitter_steps: int

    @property
    def max_delay(self) -> int:
        """The largest delay a frame may have: ``delay + jitter_steps``."""
        return self.delay + self.jitter_steps


def camera_timing(
    sc: Scenario, robot_period: int, robot_delay: int, needs_history: bool = True
) -> CameraTiming:
    """The one place a scenario's camera period and delay are resolved and checked.

    ``None`` in the scenario takes the robot's (``robot_period``, ``robot_delay``: the robot
    spec's ``[camera]``, or the library manifest's, which records the same values).  Needs
    no library, so it runs before anything is generated.

    Args:
        sc: The scenario.
        robot_period, robot_delay: The robot's l and d [steps].
        needs_history: Whether the estimator keeps a history for late frames (``replay``,
            ``oosm``, ``cloning``): then ``[filter] buffer_steps`` must cover the largest
            delay.

    Raises:
        ConfigError: period < 1, delay < 0, a phase outside [0, period), or a buffer
            shorter than delay + jitter.
    """
    cam = sc.camera
    period = robot_period if cam.period is None else cam.period
    delay = robot_delay if cam.delay is None else cam.delay
    where = f"{sc.name}: [camera]"
    if period < 1:
        raise ConfigError(
            describe(
                f"{where} period", "an integer >= 1", repr(period), "write period = 125 (steps)"
            )
        )
    if delay < 0 or cam.jitter_steps < 0:
        raise ConfigError(
            describe(
                f"{where} delay / jitter_steps",
                "integers >= 0",
                f"{delay} / {cam.jitter_steps}",
                "use delays in whole steps >= 0 (omit delay for the robot's)",
            )
        )
    if not 0 <= cam.phase < period:
        raise ConfigError(
            describe(
                f"{where} phase",
                f"an integer in [0, {period})",
                repr(cam.phase),
                "write a phase smaller than the period, e.g. phase = 0",
            )
        )
    timing = CameraTiming(period, delay, cam.phase, cam.jitter_steps)
    if needs_history and timing.max_delay > sc.filter.buffer_steps:
        raise ConfigError(
            describe(
                "[filter] buffer_steps",
                f">= camera delay + jitter = {timing.max_delay} steps",
                str(sc.filter.buffer_steps),
                "raise buffer_steps or shorten the delay",
            )
        )
    return timing


# --------------------------------------------------------------------------- --set
#: Top-level scenario keys ``--set`` may change (``seed`` and ``estimator`` are the study's).
_TOP_SETTABLE = ("integrator", "duration", "controller")
#: Dataclass sections of :class:`Scenario`.
_SET_SECTIONS = tuple(_SECTIONS)
#: Mapping-valued entries whose existing keys ``--set`` may change.
_MAPPINGS = ("trajectory", "controller_gains", "estimate0.std")
#: ``--set`` keys whose value may be ``"robot"`` (None: the robot's value).
_OPTIONAL_INT = tuple(f"camera.{k}" for k in _ROBOT_DEFAULT)


def _parse_value(text: str) -> Any:
    """A TOML value (number, bool, quoted string, list) or, failing that, the bare text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def _coerce(key: str, current: Any, raw: str) -> Any:
    """``raw`` converted to the type of ``current`` (the field's present value)."""
    value = _parse_value(raw)

    def bad(expected: str) -> ConfigError:
        return ConfigError(
            describe(f"--set {key}={raw}", expected, repr(value), f"give {key} a valid value")
        )

    if key in _OPTIONAL_INT:  # None (or "robot") = the robot's value
        if value == "robot":
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad('an integer or "robot"')
        return value
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(current, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("an integer")
        return value
    if isinstance(current, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad("a number")
        return float(value)
    if isinstance(current, tuple):
        items: Any = value
        if isinstance(value, str):
            items = [s for s in value.strip("[]() ").split(",") if s.strip()]
        elif not isinstance(value, list):
            items = [value]
        try:
            return tuple(float(v) for v in items)
        except (TypeError, ValueError):
            raise bad("numbers separated by commas, e.g. 0.5,0.5") from None
    if isinstance(current, str):
        if isinstance(value, list | dict):
            raise bad("a string")
        return str(value).lower() if isinstance(value, bool) else str(value)
    raise bad(f"a value like {current!r}")


def _split_set(text: str) -> tuple[str, str]:
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or not raw.strip():
        raise ConfigError(
            describe(
                f"--set {text!r}",
                "KEY=VALUE, e.g. integrator=paper or filter.link_torque_std=2",
                "no '=' or an empty side",
                "write section.field=value",
            )
        )
    return key, raw


def _settable_keys(sc: Scenario) -> list[str]:
    keys = list(_TOP_SETTABLE)
    for sec in _SET_SECTIONS:
        keys += [f"{sec}.{f.name}" for f in dataclasses.fields(getattr(sc, sec))]
    keys += [f"trajectory.{k}" for k in sc.trajectory]
    keys += [f"controller_gains.{k}" for k in sc.controller_gains]
    keys += [f"estimate0.std.{k}" for k in sc.estimate0.std]
    return [k for k in keys if k != "estimate0.std"]


def apply_sets(sc: Scenario, sets: Sequence[str]) -> Scenario:
    """Scenario ``sc`` with ``KEY=VALUE`` overrides applied, then re-validated.

    Keys: ``integrator``, ``duration``, ``controller``; ``section.field`` for the sections
    plant, encoders, camera, filter, estimate0; ``trajectory.K``, ``controller_gains.K`` and
    ``estimate0.std.K`` for keys the scenario already has; ``controller_gains.NAME.K`` for a
    gain of controller NAME (its table must exist).  Values are TOML literals
    (``2``, ``0.01``, ``true``, ``"rk4"``) or bare words (``paper``); tuples are written
    ``0.5,0.5``.

    Raises:
        ConfigError: unknown key, value of the wrong type, or a value the scenario's own
            validation refuses (e.g. a negative noise standard deviation).
    """
    for text in sets:
        key, raw = _split_set(text)
        parts = key.split(".")
        if len(parts) == 1 and key in _TOP_SETTABLE:
            sc = dataclasses.replace(sc, **{key: _coerce(key, getattr(sc, key), raw)})
        elif len(parts) == 2 and parts[0] in _SET_SECTIONS:
            sec = getattr(sc, parts[0])
            names = {f.name for f in dataclasses.fields(sec)}
            if parts[1] not in names or parts[1] == "std":
                raise _unknown_key(key, sc)
            new = _coerce(key, getattr(sec, parts[1]), raw)
            sc = dataclasses.replace(sc, **{parts[0]: dataclasses.replace(sec, **{parts[1]: new})})
        elif (
            len(parts) == 3
            and parts[0] == "controller_gains"
            and isinstance(sc.controller_gains.get(parts[1]), Mapping)
        ):  # controller_gains.NAME.K: one controller's gain (added if the table lacks it; the
            # controller refuses a key it does not know)
            table = dict(sc.controller_gains[parts[1]])
            old = table.get(parts[2])
            table[parts[2]] = _coerce(key, old, raw) if old is not None else _parse_value(raw)
            gains = {**sc.controller_gains, parts[1]: table}
            sc = dataclasses.replace(sc, controller_gains=gains)
        elif ".".join(parts[:-1]) in _MAPPINGS:
            where, name = ".".join(parts[:-1]), parts[-1]
            mapping: Mapping[str, Any] = (
                sc.estimate0.std if where == "estimate0.std" else getattr(sc, where)
            )
            if name not in mapping:
                raise _unknown_key(key, sc)
            d = dict(mapping)
            d[name] = _coerce(key, d[name], raw)
            if where == "estimate0.std":
                sc = dataclasses.replace(sc, estimate0=dataclasses.replace(sc.estimate0, std=d))
            else:
                changes: dict[str, Any] = {where: d}
                sc = dataclasses.replace(sc, **changes)
        else:
            raise _unknown_key(key, sc)
    validate(sc, f"{sc.name} with --set")
    return sc


def _unknown_key(key: str, sc: Scenario) -> ConfigError:
    return ConfigError(
        describe(
            f"--set key {key!r}",
            "integrator, duration, controller or section.field with section in "
            + ", ".join(_SET_SECTIONS)
            + " (also trajectory.K, controller_gains.K, estimate0.std.K)",
            "no such field",
            "one of: " + ", ".join(_settable_keys(sc)),
        )
    )
