"""The watchdogs of the live node (ros/watchdog.py, docs/watchdogs.md), in process: the node's
LiveLoop and the simulated arm free running on a simulated wall clock
(ros/watchdog_runs.py), so nothing here depends on this machine's speed or load.

- each injected fault ends in a hold for its own reason within 100 ms (of the fault, or of the
  node running again after its own stall; the encoders' silence: the encoder timeout), on
  several seeds, and the hold line names it; a torque loss the arm reports: ``actuation``
  in both scenarios;
- clean runs of the shipped scenarios never hold with the defaults (seeds disjoint from the
  ones the defaults were measured on: tools/watchdog_bounds.py);
- the [watchdog] keys: parsed, refused when bad, overridable;
- the checks one by one on hand-made calls (their order, the causes, the latch).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.watchdog import (
    Cause,
    Reason,
    Watchdog,
    WatchdogConfig,
    WatchdogTick,
)
from amsfe_sym.ros.watchdog_runs import Fault, run_watched
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.spec import parse_topic_spec
from amsfe_sym.topics.watchdog import WatchdogBounds

#: fault -> (its size, the reason it must hold for)
EXPECTED = {
    "frozen": (0.0, "innovation"),
    "jump": (0.01, "innovation"),
    "torque_loss": (0.0, "actuation"),
    "torque_misreported": (0.0, "innovation"),
    "reversed": (0.0, "innovation"),
    "stall": (0.3, "node_stalled"),
    "lag": (0.08, "deadline"),
    "silent": (0.0, "encoder_stall"),
}
FAULT_AT = 1.6  # [s] after paper-sim's start-up handed over


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=FAULT_AT + 0.7)
    return sc, library_for(sc)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
@pytest.mark.parametrize("kind", list(EXPECTED))
def test_each_fault_holds_for_its_reason(paper: Any, kind: str, seed: int) -> None:
    sc, lib = paper
    size, reason = EXPECTED[kind]
    run = run_watched(sc.with_overrides(seed=seed), lib, Fault(kind, FAULT_AT, size))  # type: ignore[arg-type]
    assert run.hold is not None, (kind, seed, run.seen)
    assert run.hold.name == reason, run.hold.line()
    assert run.hold.line().startswith(f"hold: {reason}: ")
    assert run.hold_wall is not None
    delay = run.hold_wall - run.resumed
    if kind == "silent":  # by definition: the encoder timeout, plus one wait of the node
        timeout = WatchdogBounds().encoder_timeout
        assert timeout - lib.T < delay <= timeout + 0.05 + lib.T, delay
    else:
        assert 0.0 <= delay <= 0.1, (kind, seed, delay, run.hold.line())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "seeds"), [("paper-sim", (21, 22, 23)), ("panda-control", (21, 22))]
)
def test_torque_loss_holds_for_actuation(name: str, seeds: tuple[int, ...]) -> None:
    """A torque loss the arm reports (the effort topic says zero) holds with ``actuation``
    within 100 ms of simulated time, in both scenarios, several seeds; commands that reach the
    arm late (a 30 ms stall of the node: the arm applies older ones) hold nothing."""
    at = 1.6 if name == "paper-sim" else 1.2
    sc0 = load_scenario(name).with_overrides(duration=at + 0.4)
    lib = library_for(sc0)
    for seed in seeds:
        sc = sc0.with_overrides(seed=seed)
        run = run_watched(sc, lib, Fault("torque_loss", at))
        assert run.hold is not None and run.hold.name == "actuation", (seed, run.seen)
        assert run.hold.line().startswith("hold: actuation: the arm does not apply the command")
        assert run.hold_wall is not None and 0.0 <= run.hold_wall - at <= 0.1
        assert run.hold.value > run.hold.bound == WatchdogBounds().actuation_error
        # the node not scheduled for 30 ms: the arm applies old commands (up to ~30 ticks
        # late) while the node catches up; none of them is a mismatch, nothing holds
        late = run_watched(sc, lib, Fault("stall", at, 0.03))
        assert late.hold is None, late.hold.line()
        assert late.seen.max_actuation == 0.0 and late.seen.actuation_judged > 0


@pytest.mark.slow
def test_a_report_too_late_for_the_estimator_is_judged(paper: Any) -> None:
    """The arm's applied torque of tick k-1 reaching the node after it estimated tick k (DDS
    does not order two topics): the estimator skips it (counted), the watchdog still judges
    it at the next sample; a torque loss is then held for ``actuation`` 6 ticks after it (the
    loss's first report judged a tick later)."""
    from amsfe_sym.ros.arm import SimArm
    from amsfe_sym.ros.faults import Fault as ArmFault
    from amsfe_sym.ros.faults import FaultPlan
    from amsfe_sym.ros.live import LiveLoop

    sc, lib = paper
    sc = sc.with_overrides(seed=4)
    # innovation off: the estimator, given its own command for the late ticks, would see the
    # loss too (a tick before actuation's fifth mismatch)
    bounds = WatchdogBounds(innovation_nis=math.inf)
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True, watchdog=bounds)
    plan = FaultPlan((ArmFault("torque_loss", FAULT_AT),), lib.T, lib.n)
    T_ns, k_f = round(lib.T * 1e9), round(FAULT_AT / lib.T)
    prev = np.zeros(lib.n)
    for k in range(arm.K):
        s = arm.sense()
        for f in s.frames:
            loop.frame(f.exposure_step * T_ns, f.z)
        t = k * lib.T
        w = loop.watch(k * T_ns, s.z, taken=t, clock=lambda t=t: t + 1e-4)
        if w.reason != Reason.NONE:
            break
        assert w.out is not None and w.out.u is not None
        applied = plan.torque(k, w.out.u)
        if k:
            loop.applied((k - 1) * T_ns, prev)  # after tick k was estimated: late
        prev = applied
        arm.advance(applied)
    assert loop.watchdog.hold is not None and loop.watchdog.hold.name == "actuation"
    assert loop.watchdog.hold.k == k_f + 6, loop.watchdog.hold.line()
    assert loop.skipped["torque sample after its tick was estimated"] == k - 1
    assert loop.watchdog.seen.actuation_judged == k - 1  # samples 2..k (tick 0 at 2)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "seeds", "duration"),
    [("paper-sim", range(200, 206), 4.0), ("panda-control", range(200, 203), 3.0)],
)
def test_clean_runs_never_hold(name: str, seeds: range, duration: float) -> None:
    sc0 = load_scenario(name).with_overrides(duration=duration)
    lib = library_for(sc0)
    for seed in seeds:
        run = run_watched(sc0.with_overrides(seed=seed), lib)
        assert run.hold is None, (name, seed, run.hold.line())
        assert run.ticks == round(duration / lib.T) + 1
        b, s = WatchdogBounds(), run.seen
        assert s.samples == run.ticks
        assert 0 < s.max_tracking < b.tracking_error and 0 < s.max_innovation < b.innovation_nis
        # every tick's applied torque judged, each the command the arm applied, exactly
        assert s.actuation_judged == run.ticks - 1 and s.max_actuation == 0.0


