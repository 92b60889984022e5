"""The tick grid of a log (t_k = t0 + k T), the offset between its two clocks, and what
became of each role's messages (docs/how-to/logs.md, "Timing")."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import IntArray
from amsfe_sym.errors import LogError

__all__ = [
    "FAR_S",
    "VALUE_MAX",
    "ClockOffset",
    "ClockStep",
    "LogRateError",
    "RoleUse",
    "TickGrid",
    "clock_steps",
    "count_skip",
    "fit_t0",
    "period_digits",
]


#: An encoder stamp whose (log time - stamp) is this far from the median is skipped [s] (a
#: stamp from another clock or a corrupt one); at least 100 T and 10 x the offset's spread.
FAR_S = 1.0


#: A logged position [rad or m], velocity [rad/s] or effort [N m] beyond this is no arm's: the
#: sample is skipped and named like a far stamp (a 1e300 was fed to the filter and reported
#: later as "covariance lost"; docs/input-rules.md).
VALUE_MAX = 1e6


@dataclass(frozen=True)
class ClockStep:
    """A clock step of the header stamps: the stamps jump by ``size_s`` [s] (> 0 ahead, < 0
    back) against the recorder's clock after the sample received ``at_s`` [s] after the first
    (log time), tick ``tick`` of the log, and stay there for ``samples`` samples."""

    at_s: float
    tick: int
    size_s: float
    samples: int

    def line(self) -> str:
        """How the step is named in a message."""
        way = "ahead" if self.size_s > 0 else "back"
        return (
            f"a clock step of the header stamps {abs(self.size_s):.4g} s {way} at tick "
            f"{self.tick} (t = {self.at_s:.4f} s after the first sample), {self.samples} "
            "samples on the stepped clock"
        )


def clock_steps(
    log_ns: IntArray, stamp_ns: IntArray, T: float, max_run: int
) -> tuple[list[ClockStep], NDArray[np.bool_]]:
    """The clock steps of a stream, and its samples off the clock for at most ``max_run`` in
    a row (far or corrupt stamps, skipped like a far stamp).

    The rule (docs/input-rules.md): the offset o = log time - header stamp of each sample, in
    arrival order, is cut where it jumps by more than ``max(max_run + 1, 10) T`` and ten times
    its sample-to-sample spread.  The longest piece is the stamping clock; a piece within
    that jump of it is the same clock (a recorder's stall delays log times, never stamps); a
    piece further off is a run of bad stamps when it holds at most ``max_run`` samples, a
    clock step otherwise.

    Args:
        log_ns: Arrival times [ns], in arrival order.
        stamp_ns: Header stamps [ns], the same samples.
        T: Sampling interval [s].
        max_run: Longest run of bad stamps skipped (``[timing] max_gap_steps``).

    Returns:
        The steps (each at the first sample of a stepped piece) and the mask of bad stamps.
    """
    o = (log_ns - stamp_ns).astype(np.float64) * 1e-9
    bad = np.zeros(o.size, dtype=bool)
    if o.size < 3:
        return [], bad
    d = np.diff(o)
    mad = float(np.median(np.abs(d - np.median(d))))
    thr = max((max(max_run, 9) + 1) * T, 10 * 1.4826 * mad)
    cuts = np.flatnonzero(np.abs(d) > thr) + 1
    edges = [0, *cuts.tolist(), o.size]
    pieces = list(itertools.pairwise(edges))
    a0, b0 = max(pieces, key=lambda p: p[1] - p[0])
    ref = float(np.median(o[a0:b0]))
    steps: list[ClockStep] = []
    for a, b in pieces:
        level = float(np.median(o[a:b]))
        if abs(level - ref) <= thr:
            continue
        if b - a <= max_run:
            bad[a:b] = True
            continue
        at = (int(log_ns[a]) - int(log_ns[0])) * 1e-9
        steps.append(ClockStep(at, round(at / T), ref - level, b - a))
    return steps, bad


def period_digits(period: float, count: float) -> str:
    """``period`` [s] with the fewest significant digits (3 to 12) that keep ``count``
    periods within 0.05 of one (the grid of the rounded period still holds every stamp): the
    number a message prints and its ``--period`` fix uses (stamps 1.04 ms apart were printed
    as 0.999997 ms and the fix was refused again)."""
    for digits in range(3, 13):
        text = f"{period:.{digits}g}"
        if abs(float(text) - period) * max(count, 1.0) < 0.05 * period:
            return text
    return repr(period)


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
