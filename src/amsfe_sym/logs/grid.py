"""The tick grid of a log (t_k = t0 + k T), the offset between its two clocks, and what
became of each role's messages (docs/how-to/logs.md, "Timing")."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import LogError

__all__ = ["FAR_S", "ClockOffset", "LogRateError", "RoleUse", "TickGrid", "count_skip", "fit_t0"]

IntArray = NDArray[np.int64]

#: An encoder stamp whose (log time - stamp) is this far from the median is skipped [s] (a
#: stamp from another clock or a corrupt one); at least 100 T and 10 x the offset's spread.
FAR_S = 1.0


class LogRateError(LogError):
    """The log is sampled at another rate than the robot's T.

    Attributes:
        period: The log's period [s], to the 6 digits the message prints (the value to
            generate the robot at: ``amsfe generate ROBOT --period <period>``).
    """

    def __init__(self, message: str, period: float) -> None:
        super().__init__(message)
        self.period = period


@dataclass(frozen=True)
class ClockOffset:
    """Log time minus header stamp over the encoder samples [s]: ``median`` (the offset
    between the recorder's clock and the stamping clock, plus the transport latency) and
    ``spread`` (5 % to 95 % range)."""

    median: float
    spread: float


@dataclass
class RoleUse:
    """What became of one role's messages.

    Attributes:
        topic: Its topic (None: the log has none).
        messages: Messages on the topic.
        used: Messages that entered the estimate.
        skipped: Messages not used, by reason.
        not_used: Without a topic: the log's topics of the role's types (not used).
        notes: Counts worth a look that changed nothing (used samples identical to the
            previous one: a driver republishing its last state, or an arm at rest).
    """

    topic: str | None
    messages: int = 0
    used: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    not_used: list[str] = field(default_factory=list)
    notes: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """For ``summary.json``."""
        return {
            "topic": self.topic,
            "messages": self.messages,
            "used": self.used,
            "skipped": dict(self.skipped),
            "topics_of_this_type_not_used": list(self.not_used),
            "notes": dict(self.notes),
        }


class TickGrid:
    """Stamps -> tick indices: t_k = t0 + k T [ns, s], a stamp on tick k within ``tol`` T."""

    def __init__(self, t0_ns: int, T: float, tolerance: float) -> None:
        self.t0, self.T, self.tol = t0_ns, T, tolerance

    def steps(self, stamp_ns: IntArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Tick of each stamp and whether it is on the grid (int64; off-grid ticks kept)."""
        s = (np.asarray(stamp_ns, dtype=np.int64) - self.t0) * 1e-9 / self.T
        k = np.rint(s)
        on = np.abs(s - k) <= self.tol
        big = np.abs(k) > 2**62
        return np.where(big, -(2**62), k).astype(np.int64), on & ~big

    def arrivals(self, log_ns: IntArray) -> IntArray:
        """The first tick at or after each arrival time (within the tolerance)."""
        s = (np.asarray(log_ns, dtype=np.int64) - self.t0) * 1e-9 / self.T - self.tol
        return np.clip(np.ceil(s), -(2**62), 2**62).astype(np.int64)


def fit_t0(stamps: IntArray, T: float) -> int:
    """The grid origin [ns]: the first stamp moved to the phase of all of them (circular mean of
    the stamps modulo T), so that jitter of the first stamp does not shift the grid."""
    T_ns = T * 1e9
    rel = (stamps - stamps[0]).astype(np.float64)
    frac = (rel / T_ns) - np.rint(rel / T_ns)
    phase = float(np.angle(np.mean(np.exp(2j * np.pi * frac)))) / (2 * np.pi)
    return int(stamps[0] + round(phase * T_ns))


def count_skip(use: RoleUse, reason: str, count: int = 1) -> None:
    """Count ``count`` messages of ``use``'s role skipped for ``reason`` (none: nothing)."""
    if count > 0:
        use.skipped[reason] = use.skipped.get(reason, 0) + int(count)