def test_watchdog_keys_parse_and_refuse() -> None:
    spec = parse_topic_spec({"watchdog": {"tracking_error": 0.1, "deadline_misses": 0}})
    assert spec.watchdog == WatchdogBounds(tracking_error=0.1, deadline_misses=0)
    assert (
        parse_topic_spec({"watchdog": {"innovation_nis": math.inf}}).watchdog.innovation_nis
        == math.inf
    )
    assert parse_topic_spec({"watchdog": {"lag": 0.02}}).watchdog.lag == 0.02
    for bad in (
        {"tracking": 0.1},
        {"tracking_error": 0.0},
        {"tracking_error": "0.1"},
        {"innovation_window": 0},
        {"deadline_window": 1.5},
        {"encoder_timeout": math.inf},
        {"compute_budget": math.nan},
        {"deadline_misses": True},
        {"actuation_error": 0.0},
        {"actuation_ticks": 0},
        {"lag": -0.01},
        {"lag": 0},
    ):
        with pytest.raises(ConfigError, match=r"\[watchdog\]"):
            parse_topic_spec({"watchdog": bad})


def _config(**bounds: Any) -> WatchdogConfig:
    return WatchdogConfig(n=2, N=10, ne=4, T=1e-3, bounds=WatchdogBounds(**bounds))


