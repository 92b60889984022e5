"""Faults of the simulated arm and the live loop under CPU load (issue 34 item 4,
docs/live-load.md).

In process: :class:`~amsfe_sym.ros.faults.FaultPlan` changes exactly what it says, from the
tick it says, and nothing before (the arm's random streams untouched).  Over real DDS
(markers ``ros`` and ``slow``; each test on its own ROS_DOMAIN_ID and topics, localhost, every
process bounded and killed in a ``finally``, tests/test_ros.py's harness): outcomes, never
times.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.faults import Fault, FaultPlan, parse_fault
from amsfe_sym.scenario import load_scenario


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=0.3)
    return sc, library_for(sc)


def _run_arm(sc: Any, lib: Any, faults: tuple[Fault, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The arm driven by a fixed command sequence: the samples it sends, the states it had."""
    arm, plan = SimArm(sc, lib), FaultPlan(faults, lib.T, lib.n)
    u = np.array([3.0, -1.0])[: lib.n]
    z, x = [], []
    for k in range(arm.K):
        x.append(arm.state)
        z.append(plan.encoders(k, arm.sense().z))
        if k + 1 < arm.K:
            arm.advance(plan.torque(k, u))
    return np.array(z), np.array(x)


@pytest.mark.parametrize(
    "fault",
    [Fault("encoder_frozen", 0.1), Fault("encoder_jump", 0.1, 0.25), Fault("torque_loss", 0.1)],
)
def test_a_fault_changes_what_it_says_from_its_tick(paper: Any, fault: Fault) -> None:
    sc, lib = paper
    n, kf = lib.n, 100
    z0, x0 = _run_arm(sc, lib, ())
    z1, x1 = _run_arm(sc, lib, (fault,))
    assert np.array_equal(z1[:kf], z0[:kf]) and np.array_equal(x1[: kf + 1], x0[: kf + 1])
    if fault.kind == "encoder_frozen":
        assert np.array_equal(x1, x0)  # the arm moves on; its encoders say it does not
        assert np.all(z1[kf:] == z0[kf]) and not np.array_equal(z0[kf:], z1[kf:])
    elif fault.kind == "encoder_jump":
        assert np.array_equal(x1, x0)
        np.testing.assert_array_equal(z1[kf:, :n], z0[kf:, :n] + 0.25)
        np.testing.assert_array_equal(z1[kf:, n:], z0[kf:, n:])
    else:  # no torque from tick kf: the arm departs from the driven one at kf + 1
        assert not np.array_equal(x1[kf + 1], x0[kf + 1])
        arm = SimArm(sc, lib)
        for k in range(kf + 1):
            arm.sense()
            arm.advance(np.array([3.0, -1.0])[:n] if k < kf else np.zeros(n))
        np.testing.assert_array_equal(arm.state, x1[kf + 1])


@pytest.mark.parametrize(
    "text",
    [
        "encoder_stuck@1",
        "encoder_frozen",
        "encoder_frozen@-1",
        "encoder_frozen@nan",
        "encoder_frozen@1=2",
        "encoder_jump@1",
        "encoder_jump@1=0",
        "encoder_jump@1=1e9",
        "torque_loss@x",
    ],
)
def test_a_bad_fault_is_one_line(text: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_fault(text)
    assert "\n" not in str(err.value) and "Fix" in str(err.value)


def test_faults_parse_and_the_same_kind_twice_is_refused(paper: Any) -> None:
    _, lib = paper
    assert parse_fault("encoder_jump@1.5=-0.5") == Fault("encoder_jump", 1.5, -0.5)
    assert parse_fault("torque_loss@0").label() == "torque_loss@0"
    with pytest.raises(ConfigError, match="each kind at most once"):
        FaultPlan((Fault("torque_loss", 1.0), Fault("torque_loss", 2.0)), lib.T, lib.n)
