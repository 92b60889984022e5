"""The node's watchdog over real DDS: ``sim-node --lockstep`` + ``node --controller amsfe``
with a tracking bound the start-up's hand-over already passes (set as the ROS parameter
``watchdog.tracking_error``): the node holds for ``tracking`` at the hand-over's tick,
prints the hold line, exits 3, publishes the hold command and its record says why."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest

from amsfe_sym.apps.bench.ros import node_impls
from tests.test_node_record import _bag
from tests.test_ros import PATIENT_ARM, PATIENT_WATCHDOG, _finish, _impl, _ros_env, _start


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("impl", node_impls())
def test_node_holds_on_its_tracking_watchdog(tmp_path: Path, impl: str) -> None:
    """Each node implementation (module docstring).  The arm, waiting for commands after the
    hold (its patient command timeout), is stopped once the node has exited."""
    env = _ros_env(tmp_path)
    rec = tmp_path / "rec"
    procs = []
    try:
        procs.append(
            _start(env, "node", "paper-sim", "--controller", "amsfe", "--record", str(rec),
                   *_impl(impl), "--encoder-timeout", "20", "--ros-args", *PATIENT_WATCHDOG,
                   "-p", "watchdog.tracking_error:=1e-6")
        )  # fmt: skip
        procs.append(_start(env, "sim-node", "paper-sim", "--lockstep", "--duration", "3",
                            *PATIENT_ARM))  # fmt: skip
        ((code, text),) = _finish(procs[:1], 180.0)
    finally:
        for proc in procs:
            if proc.p.poll() is None:
                proc.kill(signal.SIGTERM)
        _finish(procs, 30.0)
    assert code == 3, text
    assert "node: hold: tracking: the arm left its path" in text, text
    assert "vs bound 1e-06 at tick" in text and "hold command" in text
    bag = _bag(rec)
    config = json.loads(bag["/amsfe/config"][0].data)
    assert config["stop"]["watchdog"] == "tracking"
    assert config["stop"]["exit_code"] == 3
    assert config["stop"]["line"].startswith("hold: tracking: ")
    # every published command and the hold command after them
    assert len(bag["/effort_controller/commands"]) == len(bag["/amsfe/estimate"]) + 1