def _tick(k: int, **kw: Any) -> WatchdogTick:
    """A sample k stamped k ms, taken at k ms, done 0.1 ms later, on its path."""
    base: dict[str, Any] = {
        "k": k,
        "gap": 0,
        "stamp_ns": k * 1_000_000,
        "taken": k * 1e-3,
        "done": k * 1e-3 + 1e-4,
        "x_hat": np.zeros(10),
        "P_diag": np.ones(10),
        "q_des": np.zeros(2),
        "u": np.zeros(2),
        "handed_over": True,
        "encoder_nis": 4.0,
    }
    return WatchdogTick(**(base | kw))


def test_checks_one_by_one() -> None:
    """Each check trips on its own quantity, with its cause; the first in the documented
    order wins; a hold is latched; nothing is judged at the first sample."""
    wd = Watchdog(_config())
    assert wd.sample(_tick(0, x_hat=np.full(10, np.nan))) == Reason.NONE  # the first: offset
    assert wd.sample(_tick(1, q_des=np.array([0.0, 0.6]))) == Reason.TRACKING
    assert wd.hold is not None and wd.hold.value == 0.6 and wd.hold.k == 1
    assert wd.sample(_tick(2)) == Reason.TRACKING  # latched
    wd.reset()
    wd.sample(_tick(0))
    assert wd.sample(_tick(1, q_des=np.array([0.0, 0.6]), handed_over=False)) == Reason.NONE
    # several at once: the covariance (estimator failed) before the tracking; after a gap:
    # the node fell behind
    wd.reset()
    wd.sample(_tick(0))
    got = wd.sample(_tick(4, gap=2, status=-2, q_des=np.array([0.0, 0.6])))
    assert got == Reason.COVARIANCE and wd.hold is not None and wd.hold.cause == Cause.BEHIND
    wd.reset()
    wd.sample(_tick(0))
    assert wd.sample(_tick(1, status=-2)) == Reason.COVARIANCE
    assert wd.hold is not None and wd.hold.cause == Cause.INCONSISTENT
    # more than max_gap_steps missing: on time -> the driver paused; late -> lost by the node
    for taken, reason, cause in (
        (10e-3, Reason.ENCODER_STALL, Cause.GAP),
        (70e-3, Reason.NODE_STALLED, Cause.LOST),
    ):
        wd.reset()
        wd.sample(_tick(0))
        tick = _tick(10, gap=9, taken=taken, done=taken + 1e-4, x_hat=None, P_diag=None)
        assert wd.sample(tick) == reason and wd.hold is not None and wd.hold.cause == cause
    # compute: 0.2 s for one tick
    wd.reset()
    wd.sample(_tick(0))
    assert wd.sample(_tick(1, done=1e-3 + 0.2)) == Reason.COMPUTE
    # deadline: 51 late samples (0.06 s behind) of the last 1000
    wd.reset()
    wd.sample(_tick(0))
    for k in range(1, 52):
        got = wd.sample(_tick(k, taken=k * 1e-3 + 0.06, done=k * 1e-3 + 0.0601))
        assert got == (Reason.DEADLINE if k == 51 else Reason.NONE), k
    # innovation: the mean of NIS / 4 over 50 fused updates above 20
    wd.reset()
    wd.sample(_tick(0))
    for k in range(1, 51):
        got = wd.sample(_tick(k, encoder_nis=84.0))
        assert got == (Reason.INNOVATION if k == 50 else Reason.NONE), k
    assert wd.hold is not None and wd.hold.value == 21.0
    # the same innovations on samples processed 0.06 s late: the node behind is named, not
    # what its lateness caused (the arm on older commands), before 50 late samples counted;
    # the same with the tracking error
    # (queued: each due before the previous one was done; the tracking error at the 2nd)
    for k_trip, kw in ((50, {"encoder_nis": 84.0}), (2, {"q_des": np.array([0.0, 0.6])})):
        wd.reset()
        wd.sample(_tick(0))
        for k in range(1, k_trip + 1):
            extra = kw if "encoder_nis" in kw or k == k_trip else {}
            got = wd.sample(_tick(k, taken=k * 1e-3 + 0.06, done=k * 1e-3 + 0.0601, **extra))
            assert got == (Reason.DEADLINE if k == k_trip else Reason.NONE), k
        assert wd.hold is not None and wd.hold.cause == Cause.LATE
        assert wd.hold.value == pytest.approx(0.0601) and wd.hold.bound == 0.05
        assert wd.line().startswith("hold: deadline: this node is behind, not the arm: ")
        caused = "innovation" if k_trip == 50 else "tracking"
        assert wd.line().endswith(f"0 missing); {caused} tripped"), wd.line()
    # the same late innovations in lockstep (each sample sent after the previous command:
    # never queued, the arm waited): named as they are, the arm's
    wd.reset()
    wd.sample(_tick(0))
    for k in range(1, 51):
        sent = k * 1_000_000 + 70_000_000 * (k - 1)  # after the previous one was done
        late = _tick(k, stamp_ns=sent, taken=sent * 1e-9 + 0.06, done=sent * 1e-9 + 0.0601)
        got = wd.sample(dataclasses.replace(late, encoder_nis=84.0))
        assert got == (Reason.INNOVATION if k == 50 else Reason.NONE), k
    # non-finite: the estimate before the command
    wd.reset()
    wd.sample(_tick(0))
    assert wd.sample(_tick(1, u=np.array([np.nan, 0.0]))) == Reason.NONFINITE
    assert wd.hold is not None and wd.hold.cause == Cause.COMMAND
    assert "nan" in wd.line()


