"""The watchdogs of a live node: per encoder sample, hold or go on, and why (docs/watchdogs.md).

The readable reference of ``runtime/c/amsfe_watchdog.{h,c}``: no middleware, no clock of its
own (the caller passes the wall-clock times), the same checks in the same order with the same
floating-point operations, so the two decide the same hold at the same tick
(tests/test_watchdog_c.py).  A node calls :meth:`Watchdog.sample` once per encoder sample,
after the estimator and the controller of its tick ran (or failed), before it publishes the
command, and :meth:`Watchdog.idle` when its wait for a sample timed out.  Either returns
:attr:`Reason.NONE` (go on) or the reason to hold; the node then publishes the hold command,
prints :meth:`Watchdog.line` (``hold: <name>: <cause and fix> (...)``) and exits with the hold
code.  A hold is latched.  The reasons, their causes and texts:
:mod:`amsfe_sym.ros.watchdog_reasons`.

The checks, in the order that decides which reason a sample that trips several gets:

1. ``encoder_stall`` / ``node_stalled``: more than ``max_gap_steps`` samples missing before
   this one: when this sample is late too (its lateness at the take past ``deadline``) the
   node lost them from its queue while it lagged (``node_stalled``), else the driver paused
   (``encoder_stall``);
2. ``node_stalled``: no call of the node's own loop (sample or idle) for ``encoder_timeout``
   (the node was not scheduled);
3. ``covariance``: the estimator failed (status < 0): after predicting over missing samples
   the node fell behind, else the model and the noise are inconsistent;
4. ``nonfinite``: the estimate (x_hat, diag P) or the command holds NaN or inf;
5. ``compute``: the tick's computation (taken -> done) took longer than ``compute_budget``;
6. ``deadline``: more than ``deadline_misses`` of the last ``deadline_window`` samples were
   processed later than ``deadline`` after their stamp (lateness = done - (stamp + offset),
   the offset = taken - stamp of the first sample; the stamp is the send time when known);
7. ``lag``: the node is behind on average: the sum over the last ``deadline_window``
   samples of the lateness of each sample that is late (> 0) and was queued (due before the
   previous sample's command was done: the arm ran on an older command; never in
   lockstep), at most ``deadline`` (a burst of samples past it is ``deadline``'s), divided
   by ``deadline_window`` (the others, and the samples before the first, count 0), above
   ``lag``.  A node 20-70 ms late on every sample has no sample past
   ``deadline``, but the arm runs on commands that old: paper-sim's loop leaves its path
   when its node is steadily 30 ms behind (docs/watchdogs.md);
8. ``actuation``: the torque the arm reports applying over tick j (``WatchdogTick.applied``,
   the effort topic of kind ``applied``) is none of the commands it may have applied, on
   ``actuation_ticks`` judged samples in a row (below);
9. ``innovation``: the mean of NIS / dimension over the last ``innovation_window`` fused
   updates (encoder samples and camera frames) above ``innovation_nis``;
10. ``tracking``: max_j |q_d,j - q_hat,j| above ``tracking_error``, once the start-up handed
   over (the blend of control/blend.py ended: before it the law tracks the blended
   reference, not q_d).

A node that is behind is named before what its lateness caused: when the first check that
trips is 8, 9 or 10 and the sample itself is late (its lateness past ``deadline``) and was
queued (due before the previous sample's command was done: the arm ran on meanwhile; a
lockstep arm waits for each command, so its samples never are), the hold is ``deadline``
with the cause :attr:`Cause.LATE` (value: the lateness [s]; the line ends ``; <check>
tripped``).  The arm ran on older commands while the node lagged (a stall of 300 ms: 300
ticks on one command), and the node catches its backlog up in milliseconds: the
innovations and the path of that backlog trip long before ``deadline_misses`` late samples
are counted.

Which command the arm applied (``actuation``): :mod:`amsfe_sym.ros.watchdog_actuation`.

:meth:`Watchdog.idle` holds when no sample came for ``encoder_timeout``: ``encoder_stall``
(its publisher still in the graph: the driver is silent; no publisher: it is gone).  A call
that comes after the node's own loop paused longer than ``encoder_timeout`` judges nothing:
the samples an arm sent meanwhile may not be taken yet, and the next call (50 ms later)
decides.  It used to hold ``node_stalled`` there, and named the node when the arm was
killed (tests/test_ros.py's faults test, 2 of 5 suite runs: the node's loop had paused 3.0 s
as the arm died; what paused it is not known); a node that was truly not scheduled finds
the arm's samples queued after its pause, and their lateness and gap judge it
(``deadline``, ``node_stalled`` lost, or ``node_stalled`` unscheduled at the sample).
The first sample only sets the clock offset (its compute time is
the estimator's build) and nothing is judged before it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.ros.watchdog_actuation import ACTUATION_RING, ActuationJudge
from amsfe_sym.ros.watchdog_reasons import CAUSE_TEXT, REASON_NAMES, Cause, Reason
from amsfe_sym.topics.watchdog import WatchdogBounds

__all__ = [
    "ACTUATION_RING",
    "CAUSE_TEXT",
    "REASON_NAMES",
    "Cause",
    "Hold",
    "Reason",
    "Watchdog",
    "WatchdogConfig",
    "WatchdogSeen",
    "WatchdogTick",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class WatchdogConfig:
    """The sizes of the loop and the bounds (``amsfe_watchdog_config``).

    Attributes:
        n: Joints.
        N: States of x_hat and P_diag (4n + p).
        ne: Dimension of the encoder innovation (2n; 3n with a joint torque).
        T: Tick [s].
        bounds: The ``[watchdog]`` keys.
        max_gap_steps: Missing samples the estimator predicts through (``[timing]``).
        u_max: The actuator limits [n] [N m] (inf or empty: none; the ``actuation`` scale
            is 1 N m then).
    """

    n: int
    N: int
    ne: int
    T: float
    bounds: WatchdogBounds = field(default_factory=WatchdogBounds)
    max_gap_steps: int = 5
    u_max: tuple[float, ...] = ()

    def scale(self) -> list[float]:
        """The ``actuation`` scale per joint: u_max,j, or 1 N m where it is not a finite
        number > 0."""
        u = list(self.u_max) or [math.inf] * self.n
        return [v if math.isfinite(v) and v > 0 else 1.0 for v in u]

    def check(self) -> None:
        """Refuse what the C refuses (``amsfe_watchdog_memory_size`` returns 0).

        Raises:
            ConfigError: a size < 1, T not > 0, a window < 1, a negative count or bound.
        """
        b = self.bounds
        ok = (
            min(self.n, self.N, self.ne, b.innovation_window, b.deadline_window) >= 1
            and b.actuation_ticks >= 1
            and len(self.u_max) in (0, self.n)
            and min(b.deadline_misses, self.max_gap_steps) >= 0
            and self.T > 0
            and b.tracking_error > 0
            and b.innovation_nis > 0
            and b.deadline > 0
            and b.lag > 0
            and b.compute_budget > 0
            and b.encoder_timeout > 0
            and b.actuation_error > 0
        )
        if not ok:
            raise ConfigError(
                describe("watchdog config", "sizes >= 1, T and bounds > 0", repr(self), "fix it")
            )


@dataclass(frozen=True)
class WatchdogTick:
    """One encoder sample as processed (``amsfe_watchdog_tick``).

    Attributes:
        k: Its tick.
        gap: Samples missing just before it.
        stamp_ns: When it was sent [ns]: its source timestamp (the publisher's clock: a
            lockstep arm slower than real time is then not "late"), or its header stamp
            when unknown (one kind for a whole run).
        taken: Wall clock when it was taken from the queue [s].
        done: Wall clock when its command was computed [s].
        status: The estimator's status of this tick (0, or an ``AMSFE_ERR_*`` < 0).
        x_hat: x(k|k) [N] (None: none).
        P_diag: diag P(k|k) [N] (None: none).
        q_des: q_d(t_k) [n] [rad] (None: no controller).
        u: The command [n] [N m] (None: none).
        handed_over: The start-up handed over (tracking is judged).
        encoder_nis: NIS of the encoder update fused this tick (NaN: none).
        frame_nis: NIS of each camera frame fused this tick.
        applied: The torque the arm reports applying over tick ``applied_k`` [n] [N m] (the
            effort topic of kind ``applied``: the newest by tick received since the last
            sample; None: none new, or another kind).
        applied_k: Its tick (>= 0).
    """

    k: int
    gap: int
    stamp_ns: int
    taken: float
    done: float
    status: int = 0
    x_hat: FloatArray | None = None
    P_diag: FloatArray | None = None
    q_des: FloatArray | None = None
    u: FloatArray | None = None
    handed_over: bool = False
    encoder_nis: float = math.nan
    frame_nis: tuple[float, ...] = ()
    applied: FloatArray | None = None
    applied_k: int = -1


@dataclass
class WatchdogSeen:
    """The largest value of each watched quantity so far (``amsfe_watchdog_state``'s max_*):
    how the defaults were measured.  Units: those of the keys."""

    samples: int = 0
    max_tracking: float = 0.0
    max_innovation: float = 0.0
    max_lateness: float = -math.inf
    max_late_in_window: int = 0
    max_compute: float = 0.0
    max_wall_gap: float = 0.0
    max_actuation: float = 0.0
    actuation_judged: int = 0
    max_lag: float = 0.0


@dataclass(frozen=True)
class Hold:
    """A hold: its reason and cause, the tick, the quantity that tripped and its bound.

    Attributes:
        reason: Why.
        cause: Which cause (the text).
        k: The tick of the hold (the last sample's for an idle hold).
        value: The quantity (units of the key: rad, -, s, samples).
        bound: Its bound.
        gap: Samples missing (covariance, stalls).
        caused: What the node's lateness caused, the check that tripped first (``deadline``
            with :attr:`Cause.LATE`; else NONE).
    """

    reason: Reason
    cause: Cause
    k: int
    value: float
    bound: float
    gap: int = 0
    caused: Reason = Reason.NONE

    @property
    def name(self) -> str:
        """The reason's stable name."""
        return REASON_NAMES[self.reason]

    @property
    def text(self) -> str:
        """The cause and its fix (one line)."""
        return CAUSE_TEXT[(self.reason, self.cause)]

    def line(self) -> str:
        """``hold: <name>: <text> (<value> vs <bound> at tick k)`` (the C's
        ``amsfe_watchdog_format``, character for character)."""
        caused = f"; {REASON_NAMES[self.caused]} tripped" if self.caused else ""
        return (
            f"hold: {self.name}: {self.text} ({_g(self.value)} vs bound {_g(self.bound)} "
            f"at tick {self.k}, {self.gap} missing){caused}"
        )


def _g(v: float) -> str:
    """C's ``%.6g`` (inf, nan as C prints them)."""
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return "%.6g" % v  # noqa: UP031 (C's conversion, the same digits)


class Watchdog:
    """The watchdogs of one run (module docstring).

    Args:
        config: Sizes and bounds.

    Raises:
        ConfigError: a bad config (:meth:`WatchdogConfig.check`).
    """

    def __init__(self, config: WatchdogConfig) -> None:
        config.check()
        self.config = config
        b = config.bounds
        self._nis = [0.0] * b.innovation_window
        self._late = [0] * b.deadline_window
        self._behind = [0.0] * b.deadline_window
        self._scale = config.scale()
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first sample."""
        self.hold: Hold | None = None
        self.seen = WatchdogSeen()
        self._first = True
        self._stamp0 = 0
        self._taken0 = 0.0
        self._last_call = 0.0
        self._last_taken = 0.0
        self._last_done = 0.0
        self._last_k = -1
        self._nis_sum, self._nis_pos, self._nis_count = 0.0, 0, 0
        self._late_pos, self._late_count, self._late_filled = 0, 0, 0
        self._nis[:] = [0.0] * len(self._nis)
        self._late[:] = [0] * len(self._late)
        self._behind[:] = [0.0] * len(self._behind)
        self._behind_sum = 0.0
        self._act = ActuationJudge(self.config.n, self._scale, self.config.bounds.actuation_error)

    @property
    def reason(self) -> Reason:
        """The reason held for (NONE while running)."""
        return Reason.NONE if self.hold is None else self.hold.reason

    def line(self) -> str:
        """The hold line (empty while running)."""
        return "" if self.hold is None else self.hold.line()

    def _push_nis(self, v: float) -> None:
        """One fused update's NIS / dimension into the window (a running sum: the C adds
        and subtracts the same values in the same order)."""
        old = self._nis[self._nis_pos]
        self._nis[self._nis_pos] = v
        self._nis_pos = (self._nis_pos + 1) % len(self._nis)
        if self._nis_count < len(self._nis):
            self._nis_count += 1
            self._nis_sum = self._nis_sum + v
        else:
            self._nis_sum = (self._nis_sum - old) + v

    def sample(self, tick: WatchdogTick) -> Reason:
        """Judge one processed sample: the reason to hold, or :attr:`Reason.NONE`."""
        if self.hold is not None:
            return self.hold.reason
        c, b, s = self.config, self.config.bounds, self.seen
        if self._first:  # the clock offset; nothing judged
            self._first = False
            self._stamp0, self._taken0 = tick.stamp_ns, tick.taken
            self._last_call = self._last_taken = tick.taken
            self._last_done = tick.done
            self._last_k = tick.k
            s.samples += 1
            self._act.keep(tick.k, tick.u)
            return Reason.NONE
        s.samples += 1
        rel = float(tick.stamp_ns - self._stamp0) * 1e-9
        due = self._taken0 + rel  # the wall clock the sample was due at
        wall_gap = tick.taken - self._last_call
        s.max_wall_gap = max(s.max_wall_gap, wall_gap)
        self._last_call = self._last_taken = tick.taken
        self._last_k = tick.k
        trips: list[Hold] = []
        k, gap = tick.k, tick.gap
        if gap > c.max_gap_steps:  # 1: a stall seen at the next sample
            late_at_take = tick.taken - due
            cause = Cause.LOST if late_at_take > b.deadline else Cause.GAP
            reason = Reason.NODE_STALLED if cause == Cause.LOST else Reason.ENCODER_STALL
            trips.append(Hold(reason, cause, k, float(gap), float(c.max_gap_steps), gap))
        if wall_gap > b.encoder_timeout:  # 2
            trips.append(
                Hold(Reason.NODE_STALLED, Cause.UNSCHEDULED, k, wall_gap, b.encoder_timeout, gap)
            )
        if tick.status < 0:  # 3
            cause = Cause.BEHIND if gap > 0 else Cause.INCONSISTENT
            trips.append(Hold(Reason.COVARIANCE, cause, k, float(tick.status), 0.0, gap))
        if _nonfinite(tick.x_hat) or _nonfinite(tick.P_diag):  # 4
            trips.append(Hold(Reason.NONFINITE, Cause.ESTIMATE, k, math.nan, 0.0, gap))
        elif _nonfinite(tick.u):
            trips.append(Hold(Reason.NONFINITE, Cause.COMMAND, k, math.nan, 0.0, gap))
        compute = tick.done - tick.taken  # 5
        s.max_compute = max(s.max_compute, compute)
        if compute > b.compute_budget:
            trips.append(Hold(Reason.COMPUTE, Cause.NONE, k, compute, b.compute_budget, gap))
        # queued: due before the previous sample's command was done (the arm ran on an
        # older command; never in lockstep: that arm sends a sample after the command came)
        queued = due < self._last_done
        self._last_done = tick.done
        lateness = tick.done - due  # 6
        s.max_lateness = max(s.max_lateness, lateness)
        late = 1 if lateness > b.deadline else 0
        pos = self._late_pos
        self._late_count += late - self._late[pos]
        self._late[pos] = late
        self._late_pos = (pos + 1) % len(self._late)
        s.max_late_in_window = max(s.max_late_in_window, self._late_count)
        if self._late_count > b.deadline_misses:
            misses = float(self._late_count)
            trips.append(
                Hold(Reason.DEADLINE, Cause.NONE, k, misses, float(b.deadline_misses), gap)
            )
        # 7: a sample past deadline counts deadline (a burst of them is deadline's to count)
        behind = 0.0
        if queued and lateness > 0.0:
            behind = lateness if lateness < b.deadline else b.deadline
        self._behind_sum = (self._behind_sum - self._behind[pos]) + behind
        self._behind[pos] = behind
        lag = self._behind_sum / len(self._behind)
        s.max_lag = max(s.max_lag, lag)
        if lag > b.lag:
            trips.append(Hold(Reason.LAG, Cause.NONE, k, lag, b.lag, gap))
        mismatch = self._act.judge(tick.k, tick.u, tick.applied, tick.applied_k)  # 8
        s.actuation_judged, s.max_actuation = self._act.judged, self._act.max_distance
        if mismatch is not None and self._act.run >= b.actuation_ticks:
            trips.append(Hold(Reason.ACTUATION, Cause.NONE, k, mismatch, b.actuation_error, gap))
        self._act.keep(tick.k, tick.u)
        if math.isfinite(tick.encoder_nis):  # 9
            self._push_nis(tick.encoder_nis / c.ne)
        for v in tick.frame_nis:
            if math.isfinite(v):
                self._push_nis(v / 2.0)
        if self._nis_count == len(self._nis):
            mean = self._nis_sum / len(self._nis)
            s.max_innovation = max(s.max_innovation, mean)
            if mean > b.innovation_nis:
                trips.append(Hold(Reason.INNOVATION, Cause.NONE, k, mean, b.innovation_nis, gap))
        if tick.handed_over and tick.q_des is not None and tick.x_hat is not None:  # 10
            err = _max_abs_diff(tick.q_des, tick.x_hat[: c.n])
            s.max_tracking = max(s.max_tracking, err)
            if err > b.tracking_error:
                trips.append(Hold(Reason.TRACKING, Cause.NONE, k, err, b.tracking_error, gap))
        # 11: behind first: a late sample that was due before the previous one was done
        # waited in the queue while the arm ran on (never in lockstep: the arm waits)
        if trips and late and queued and trips[0].reason in _CAUSED_BY_LATENESS:
            first = trips[0].reason
            trips[0] = Hold(Reason.DEADLINE, Cause.LATE, k, lateness, b.deadline, gap, first)
        if trips:
            self.hold = trips[0]
            return self.hold.reason
        return Reason.NONE

    def idle(self, now: float, publishers: int = -1) -> Reason:
        """The wait for a sample timed out at wall clock ``now`` [s]; ``publishers``: the
        encoder topic's publisher count (-1: unknown).  The reason to hold, or NONE."""
        if self.hold is not None:
            return self.hold.reason
        if self._first:
            return Reason.NONE
        b, s = self.config.bounds, self.seen
        wall_gap = now - self._last_call
        s.max_wall_gap = max(s.max_wall_gap, wall_gap)
        self._last_call = now
        silence = now - self._last_taken
        if wall_gap > b.encoder_timeout:
            # the node's own loop paused (a write to a peer that died blocked it, or it had
            # no CPU): what an arm sent meanwhile may not be taken yet, so the silence is
            # judged at the next call; a live arm's samples then come (a sample after the
            # pause is judged by its gap and lateness), a dead one's do not
            return self.reason
        if silence > b.encoder_timeout:
            cause = Cause.GONE if publishers == 0 else Cause.SILENT
            self.hold = Hold(Reason.ENCODER_STALL, cause, self._last_k, silence, b.encoder_timeout)
        return self.reason

    def idle_counting(self, now: float, publishers: Callable[[], int]) -> Reason:
        """:meth:`idle`, the encoders' publishers counted (``publishers()``, a graph query)
        only when the silence since the last sample is past ``encoder_timeout``."""
        timeout = self.config.bounds.encoder_timeout
        silent = not self._first and now - self._last_taken > timeout
        return self.idle(now, publishers() if silent and self.hold is None else -1)


#: What a node that is behind causes: the arm runs on older commands meanwhile, so its
#: torque, its innovations and its path can leave their bounds; on a late sample the hold
#: names the lateness (``deadline``, :attr:`Cause.LATE`), not the arm.
_CAUSED_BY_LATENESS = (Reason.ACTUATION, Reason.INNOVATION, Reason.TRACKING)


def _nonfinite(v: FloatArray | None) -> bool:
    return v is not None and not bool(np.isfinite(v).all())


def _max_abs_diff(a: FloatArray, b: FloatArray) -> float:
    """max_j |a_j - b_j| (NaN: NaN; the C's loop gives the same)."""
    d = np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))
    return float(np.max(d))
