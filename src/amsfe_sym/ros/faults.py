"""Faults of the simulated arm (``amsfe sim-node --fault KIND@T[=VALUE]``): what a broken
encoder or a lost drive does to a run, at a stated time, for the watchdogs of ``amsfe node``
to catch (docs/live-load.md).  No middleware here: :class:`FaultPlan` changes the samples the
arm sends and the torque it applies, tick by tick.

Kinds (from the tick ``k_f = round(T_f / T)`` on, to the end of the run):

- ``encoder_frozen``: every encoder sample repeats the one of tick ``k_f`` (motor angles and
  rates stuck; stamps still advance: a driver sending a stale value);
- ``encoder_jump=VALUE``: every motor angle reads ``VALUE`` rad more than it is (a slipped or
  miscounted encoder: a step offset that stays);
- ``torque_loss``: the commands are ignored and zero torque is applied (a drive that lost
  power); the effort topic says so (it publishes what was applied).

The random streams are not touched (the sensors still draw their noise at every tick), so a
seed and a fault give the same run every time, and the ticks before ``k_f`` are those of the
run without the fault.  A stall of the node is not a fault of the arm: the harness stops the
node's process (SIGSTOP / SIGCONT; tests/test_live_load.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe

__all__ = ["FAULT_KINDS", "Fault", "FaultKind", "FaultPlan", "parse_fault"]

FloatArray = NDArray[np.float64]

FaultKind = Literal["encoder_frozen", "encoder_jump", "torque_loss"]

#: The kinds of :data:`FaultKind`, in the order the docs list them.
FAULT_KINDS: tuple[str, ...] = get_args(FaultKind)

#: The largest encoder jump accepted [rad].
MAX_JUMP = 100.0


@dataclass(frozen=True)
class Fault:
    """One fault of the simulated arm.

    Attributes:
        kind: What breaks (module docstring).
        t: When it starts [s of the run's time, >= 0].
        value: ``encoder_jump``: the offset of every motor angle [rad]; else 0.
    """

    kind: FaultKind
    t: float
    value: float = 0.0

    def label(self) -> str:
        """``kind@t[=value]``, as the option is written."""
        v = f"={self.value:g}" if self.kind == "encoder_jump" else ""
        return f"{self.kind}@{self.t:g}{v}"


def parse_fault(text: str) -> Fault:
    """A fault from ``KIND@T[=VALUE]`` (``encoder_frozen@1.0``, ``encoder_jump@1.0=0.5``,
    ``torque_loss@1.5``).

    Raises:
        ConfigError: an unknown kind, a time that is not a finite number >= 0, a value where
            none is taken or a jump without one / outside +-:data:`MAX_JUMP` rad.
    """
    example = "e.g. --fault encoder_jump@1.0=0.5 (kinds: " + ", ".join(FAULT_KINDS) + ")"
    kind, at, rest = text.partition("@")
    if kind not in FAULT_KINDS or not at:
        raise ConfigError(
            describe("--fault", "KIND@T[=VALUE] with a known KIND", repr(text), example)
        )
    t_text, eq, v_text = rest.partition("=")
    try:
        t = float(t_text)
        value = float(v_text) if eq else math.nan
    except ValueError:
        t, value = math.nan, math.nan
        eq = eq or "bad"
    if not math.isfinite(t) or t < 0:
        raise ConfigError(describe(f"--fault {text}", "a time T >= 0 [s]", repr(t_text), example))
    if kind == "encoder_jump":
        if not eq or not math.isfinite(value) or not 0 < abs(value) <= MAX_JUMP:
            raise ConfigError(
                describe(
                    f"--fault {text}",
                    f"an offset VALUE [rad], 0 < |VALUE| <= {MAX_JUMP:g}",
                    repr(v_text) if eq else "none",
                    "e.g. --fault encoder_jump@1.0=0.5",
                )
            )
        return Fault("encoder_jump", t, value)
    if eq:
        raise ConfigError(
            describe(f"--fault {text}", f"no value for {kind}", repr(v_text), f"{kind}@{t_text}")
        )
    return Fault(kind, t)  # type: ignore[arg-type]


class FaultPlan:
    """The faults of one run, applied tick by tick.

    Args:
        faults: The faults (several may overlap; one of each kind).
        T: The tick period [s].
        n: Joints.

    Raises:
        ConfigError: the same kind twice.
    """

    def __init__(self, faults: tuple[Fault, ...], T: float, n: int) -> None:
        kinds = [f.kind for f in faults]
        if len(set(kinds)) != len(kinds):
            raise ConfigError(
                describe("--fault", "each kind at most once", ", ".join(kinds), "give it once")
            )
        self.n = n
        self.start = {f.kind: round(f.t / T) for f in faults}
        self.jump = next((f.value for f in faults if f.kind == "encoder_jump"), 0.0)
        self._frozen: FloatArray | None = None

    def started(self, k: int) -> list[str]:
        """The kinds that start at tick ``k``."""
        return [kind for kind, k0 in self.start.items() if k0 == k]

    def _on(self, kind: str, k: int) -> bool:
        return kind in self.start and k >= self.start[kind]

    def encoders(self, k: int, z: FloatArray) -> FloatArray:
        """The sample [qm, qmd] the arm sends at tick ``k`` for the true sample ``z``."""
        if self._on("encoder_frozen", k):
            if self._frozen is None:
                self._frozen = np.array(z, dtype=float)
            z = self._frozen.copy()
        if self._on("encoder_jump", k):
            z = np.array(z, dtype=float)
            z[: self.n] += self.jump
        return z

    def torque(self, k: int, u: FloatArray) -> FloatArray:
        """The torque the arm applies over tick ``k`` for the command ``u`` [N m]."""
        return np.zeros(self.n) if self._on("torque_loss", k) else u
