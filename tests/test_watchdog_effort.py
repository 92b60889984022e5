"""The ``innovation`` bound per effort kind (issue 34; docs/watchdogs.md "The innovation
bound per effort kind"): simulated logs of each effort kind, played in process into the
node's loop (ros/watchdog_logs.py) with the bounds the topic spec of that kind gives.

- the topic spec's ``[effort] kind`` picks the default ``innovation_nis``; a bound the spec
  or ``[watchdog]`` sets is kept;
- clean logs of every kind never hold (seeds disjoint from the measured ones:
  tools/watchdog_innovation.py measured 2000-2019 and faults on 0-2);
- a frozen encoder, a 20 mrad encoder jump and a misreported joint torque (zero, reversed)
  hold for ``innovation`` within 100 ms of the fault.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.watchdog_logs import play_watched
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.spec import parse_topic_spec
from amsfe_sym.topics.watchdog import INNOVATION_NIS, WatchdogBounds

#: (effort kind, encoders' positions) as a log's topic spec says them.
KINDS = [
    ("applied", "motor"),
    ("joint_torque", "motor"),
    ("joint_torque", "link"),
    ("none", "motor"),
]
FAULT_AT = 1.0  # [s] of the log


def _spec(kind: str, positions: str) -> dict[str, Any]:
    return {"joints": {"positions": positions}, "effort": {"kind": kind}}


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    return sc, library_for(sc)


def test_the_innovation_default_follows_the_effort_kind() -> None:
    """No spec, or ``applied``: 5; ``joint_torque`` and ``none``: their own default, above
    the applied one; ``[watchdog] innovation_nis`` (also inf) wins over the kind; the other
    ``[watchdog]`` keys leave the kind's default."""
    assert parse_topic_spec({}).watchdog.innovation_nis == WatchdogBounds().innovation_nis == 5.0
    assert parse_topic_spec(_spec("applied", "motor")).watchdog.innovation_nis == 5.0
    for kind in ("joint_torque", "none"):
        got = parse_topic_spec({"effort": {"kind": kind}}).watchdog
        assert got.innovation_nis == INNOVATION_NIS[kind] > 5.0
        got = parse_topic_spec({"effort": {"kind": kind}, "watchdog": {"tracking_error": 0.2}})
        assert got.watchdog.innovation_nis == INNOVATION_NIS[kind]
        assert got.watchdog.tracking_error == 0.2
        for nis in (7.5, math.inf):
            spec = {"effort": {"kind": kind}, "watchdog": {"innovation_nis": nis}}
            assert parse_topic_spec(spec).watchdog.innovation_nis == nis


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "positions"), KINDS)
def test_clean_logs_of_every_effort_kind_never_hold(paper: Any, kind: str, positions: str) -> None:
    """A clean log of each kind, judged with its spec's bounds, plays to its end; its window
    means stay below the bound (they are real NIS: above 0.5, and the joint torque's and
    no torque's above the applied one's bound of 5 somewhere, the defect of issue 34)."""
    sc, lib = paper
    bounds = parse_topic_spec(_spec(kind, positions)).watchdog
    peaks = []
    for seed in (3000, 3001):
        p = play_watched(sc.with_overrides(seed=seed), lib, kind, positions, bounds=bounds)
        assert p.hold is None, p.hold.line() if p.hold else None
        peaks.append(float(np.nanmax(p.means)))
    assert 0.5 < max(peaks) < bounds.innovation_nis, peaks
    if kind == "joint_torque" and positions == "link":
        assert max(peaks) > 5.0, peaks  # the applied kind's bound would have held it


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "positions"), KINDS)
@pytest.mark.parametrize(
    ("fault", "size"),
    [("frozen", 0.0), ("jump", 0.02), ("torque_zero", 0.0), ("torque_reversed", 0.0)],
)
def test_log_faults_hold_for_innovation_within_100_ms(
    paper: Any, kind: str, positions: str, fault: Any, size: float
) -> None:
    """Each fault in a log of each kind, judged with its spec's bounds, holds for
    ``innovation`` within 100 ms of the fault and not before it (a log without a torque has
    no torque to misreport)."""
    if kind == "none" and fault.startswith("torque"):
        pytest.skip("no torque in the log")
    sc, lib = paper
    bounds = parse_topic_spec(_spec(kind, positions)).watchdog
    for seed in (5, 6):
        p = play_watched(sc.with_overrides(seed=seed), lib, kind, positions, fault, FAULT_AT,
                         size=size, bounds=bounds)  # fmt: skip
        assert p.hold is not None and p.hold.name == "innovation", p.hold
        assert p.hold_t is not None and FAULT_AT <= p.hold_t <= FAULT_AT + 0.1, p.hold_t
