"""The ``actuation`` watchdog's judge: which of the node's commands the arm applied
(docs/watchdogs.md; :mod:`amsfe_sym.ros.watchdog`, check 7; the C's
``amsfe_watchdog.c``, the same operations in the same order).

A command reaches the arm late, or not at
all, in free running: the arm then applies the newest one it has (an older one), or holds
zero before the first; what it applied over tick j is one of the node's commands of ticks
<= j, and never an older one than it applied before (one publisher, in order).  So the
watchdog keeps the commands of the last :data:`ACTUATION_RING` ticks (each sample's ``u``)
and the command the arm was last seen applying (zero before the first match); the
candidates for the torque a reported over tick j are that one and the kept commands after
it up to tick j.  The distance of a candidate c is max_j |a_j - c_j| / s_j, s_j the joint's
actuator limit u_max,j (1 N m without one).  The nearest candidate (the oldest of equals)
within ``actuation_error`` is the command applied (it becomes the last seen); none within:
a mismatch, its value the smallest distance.  A hold after ``actuation_ticks`` mismatches in
a row.  Judged only when the sample has a command
(the node publishes commands) and a reported torque (new since the last sample, finite), and
the candidates are those kept: a command more than :data:`ACTUATION_RING` ticks older than
the node's newest is not one the arm may still apply (the node itself is then that far
behind, which the ``deadline`` check holds long before).  The search is short: the last
seen command follows the arm, so the candidates are the commands still on their way to it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from amsfe_sym.arrays import FloatArray

__all__ = ["ACTUATION_RING", "ActuationJudge"]

#: Ticks of commands the ``actuation`` check keeps (``AMSFE_WD_ACTUATION_RING``).
ACTUATION_RING = 1024


class ActuationJudge:
    """The commands kept and the one last seen applied (module docstring).

    Args:
        n: Joints.
        scale: Per joint, the distance's scale s_j (its actuator limit [N m], 1 without).
        bound: ``actuation_error``: the largest distance of a command applied [-].

    Attributes:
        run: Mismatches in a row (0 after a match).
        judged: Samples judged.
        max_distance: The largest smallest-distance judged so far [-].
    """

    def __init__(self, n: int, scale: Sequence[float], bound: float) -> None:
        self.n, self._scale, self._bound = n, list(scale), bound
        self._ring_k = [-1] * ACTUATION_RING  # the tick of each kept command, by k % RING
        self._ring_u: list[list[float]] = [[0.0] * n] * ACTUATION_RING
        self._cmd_newest = -1
        self._matched = [0.0] * n  # the command last seen applied (zero first)
        self._matched_k = -1
        self.run = 0
        self.judged = 0
        self.max_distance = 0.0

    def keep(self, k: int, u: FloatArray | Sequence[float] | None) -> None:
        """The command of tick ``k`` into the ring (none: nothing)."""
        if u is None or k < 0:
            return
        slot = k % ACTUATION_RING
        self._ring_k[slot] = k
        self._ring_u[slot] = [float(v) for v in u]
        self._cmd_newest = max(self._cmd_newest, k)

    def _distance(self, a: list[float], c: list[float]) -> float:
        """max_j |a_j - c_j| / s_j (the C's loop: the first joint, then larger ones)."""
        d = abs(a[0] - c[0]) / self._scale[0]
        for j in range(1, self.n):
            dj = abs(a[j] - c[j]) / self._scale[j]
            if dj > d:
                d = dj
        return d

    def judge(
        self,
        k: int,
        u: FloatArray | Sequence[float] | None,
        applied: FloatArray | Sequence[float] | None,
        applied_k: int,
    ) -> float | None:
        """Judge the torque ``applied`` the arm reports over tick ``applied_k``, at the sample
        of tick ``k`` with command ``u``: None when not judged or matched (the run of
        mismatches reset), else the mismatch (the smallest distance; the run counted)."""
        if u is None or applied is None or applied_k < 0:
            return None
        a = [float(v) for v in applied]
        if len(a) != self.n or not all(math.isfinite(v) for v in a):
            return None
        newest = self._cmd_newest
        self.judged += 1
        last = min(applied_k, newest)
        best, best_k, best_c = self._distance(a, self._matched), self._matched_k, self._matched
        i = max(self._matched_k + 1, newest - ACTUATION_RING + 1)
        while i <= last:
            slot = i % ACTUATION_RING
            if self._ring_k[slot] == i:
                d = self._distance(a, self._ring_u[slot])
                if d < best:
                    best, best_k, best_c = d, i, self._ring_u[slot]
            i += 1
        self.max_distance = max(self.max_distance, best)
        if best <= self._bound:  # the command applied: the nearest (the oldest of equals)
            self._matched, self._matched_k = best_c, best_k
            self.run = 0
            return None
        self.run += 1
        return best
