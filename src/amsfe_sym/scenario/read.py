"""Reading a scenario: find it, parse its TOML, check every value (docs/reference/scenarios.md)."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from amsfe_sym.core.toml import read_toml
from amsfe_sym.core.values import (
    BACKWARD_MAPS,
    BUFFER_STEPS_MAX,
    C_INT_MAX,
    NOISE_STD_MAX,
    read_int,
    read_number,
    read_seed,
)
from amsfe_sym.errors import ConfigError, check_known_keys, describe
from amsfe_sym.load.spec import INTEGRATORS, data_dir
from amsfe_sym.scenario.model import SECTIONS, Scenario


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
    *SECTIONS,
}


def load_scenario(name_or_path: str | os.PathLike[str]) -> Scenario:
    """Parse and validate a scenario file.

    Raises:
        ConfigError: unknown keys, bad values, non-positive noise where a covariance must be
            positive definite, a camera delay longer than the filter's buffer, ...
    """
    path = find_scenario(name_or_path)
    return parse_scenario(read_toml(path, ConfigError), path)


def parse_scenario(data: Mapping[str, Any], path: Path) -> Scenario:
    """Build a :class:`Scenario` from parsed TOML."""
    where = str(path)
    check_known_keys(where, data, _TOP, "remove or rename them (docs/reference/scenarios.md)")
    for key in ("robot", "plant", "estimate0", "trajectory"):
        if key not in data:
            raise ConfigError(describe(where, f"a {key!r} entry", "none", f"add {key}"))
    sections: dict[str, Any] = {}
    for key, cls in SECTIONS.items():
        raw = dict(data.get(key, {}))
        fields = {f.name for f in dataclasses.fields(cls)}
        bad = sorted(set(raw) - fields)
        if bad:
            raise ConfigError(
                describe(
                    f"{where} [{key}]",
                    f"keys among {sorted(fields)}",
                    f"unknown {bad}",
                    "remove or rename them (docs/reference/scenarios.md)",
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
    top: dict[str, Any] = {
        k: read_seed(data[k], f"{where}: {k}", ConfigError)
        if k == "seed"
        else _typed(data[k], str(f.type), f"{where}: {k}")
        for f in dataclasses.fields(Scenario)
        if (k := f.name) in data and k not in SECTIONS and k != "compare"
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


def _finite_vectors(sc: Scenario, where: str) -> None:
    """The initial states (``[plant]``'s and ``[estimate0]``'s vectors) hold finite numbers:
    a NaN start made the run's first check report "the true state diverged"."""
    for section, value in (("plant", sc.plant), ("estimate0", sc.estimate0)):
        for f in dataclasses.fields(value):
            v = getattr(value, f.name)
            if isinstance(v, tuple) and not all(
                isinstance(x, int | float) and math.isfinite(x) for x in v
            ):
                raise ConfigError(
                    describe(
                        f"{where}: [{section}] {f.name}",
                        "finite numbers (an initial state)",
                        repr(list(v)),
                        f"give every entry of {f.name} a finite value",
                    )
                )


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
    if ann == "float":  # the same reader as robot.toml's (amsfe_sym.core.values)
        return read_number(v, what, ConfigError)
    if ann == "int":  # (ranges are checked by validate(); here: a whole number a C int holds)
        return read_int(v, what, ConfigError, -C_INT_MAX)
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
        if ok and what != "duration" and v > NOISE_STD_MAX:  # a std: its square must be sane
            raise ConfigError(
                describe(
                    f"{where}: {what}",
                    f"a standard deviation <= {NOISE_STD_MAX:g} "
                    "(its unit: docs/reference/scenarios.md)",
                    repr(v),
                    "use the sensor's or the model's std (1e300 squared is inf)",
                )
            )
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
    _finite_vectors(sc, where)
    read_seed(sc.seed, f"{where}: seed", ConfigError)
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
    positive(f.paper_torque_std, "[filter] paper_torque_std", allow_zero=True)
    if f.backward_map not in BACKWARD_MAPS:
        raise ConfigError(
            describe(
                f"{where}: [filter] backward_map",
                "one of " + ", ".join(repr(m) for m in BACKWARD_MAPS),
                repr(f.backward_map),
                'write backward_map = "linearised" (or "inverse", the paper\'s eq. (22))',
            )
        )
    for name in ("encoder_q_std", "encoder_qd_std", "camera_pixel_std"):
        positive(getattr(f, name), f"[filter] {name}", allow_zero=True)
    read_int(f.buffer_steps, f"{where}: [filter] buffer_steps", ConfigError, 1, BUFFER_STEPS_MAX)
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
