"""How an ``amsfe node`` run stops (:mod:`amsfe_sym.ros.node`): why (:class:`Stop`), the
exit code of a fail-safe hold (:data:`EXIT_HOLD`), how the run ended (:class:`NodeReport`),
and the lines the node says as it stops.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import AmsfeError

__all__ = ["EXIT_HOLD", "NodeReport", "Stop", "held_line", "latency_line"]

FloatArray = NDArray[np.float64]

#: Exit code of a fail-safe stop (a watchdog tripped: docs/watchdogs.md).
EXIT_HOLD = 3


@dataclass(frozen=True)
class NodeReport:
    """How a node run ended.

    Attributes:
        ticks: Encoder samples processed.
        reason: Why it stopped (one line).
        exit_code: 0 (duration reached, shutdown) or :data:`EXIT_HOLD`.
        hold: The hold command published [N m] (None: none was).
        counters: The estimator's decisions and the skipped messages by reason.
        record: The record written (None: none).
    """

    ticks: int
    reason: str
    exit_code: int
    hold: FloatArray | None
    counters: dict[str, int]
    record: Path | None


@dataclass(frozen=True)
class Stop:
    """Why the node stops: one line, the exit code, the error to raise (bad input), the
    watchdog's reason name (``tracking``, ...)."""

    reason: str
    code: int
    error: AmsfeError | None = None
    watchdog: str | None = None


def latency_line(lat: FloatArray) -> str:
    """The node's latency line (``amsfe bench --ros`` reads it): sample received by the
    middleware -> command published, p50 / p99 / max [ms] over the run's commands."""
    p50, p99 = np.percentile(lat, [50, 99]) * 1e3
    return (
        f"node: latency sample received -> command published p50 {p50:.3f} p99 {p99:.3f} "
        f"max {lat.max() * 1e3:.3f} ms over {lat.size} commands"
    )


def held_line(hold: FloatArray | None) -> str:
    """What a node's last line adds for the hold command it published ('': none was)."""
    if hold is None:
        return ""
    return f"; hold command {[round(float(v), 6) for v in hold]} N m published"
