"""Typed values of the configuration files: one reader for robot.toml and the scenario files,
so both refuse the same things: no ``float()`` of a string or a boolean, finite
numbers everywhere, integers that must be integers, and counts bounded by what a C ``int``
of the runtime's parameter blocks holds (no silent narrowing).

Each function raises the error class it is given (``SpecError`` for robot.toml,
``ConfigError`` for scenarios) with one line: where, expected, found (with its type), fix.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from amsfe_sym.errors import AmsfeError, describe

__all__ = [
    "BACKWARD_MAPS",
    "BUFFER_STEPS_MAX",
    "C_INT_MAX",
    "EFFORT_KINDS",
    "NOISE_STD_MAX",
    "PERIOD_MAX",
    "PERIOD_MIN",
    "SEED_MAX",
    "SUBSTEPS_MAX",
    "EffortKind",
    "is_number",
    "read_in_range",
    "read_int",
    "read_number",
    "read_seed",
    "require_positive",
]

#: The values of ``[filter] backward_map`` / ``FilterConfig.backward_map`` (``oosm``'s
#: backward map of eq. (24)), in the order of the C runtime's codes
#: (``amsfe_params.backward_map``: 0 linearised, 1 inverse).
BACKWARD_MAPS = ("linearised", "inverse")

#: What a log's or a live topic's effort is (docs/reference/topics.md, docs/explanation/effort.md):
#: ``applied``
#: the motor torque u applied over [t_k, t_k+1] (the input of F, eq. (1b)); ``joint_torque``
#: the measured joint (spring) torque Ks (qm - q) of torque-sensing arms (Franka, KUKA iiwa),
#: a measurement of the state, u unknown; ``none`` encoders only, u unknown.
EffortKind = Literal["applied", "joint_torque", "none"]
EFFORT_KINDS: tuple[EffortKind, ...] = ("applied", "joint_torque", "none")

#: The largest C ``int`` (the runtime's parameter blocks hold counts as ``int``).
C_INT_MAX = 2**31 - 1

#: The largest seed: TOML's largest integer (a signed 64-bit one), so the ``config.toml``
#: of every run re-runs (``amsfe simulate RUN/config.toml``) and any TOML reader reads it.
SEED_MAX = 2**63 - 1

#: The sampling intervals a robot is generated at [s] (docs/input-rules.md): 1 us (1 MHz,
#: beyond any joint bus) to 10 s.  A shorter one made a library named ``T0pus`` for every
#: period below 0.5 ns and 1e-320 overflowed the camera's steps; a longer one asks for
#: more rk4 substeps than :data:`SUBSTEPS_MAX` for every arm shipped.
PERIOD_MIN = 1e-6
PERIOD_MAX = 10.0

#: The most rk4 steps per T (``model_substeps``, ``plant_substeps``, ``inverse_iterations``):
#: each is unrolled in the generated graph, so 10^10 of them never finished; the
#: Panda at 30 Hz, the most any shipped log needs, takes 62.
SUBSTEPS_MAX = 256

#: The largest noise standard deviation any key takes (R and Q in their units: rad, rad/s,
#: px, N m): its square stays far from overflow (1e300 squared is inf) and from swamping
#: every other term of a covariance in double precision.
NOISE_STD_MAX = 1e6

#: The most history steps a filter keeps for late frames (``buffer_steps``) and the deepest
#: QoS history (``[qos] depth``): 100 s at 1 kHz; 2e9 asked for 2 TiB.
BUFFER_STEPS_MAX = 100_000


def is_number(x: object) -> bool:
    """A TOML number (int or float), not a boolean."""
    return isinstance(x, int | float) and not isinstance(x, bool)


def _found(x: object) -> str:
    kind = "a string" if isinstance(x, str) else type(x).__name__
    return f"{x!r} ({kind})"


def read_number(
    x: Any,
    where: str,
    error: type[AmsfeError],
    low: float | None = None,
    strict: bool = False,
) -> float:
    """``x`` as a finite float (``>= low``, or ``> low`` when ``strict``).

    Raises:
        error: not a number (strings and booleans are not numbers), not finite, or too low.
    """
    if not is_number(x):
        raise error(describe(where, "a number", _found(x), "write a number without quotes"))
    v = float(x)
    if not math.isfinite(v):
        raise error(describe(where, "a finite number", repr(x), "write a finite number"))
    if low is not None and (v <= low if strict else v < low):
        bound = f"{'>' if strict else '>='} {low:g}"
        expected = "a positive number" if strict and low == 0 else f"a number {bound}"
        raise error(describe(where, expected, repr(x), f"use a value {bound}"))
    return v


def require_positive(
    v: float, where: str, expected: str, fix: str, error: type[AmsfeError]
) -> float:
    """``v`` when it is finite and > 0; else ``error`` saying ``where``, ``expected`` (with
    its unit, e.g. "a positive sample time [s]"), the value found and ``fix``."""
    if not (math.isfinite(v) and v > 0):
        raise error(describe(where, expected, repr(v), fix))
    return v


def read_in_range(
    x: Any, where: str, error: type[AmsfeError], low: float, high: float, fix: str = ""
) -> float:
    """``x`` as a finite float in ``[low, high]`` (docs/input-rules.md: every number a
    command takes is bounded before any work starts).

    Raises:
        error: not a number, not finite, or outside the range (the range in the message).
    """
    v = read_number(x, where, error)
    if not low <= v <= high:
        raise error(
            describe(
                where,
                f"a number in [{low:g}, {high:g}]",
                repr(x),
                fix or f"use a value from {low:g} to {high:g}",
            )
        )
    return v


def read_int(x: Any, where: str, error: type[AmsfeError], low: int, high: int = C_INT_MAX) -> int:
    """``x`` as an integer in ``[low, high]`` (a float is refused, even 2.0: counts are
    written as whole numbers; ``high`` defaults to the largest C ``int``).

    Raises:
        error: not an integer, or out of range.
    """
    if isinstance(x, bool) or not isinstance(x, int):
        key = where.rsplit(" ", 1)[-1]
        whole = isinstance(x, float) and x.is_integer()
        fix = f"write {key} = {int(x)}" if whole else f"write a whole number, e.g. {key} = 1"
        raise error(describe(where, "an integer", _found(x), fix))
    if not low <= x <= high:
        raise error(
            describe(
                where, f"an integer in [{low}, {high}]", repr(x), "write a value in that range"
            )
        )
    return x


def read_seed(x: Any, where: str, error: type[AmsfeError]) -> int:
    """A seed: an integer in ``[0, SEED_MAX]`` (the one rule of the command line's
    ``--seed`` and of the scenario files' ``seed``).

    Raises:
        error: not an integer, or out of range.
    """
    if isinstance(x, int) and not isinstance(x, bool) and not 0 <= x <= SEED_MAX:
        raise error(
            describe(
                where,
                f"an integer >= 0 and <= {SEED_MAX} (2^63 - 1, TOML's largest integer)",
                repr(x),
                "write a seed in that range, e.g. seed = 0",
            )
        )
    return read_int(x, where, error, 0, SEED_MAX)