def test_actuation_finds_the_command_applied() -> None:
    """``actuation``: the arm's torque is compared with the command it may have applied
    (late commands: an older one, zero before the first), relative to u_max; a mismatch
    holds only after ``actuation_ticks`` in a row; nothing judged without a command or a
    reported torque."""
    cfg = WatchdogConfig(
        n=2, N=10, ne=4, T=1e-3, bounds=WatchdogBounds(actuation_ticks=3), u_max=(10.0, math.inf)
    )
    assert cfg.scale() == [10.0, 1.0]
    wd = Watchdog(cfg)
    u = [np.array([1.0 + k, -0.5 * k]) for k in range(40)]
    wd.sample(_tick(0, u=u[0]))
    # tick 0 applied zero (u_0 not there in time), ticks 1..3 applied u_0 (late), then u_2
    for k, (j, a) in enumerate(
        [(0, np.zeros(2)), (1, u[0]), (2, u[0]), (3, u[0]), (4, u[2]), (5, u[5])], start=1
    ):
        assert wd.sample(_tick(k, u=u[k], applied=a, applied_k=j)) == Reason.NONE, k
    assert wd.seen.actuation_judged == 6 and wd.seen.max_actuation == 0.0
    # an older command than the last applied (u_2) is not a candidate any more: a mismatch,
    # held at the third in a row (no reported torque between: not judged, run kept)
    assert wd.sample(_tick(7, u=u[7], applied=u[1], applied_k=6)) == Reason.NONE
    assert wd.sample(_tick(8, u=u[8])) == Reason.NONE
    assert wd.sample(_tick(9, u=u[9], applied=np.zeros(2), applied_k=8)) == Reason.NONE
    assert wd.sample(_tick(10, u=u[10], applied=np.zeros(2), applied_k=9)) == Reason.ACTUATION
    h = wd.hold
    assert h is not None and h.cause == Cause.NONE and h.k == 10 and h.bound == 0.01
    # the smallest distance: |0 - u_5| on the candidates u_5..u_9: joint 0 (6 / 10) vs joint
    # 1 (2.5 / 1): 2.5
    assert h.value == 2.5, h.value
    assert wd.line().startswith("hold: actuation: the arm does not apply the command")
    # within the bound: 0.08 N m off on joint 0 is 0.8 % of 10 N m; a run broken by a match
    wd.reset()
    wd.sample(_tick(0, u=u[0]))
    for k in range(1, 30):
        a = u[k - 1] + np.array([0.08, 0.0]) if k % 3 else np.zeros(2)
        assert wd.sample(_tick(k, u=u[k], applied=a, applied_k=k - 1)) == Reason.NONE, k
    # not judged: no command (no controller), a non-finite torque
    wd.reset()
    wd.sample(_tick(0, u=None))
    for k in range(1, 10):
        assert wd.sample(_tick(k, u=None, applied=np.ones(2), applied_k=k - 1)) == Reason.NONE
        bad = np.array([np.nan, 1.0])
        assert wd.sample(_tick(k + 100, u=u[1], applied=bad, applied_k=k)) == Reason.NONE
    assert wd.seen.actuation_judged == 0
    with pytest.raises(ConfigError):
        Watchdog(WatchdogConfig(n=2, N=10, ne=4, T=1e-3, u_max=(1.0,)))
    with pytest.raises(ConfigError):
        Watchdog(WatchdogConfig(2, 10, 4, 1e-3, WatchdogBounds(actuation_ticks=0)))


