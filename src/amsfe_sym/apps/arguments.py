"""The command line's argument types: each accepts a valid value or says, in one line, what
it expected, what it found and how to fix it (argparse then exits 2)."""

from __future__ import annotations

import argparse
import dataclasses
import math
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

from amsfe_sym.core.values import SEED_MAX
from amsfe_sym.errors import describe

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "COUNT",
    "DURATION",
    "JOINT_RANGE",
    "SAMPLES",
    "SEED",
    "Parser",
    "lock_arg",
    "number_type",
    "options_from_args",
]

Options = TypeVar("Options", bound="DataclassInstance")


def lock_arg(text: str) -> tuple[str, float]:
    """``--lock JOINT`` or ``JOINT=VALUE`` (a finite angle [rad] or position [m])."""
    name, _, value = text.partition("=")
    try:
        v = float(value) if value else 0.0
    except ValueError:
        v = math.nan
    if not name or not math.isfinite(v):
        raise argparse.ArgumentTypeError(
            f"--lock {text!r}: expected JOINT or JOINT=VALUE with a finite value, "
            f"e.g. --lock {name or 'joint2'}=0.1"
        )
    return name, v


def number_type(kind: type, low: float, inclusive: bool, fix: str, high: int | None = None) -> Any:
    """An argparse ``type=`` that accepts a finite ``kind`` >= ``low`` (> when not inclusive)
    and <= ``high`` (if given), and otherwise says, in one line, what it expected, what it
    found and how to fix it."""
    bound = f"{'>=' if inclusive else '>'} {low:g}"
    if high is not None:
        bound += f" and <= {high}"
    expected = f"{'an integer' if kind is int else 'a finite number'} {bound}"

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            value = None
        ok = value is not None and math.isfinite(value)
        if (
            not ok
            or (value < low if inclusive else value <= low)
            or (high is not None and value > high)
        ):
            raise argparse.ArgumentTypeError(
                describe("value", expected, repr(text), fix).removeprefix("value: ")
            )
        return value

    parse.__name__ = kind.__name__  # argparse names the type in its own messages
    return parse


#: The seed rule of :func:`amsfe_sym.core.values.read_seed`: 0 .. 2^63 - 1.
SEED = number_type(int, 0, True, "pass a seed in that range, e.g. --seed 0", high=SEED_MAX)
COUNT = number_type(int, 1, True, "pass a count >= 1")
SAMPLES = number_type(int, 1, True, "pass --samples 50 (a check over no state cannot fail)")
DURATION = number_type(float, 0.0, False, "pass a simulated time in seconds, e.g. --duration 2")


def JOINT_RANGE(text: str) -> tuple[int, ...]:
    """``A-B`` (or one number) -> the chain lengths A..B of ``amsfe bench --joints``."""
    lo, _, hi = text.partition("-")
    try:
        a, b = int(lo), int(hi or lo)
    except ValueError:
        a, b = 0, -1
    if not 1 <= a <= b <= 40:
        raise argparse.ArgumentTypeError(
            f"expected A-B with 1 <= A <= B <= 40, found {text!r}; pass e.g. --joints 1-12"
        )
    return tuple(range(a, b + 1))


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``error: amsfe simulate: argument --seed: ...``, exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {self.prog}: {message} (see {self.prog} -h)\n")


def options_from_args(cls: type[Options], args: argparse.Namespace, **given: Any) -> Options:
    """A command's options (the dataclass ``cls``) from its parsed ``args``: each field is
    the option of its name, but for the ``given`` ones (an option that needs converting, or
    a field no option sets).  A field with neither is an AttributeError (a parser and its
    options out of step, a bug, not bad input)."""
    taken = {f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if f.name not in given}
    return cls(**taken, **given)
