"""The ``lag`` watchdog (ros/watchdog.py check 7, docs/watchdogs.md): a node late by 20-70 ms
on every sample has no sample past ``deadline`` (50 ms), yet the arm runs on commands that
old; ``lag`` holds it by the mean lateness of the queued samples of the last
``deadline_window``, naming the node, before the arm's path leaves ``tracking_error``.

On hand-made samples (a steady 20 ms lag whose arm drifts; the same lateness in lockstep; a
50 ms stall caught up) and on the in-process free-running arm (ros/watchdog_runs.py: a node
30 ms behind, the lag at which paper-sim's loop leaves its path).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.watchdog import Reason, Watchdog, WatchdogConfig, WatchdogTick
from amsfe_sym.ros.watchdog_runs import Fault, run_watched
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.watchdog import WatchdogBounds

#: The drift of the arm's path [rad per sample]: past tracking_error (0.1) at sample 801.
DRIFT = 1.25e-4


def _config(**bounds: Any) -> WatchdogConfig:
    return WatchdogConfig(n=2, N=10, ne=4, T=1e-3, bounds=WatchdogBounds(**bounds))


def _tick(k: int, sent_s: float, taken: float, done: float) -> WatchdogTick:
    """Sample k sent at ``sent_s`` [s], its path ``DRIFT k`` from q_d on joint 2."""
    return WatchdogTick(
        k=k,
        gap=0,
        stamp_ns=round(sent_s * 1e9),
        taken=taken,
        done=done,
        x_hat=np.zeros(10),
        P_diag=np.ones(10),
        q_des=np.array([0.0, DRIFT * k]),
        u=np.zeros(2),
        handed_over=True,
        encoder_nis=4.0,
    )


def _lagging(k: int, lag: float = 0.02) -> WatchdogTick:
    """Free running: sample k sent at k ms; the first processed at once (the clock offset),
    the others ``lag`` [s] after it (each due before the previous one was done: queued, the
    arm ran on the older command)."""
    t = k * 1e-3
    lag = lag if k else 1e-4
    return _tick(k, t, t + lag - 1e-4, t + lag)


def _run(wd: Watchdog, ticks: list[WatchdogTick]) -> tuple[Reason, int]:
    """The first hold of a sequence and its sample (NONE, -1: none)."""
    for t in ticks:
        got = wd.sample(t)
        if got != Reason.NONE:
            return got, t.k
    return Reason.NONE, -1


def test_a_steady_20_ms_lag_holds_for_lag_before_tracking() -> None:
    """20 ms late on every sample (never past ``deadline``), the arm drifting off its path:
    ``lag`` holds once the window's mean lateness passes 10 ms (sample 500 of 1000), long
    before the drift reaches ``tracking_error`` (sample 801), and the line names the node;
    without the check the hold is ``tracking``, naming the arm (the late-sample rule does not
    apply: no sample is past ``deadline``)."""
    ticks = [_lagging(k) for k in range(1000)]
    wd = Watchdog(_config())
    reason, k = _run(wd, ticks)
    assert reason == Reason.LAG and 495 <= k <= 505, (reason, k)
    assert wd.hold is not None and wd.hold.bound == 0.01 and wd.hold.value > 0.01
    assert wd.line().startswith("hold: lag: this node is behind on average, not the arm: ")
    assert wd.seen.max_late_in_window == 0 and wd.seen.max_tracking < 0.1
    off = Watchdog(_config(lag=math.inf))
    assert _run(off, ticks) == (Reason.TRACKING, 801)
    # measured, not judged: samples 2-801 queued 20 ms late (the 1st was due after the 0th
    # was done), in the window of 1000
    assert off.seen.max_lag == pytest.approx(0.016, rel=1e-9)


def test_lateness_in_lockstep_or_caught_up_is_not_lag() -> None:
    """The same 20 ms per sample in lockstep (each sample sent after the previous command
    was done: never queued; the arm waited) is no lag: the drift holds for ``tracking``, the
    arm's.  A node that keeps up (0.1 ms per sample) has no lag; a 50 ms stall caught up at
    0.5 ms a sample counts, diluted in the window of 1000, far below 10 ms."""
    wd = Watchdog(_config())
    lockstep, sent = [_tick(0, 0.0, 0.0, 1e-4)], 1.1e-3
    for k in range(1, 1000):
        lockstep.append(_tick(k, sent, sent + 0.0199, sent + 0.02))
        sent += 0.021  # the arm sends the next sample 1 ms after the command came
    assert _run(wd, lockstep) == (Reason.TRACKING, 801)
    assert wd.seen.max_lag == 0.0 and wd.seen.max_lateness == pytest.approx(0.02)
    wd = Watchdog(_config(tracking_error=math.inf))
    assert _run(wd, [_lagging(k, 1e-4) for k in range(2000)]) == (Reason.NONE, -1)
    assert wd.seen.max_lag == 0.0
    wd, done, stalled = Watchdog(_config(tracking_error=math.inf)), 0.0, []
    for k in range(2000):
        taken = max(k * 1e-3, done, 0.55 if k >= 500 else 0.0)  # not scheduled 0.5-0.55 s
        done = taken + 5e-4
        stalled.append(_tick(k, k * 1e-3, taken, done))
    assert _run(wd, stalled) == (Reason.NONE, -1)
    assert 1e-3 < wd.seen.max_lag < 5e-3, wd.seen.max_lag


@pytest.mark.slow
def test_a_stall_caught_up_from_a_deep_queue_is_deadline_s() -> None:
    """A 300 ms stall of a node whose queue keeps every sample (the C node's): the samples
    it catches up are each past ``deadline``, and ``deadline`` counts them (held at the
    51st); ``lag`` counts each at most ``deadline``, so it does not trip first."""
    sc = load_scenario("paper-sim").with_overrides(duration=2.3, seed=11)
    run = run_watched(sc, library_for(sc), Fault("stall", 1.6, 0.3), depth=1000)
    assert run.hold is not None and run.hold.name == "deadline", run.hold and run.hold.line()
    assert run.hold.value == 51 and run.seen.max_lag < 0.01


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_node_30_ms_behind_holds_for_lag(seed: int) -> None:
    """In process, free running: the node not scheduled for 30 ms at 0.5 s, then just keeping
    up (0.99 T a sample: it stays about 30 ms behind, no sample past ``deadline``).  With the
    defaults it holds for ``lag`` within 0.5 s (the window's mean passes 10 ms after about
    340 samples); the arm has not left its path by then."""
    sc = load_scenario("paper-sim").with_overrides(duration=2.0, seed=seed)
    lib = library_for(sc)
    run = run_watched(sc, lib, Fault("lag", 0.5, 0.03))
    assert run.hold is not None and run.hold.name == "lag", run.hold and run.hold.line()
    assert run.hold_wall is not None and 0.0 <= run.hold_wall - run.resumed <= 0.5
    assert run.seen.max_late_in_window == 0 and run.seen.max_tracking < 0.05
