"""Value checks shared by the simulated sensors: standard deviations, per-joint vectors,
positive integers (one clear error naming what was expected and found)."""

from __future__ import annotations

import math
import numbers
import operator
from collections.abc import Sequence
from typing import TypeGuard

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, MeasurementError, ShapeError, describe

StdLike = float | Sequence[float]


# --------------------------------------------------------------------------------------
# helpers


def _is_int(value: object) -> TypeGuard[numbers.Integral]:
    """True for Python and numpy integers, False for bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _flat_floats(value: object, what: str) -> FloatArray:
    """``value``, a number or a flat sequence of numbers, as a non-empty 1-D float array (a
    number: shape (1,)), not yet checked for finiteness."""
    try:
        arr = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError) as exc:
        raise ConfigError(
            describe(
                what,
                "a number or a list of numbers",
                repr(value),
                "write a number or a list like [0.0, 0.0] without quotes",
            )
        ) from exc
    if arr.ndim != 1 or arr.size == 0:
        raise ConfigError(
            describe(
                what,
                "a number or a non-empty flat list (one value per joint)",
                f"shape {arr.shape}",
                "write one number, or one number per joint in a flat list",
            )
        )
    return arr


def _check_std(value: object, what: str) -> StdLike:
    """Validate a scalar or per-joint standard deviation; return a float or a tuple."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        v = float(value)
        if not math.isfinite(v) or v < 0.0:
            raise ConfigError(
                describe(what, "a finite standard deviation >= 0", repr(value), "use e.g. 1e-4")
            )
        return v
    arr = _flat_floats(value, what)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ConfigError(
            describe(
                what,
                "finite standard deviations >= 0",
                repr(value),
                "replace negative, NaN or inf entries by a std >= 0 (0 = no noise)",
            )
        )
    return tuple(float(x) for x in arr)


def _per_joint(value: StdLike, n: int, what: str) -> FloatArray:
    """Broadcast a validated scalar or per-joint value to an array of shape (n,)."""
    if isinstance(value, float):
        return np.full(n, value)
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,):
        raise ShapeError(
            describe(
                what,
                f"a scalar or {n} values (one per joint)",
                f"{arr.size} values",
                f"give one number or a list of length {n}",
            )
        )
    return arr


def _vector(value: ArrayLike, n: int, what: str) -> FloatArray:
    """Return ``value`` as a finite float vector of shape (n,), or raise."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,):
        raise ShapeError(
            describe(what, f"shape ({n},)", f"shape {arr.shape}", f"pass a 1-D array of {n}")
        )
    if not np.all(np.isfinite(arr)):
        raise MeasurementError(
            describe(
                what,
                "finite values",
                np.array2string(arr, precision=4),
                "the true state diverged or was not initialised; check the plant",
            )
        )
    return arr


def _positive_int(value: object, what: str, minimum: int) -> int:
    """Return ``value`` as an ``int`` if it is an integer (not a bool) >= ``minimum``."""
    if not _is_int(value) or operator.index(value) < minimum:
        raise ConfigError(
            describe(
                what,
                f"an integer >= {minimum}",
                repr(value),
                f"write a whole number >= {minimum} without quotes",
            )
        )
    return operator.index(value)
