"""``--set KEY=VALUE``: one scenario key changed from the command line, re-validated with
the scenario's own checks (docs/reference/scenarios.md)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from amsfe_sym.core.toml import tomllib
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.scenario.model import SECTIONS, Scenario
from amsfe_sym.scenario.read import _ROBOT_DEFAULT, validate

#: Top-level scenario keys ``--set`` may change (``seed`` and ``estimator`` are the study's).
_TOP_SETTABLE = ("integrator", "duration", "controller")
#: Dataclass sections of :class:`Scenario`.
_SET_SECTIONS = tuple(SECTIONS)
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
    if isinstance(current, tuple | list):  # (a list: a [trajectory] key as TOML read it)
        items: Any = value
        if isinstance(value, str):
            items = [s for s in value.strip("[]() ").split(",") if s.strip()]
        elif not isinstance(value, list):
            items = [value]
        try:
            numbers = tuple(float(v) for v in items)
        except (TypeError, ValueError):
            raise bad("numbers separated by commas, e.g. 0.5,0.5") from None
        return list(numbers) if isinstance(current, list) else numbers
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


def with_filter(sc: Scenario, options: Mapping[str, Any], where: str) -> Scenario:
    """``sc`` with the ``[filter]`` keys of ``options`` over its own, key by key (a topic
    spec's ``[filter]``, on a log and live), re-validated with the scenario's checks;
    ``where`` names the source in a refusal."""
    out = dataclasses.replace(sc, filter=dataclasses.replace(sc.filter, **dict(options)))
    validate(out, where)
    return out


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
