"""The robot spec's values read from its TOML (:mod:`amsfe_sym.load.spec`): each one checked
and refused in one line (:class:`~amsfe_sym.errors.SpecError`, naming where it is and the fix).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from amsfe_sym.core.values import SUBSTEPS_MAX, read_int, read_number
from amsfe_sym.errors import SpecError, check_known_keys, describe

__all__ = [
    "read_count",
    "read_finite",
    "read_names",
    "read_nonneg",
    "read_opt_pos",
    "read_opt_vec",
    "read_positive",
    "read_steps",
    "read_table",
    "read_vec3",
    "refuse_unknown",
]


def read_table(data: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    """The table ``key`` of ``data`` ({} when absent)."""
    val = data.get(key, {})
    if not isinstance(val, Mapping):
        raise SpecError(describe(f"{where} {key}", "a table", type(val).__name__, f"write [{key}]"))
    return val


def refuse_unknown(data: Mapping[str, Any], allowed: set[str], where: str) -> None:
    """Refuse keys of ``data`` not in ``allowed``."""
    fix = "remove or rename them (see docs/reference/robot-spec.md)"
    check_known_keys(where, data, allowed, fix, SpecError)


def read_names(x: Any, where: str) -> tuple[str, ...]:
    """A list of names (joints, frames)."""
    if not isinstance(x, list) or not all(isinstance(v, str) for v in x):
        raise SpecError(describe(where, "a list of names", repr(x), 'write ["joint1", ...]'))
    return tuple(x)


def read_finite(x: Any, where: str) -> float:
    """A finite number."""
    return read_number(x, where, SpecError)


def read_positive(x: Any, where: str) -> float:
    """A finite number > 0."""
    return read_number(x, where, SpecError, low=0.0, strict=True)


def read_nonneg(x: Any, where: str) -> float:
    """A finite number >= 0."""
    return read_number(x, where, SpecError, low=0.0)


def read_count(x: Any, where: str, low: int) -> int:
    """A whole number >= ``low``."""
    return read_int(x, where, SpecError, low)


def read_steps(x: Any, where: str) -> int:
    """A count of unrolled steps: 1 .. :data:`~amsfe_sym.core.values.SUBSTEPS_MAX`."""
    return read_int(x, where, SpecError, 1, SUBSTEPS_MAX)


def read_opt_pos(x: Any, where: str) -> float | None:
    """An optional number > 0 (None: absent)."""
    return None if x is None else read_positive(x, where)


def read_vec3(x: Any, where: str) -> tuple[float, float, float]:
    """3 finite numbers [x, y, z]."""
    if not isinstance(x, Sequence) or isinstance(x, str) or len(x) != 3:
        raise SpecError(describe(where, "3 numbers [x, y, z]", repr(x), "write [x, y, z]"))
    a, b, c = (read_finite(v, where) for v in x)
    return (a, b, c)


def read_opt_vec(x: Any, where: str, strict: bool = True) -> tuple[float, ...] | None:
    """An optional per-joint array of numbers > 0 (``strict``) or >= 0."""
    if x is None:
        return None
    if not isinstance(x, Sequence) or isinstance(x, str):
        raise SpecError(
            describe(where, "an array of numbers, one per joint", repr(x), "write [..]")
        )
    return tuple(read_number(v, where, SpecError, low=0.0, strict=strict) for v in x)
