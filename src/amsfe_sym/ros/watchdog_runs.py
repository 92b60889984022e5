"""A free-running node and its arm in process, on a simulated wall clock, with faults
injected: what the watchdogs are measured and tested on (docs/watchdogs.md,
tests/test_watchdog.py, tools/watchdog_bounds.py).

The arm (:class:`~amsfe_sym.ros.arm.SimArm`) publishes its sample k at wall clock k T and
applies, over [t_k, t_k+1], the newest command the node had computed by t_k (held, as a
forward command controller holds it), and says so on its effort topic (``sim-node``'s
applied torque, stamped t_k, with the next sample).  The node (:class:`LiveLoop`,
:meth:`~amsfe_sym.ros.live.LiveLoop.watch`) takes the samples from a KEEP_LAST queue of
``depth`` one at a time (a single server: taken = max(arrival, the previous done)), each
taking ``compute`` [s] of wall clock, and calls the watchdog's ``idle`` every ``wait`` [s]
while its queue is empty.  Nothing here reads a real clock (unless ``real_compute``): a run
is a function of the scenario, the seed and the fault.

Faults (:class:`Fault`), from ``at`` [s] on:

- ``frozen``: the encoders repeat the sample of ``at`` (a frozen driver);
- ``jump``: the encoder angles jump by ``size`` [rad] (a slipped encoder);
- ``torque_loss``: the actuators apply nothing and the arm reports it (``sim-node``'s
  ``torque_loss``: its effort topic publishes the torque applied);
- ``torque_misreported``: the actuators apply nothing while the arm reports the command (a
  drive that reports its setpoint, not its current);
- ``reversed``: the actuators apply -u while the drive reports u (a motor mounted or wired
  with the wrong sign: the drive reports its own setpoint; a diverging arm);
- ``stall``: the node is not scheduled for ``size`` [s] (its queue fills: ``depth``);
- ``lag``: the node is not scheduled for ``size`` [s], then needs ``0.99 T`` a sample (or
  ``compute`` when longer: ``compute = T`` keeps it exactly ``size`` behind), so it stays
  that far behind (a deadline burst that never catches up);
- ``silent``: the arm stops publishing (its publisher stays in the graph).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.ros.watchdog import Hold, WatchdogSeen, WatchdogTick
from amsfe_sym.ros.watchdog_reasons import Reason
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics.watchdog import WatchdogBounds

__all__ = ["FAULTS", "Fault", "FaultKind", "WatchEvent", "WatchRun", "run_watched"]

FloatArray = NDArray[np.float64]

FaultKind = Literal[
    "none",
    "frozen",
    "jump",
    "torque_loss",
    "torque_misreported",
    "reversed",
    "stall",
    "lag",
    "silent",
]
#: The faults :func:`run_watched` injects (every kind but ``none``).
FAULTS: tuple[FaultKind, ...] = tuple(k for k in get_args(FaultKind) if k != "none")


@dataclass(frozen=True)
class Fault:
    """A fault injected at ``at`` [s] (module docstring); ``size``: the jump [rad] or the
    stall [s]."""

    kind: FaultKind = "none"
    at: float = math.inf
    size: float = 0.0


@dataclass(frozen=True)
class WatchEvent:
    """One call of the watchdog: a sample (``tick``) or an idle call (``now``,
    ``publishers``), and what it returned."""

    tick: WatchdogTick | None
    now: float
    publishers: int
    reason: Reason


@dataclass
class WatchRun:
    """What a run gave.

    Attributes:
        events: Every call of the watchdog, in order (what the C twin is fed).
        hold: The hold (None: the run went to its end).
        hold_wall: Wall clock of the hold [s] (None: none).
        resumed: Wall clock at which the node could run again after a stall [s] (else the
            fault's time).
        seen: The largest watched quantities.
        true_error: Largest true link error max_j |q_j - q_d,j| after the hand-over [rad].
        ticks: Samples the arm published.
    """

    events: list[WatchEvent] = field(default_factory=list)
    hold: Hold | None = None
    hold_wall: float | None = None
    resumed: float = math.inf
    seen: WatchdogSeen = field(default_factory=WatchdogSeen)
    true_error: float = 0.0
    ticks: int = 0


def run_watched(
    sc: Scenario,
    lib: ModelLibrary,
    fault: Fault = Fault(),
    *,
    bounds: WatchdogBounds | None = None,
    compute: float = 2e-4,
    depth: int = 100,
    wait: float = 0.05,
    after_hold: float = 0.0,
    real_compute: bool = False,
) -> WatchRun:
    """Run the arm and the node (module docstring) until the scenario's end or a hold
    (``after_hold`` [s] more of the arm then, none judged).

    Args:
        sc: The scenario (its seed, duration, controller).
        lib: Its library.
        fault: What to inject.
        bounds: The watchdogs' bounds (None: the defaults).
        compute: Wall clock the node needs per sample [s].
        depth: The node's queue (KEEP_LAST) [samples].
        wait: The node's wait for a sample before it calls idle [s].
        after_hold: Keep the arm running this long after the hold [s] (not judged).
        real_compute: Each sample takes the wall clock its processing really took on this
            machine (``time.perf_counter``) instead of ``compute``: the Python node's own
            compute time and the lateness it causes (a measurement, never a test's).
    """
    T = lib.T
    T_ns = round(T * 1e9)
    arm = SimArm(sc, lib)
    loop = LiveLoop(sc, lib, controller=True, watchdog=bounds)
    assert loop.ctrl is not None
    run = WatchRun()
    n = lib.n
    queue: deque[tuple[int, float, FloatArray, list[CameraFrame], FloatArray | None]] = deque()
    free = 0.0  # the node is busy until then
    commands: deque[tuple[float, FloatArray]] = deque()  # (ready at, u)
    u_arm = np.zeros(n)
    applied_prev: FloatArray | None = None
    frozen: FloatArray | None = None
    off_start, off_len = math.inf, 0.0
    if fault.kind in ("stall", "lag"):
        off_start, off_len = fault.at, fault.size
        run.resumed = fault.at + fault.size
    elif fault.kind != "none":
        run.resumed = fault.at
    per_sample = compute
    for k in range(arm.K):
        t = k * T
        if run.hold_wall is not None and t > run.hold_wall + after_hold:
            break
        s = arm.sense()
        faulty = t >= fault.at
        z = s.z.copy()
        if faulty and fault.kind == "frozen":
            frozen = z if frozen is None else frozen
            z = frozen.copy()
        elif faulty and fault.kind == "jump":
            z[:n] += fault.size
        if not (faulty and fault.kind == "silent"):
            queue.append((k, t, z, s.frames, applied_prev))
            run.ticks += 1
            while len(queue) > depth:
                queue.popleft()  # KEEP_LAST: the oldest is lost
        # the node works until the arm's next tick
        while run.hold_wall is None:
            if not queue:  # it waits; idle calls every `wait`
                now = free + wait
                if off_start <= now < off_start + off_len:
                    now = off_start + off_len  # not scheduled
                if now >= t + T:
                    break
                free = now
                r = loop.watchdog.idle(now, 1)
                run.events.append(WatchEvent(None, now, 1, r))
                if r != Reason.NONE:
                    run.hold_wall = now
                continue
            kq, tq, zq, frames, applied = queue[0]
            taken = max(free, tq)
            if off_start <= taken < off_start + off_len:
                taken = off_start + off_len  # not scheduled
                if fault.kind == "lag":
                    per_sample = max(compute, 0.99 * T)
            if taken >= t + T:
                break  # the next tick comes first
            queue.popleft()
            if applied is not None and kq > 0:
                loop.applied((kq - 1) * T_ns, applied)
            for f in frames:
                loop.frame(f.exposure_step * T_ns, f.z)
            clock = _Clock(taken + per_sample, taken if real_compute else None)
            w = loop.watch(kq * T_ns, zq, taken=taken, clock=clock)
            done = clock.read
            free = done
            if w.tick is not None:
                run.events.append(WatchEvent(w.tick, taken, -1, w.reason))
            if w.reason != Reason.NONE:
                run.hold_wall = done
            elif w.out is not None and w.out.u is not None:
                commands.append((done, w.out.u))
                if kq == k and loop.ctrl.handed_over(kq):
                    q_d = loop.ctrl.reference(kq, kq * T)[0]
                    err = float(np.max(np.abs(s.x_true[:n] - q_d)))
                    run.true_error = max(run.true_error, err)
        if k + 1 >= arm.K:
            break
        while commands and commands[0][0] <= t + T:  # the newest command ready by t_k+1
            u_arm = commands.popleft()[1]
        u_apply = u_arm
        if faulty and fault.kind in ("torque_loss", "torque_misreported"):
            u_apply = np.zeros(n)
        elif faulty and fault.kind == "reversed":
            u_apply = -u_arm
        # a drive that reports its setpoint: the command, whatever reaches the joint
        reports_setpoint = fault.kind in ("torque_misreported", "reversed")
        applied_prev = u_arm if reports_setpoint and faulty else u_apply
        arm.advance(u_apply)
    run.hold = loop.watchdog.hold
    run.seen = loop.watchdog.seen
    return run


class _Clock:
    """The simulated wall clock at the end of a sample's processing: ``now`` [s], or, with
    ``start`` [s], ``start`` plus the real time since the clock was made."""

    def __init__(self, now: float, start: float | None = None) -> None:
        self.now, self.start, self._t0 = now, start, time.perf_counter()
        self.read = now

    def __call__(self) -> float:
        if self.start is not None:
            self.now = self.start + (time.perf_counter() - self._t0)
        self.read = self.now
        return self.now