def test_idle_says_whose_silence() -> None:
    """Silence with the publisher there: the driver is silent; without: gone.  A call after
    the node's own loop paused past the timeout judges nothing (the arm's samples of the
    pause may not be taken yet): the next call does."""
    for calls, pubs, reason, cause in (
        ([0.3, 0.6], 1, Reason.ENCODER_STALL, Cause.SILENT),
        ([0.3, 0.6], 0, Reason.ENCODER_STALL, Cause.GONE),
        ([0.7, 0.75], 1, Reason.ENCODER_STALL, Cause.SILENT),
        ([0.7, 0.75], 0, Reason.ENCODER_STALL, Cause.GONE),
    ):
        wd = Watchdog(_config())
        assert wd.idle(0.2, pubs) == Reason.NONE  # before the first sample: nothing
        wd.sample(_tick(0))
        got = [wd.idle(t, pubs) for t in calls]
        assert got[-1] == reason and wd.hold is not None and wd.hold.cause == cause, got
        assert all(g == Reason.NONE for g in got[:-1])


def test_idle_counting_asks_the_graph_only_when_silent() -> None:
    """The node's idle call reads the publisher count (a graph query) only once the silence
    is past the timeout, and holds as idle does with that count."""
    asked: list[float] = []

    def count() -> int:
        asked.append(1.0)
        return 0

    wd = Watchdog(_config())
    assert wd.idle_counting(0.1, count) == Reason.NONE and not asked  # before the first
    wd.sample(_tick(0))
    assert wd.idle_counting(0.3, count) == Reason.NONE and not asked
    assert wd.idle_counting(0.6, count) == Reason.ENCODER_STALL and len(asked) == 1
    assert wd.hold is not None and wd.hold.cause == Cause.GONE
    assert wd.idle_counting(0.9, count) == Reason.ENCODER_STALL and len(asked) == 1  # latched
