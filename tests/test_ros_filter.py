"""The topic spec's ``[filter]`` on a live node (ros/spec_filter.py): the same keys and the
same precedence as ``amsfe estimate``'s log spec, carried through the node's ROS parameters."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.ros.middleware import spec_parameters
from amsfe_sym.ros.spec_filter import live_filter
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.spec import parse_topic_spec


def _spec(filter_table: dict[str, Any]) -> Any:
    return parse_topic_spec({"filter": filter_table}, "spec.toml")


def test_the_spec_filter_wins_key_by_key_over_the_scenario() -> None:
    sc = load_scenario("paper-sim")
    spec = _spec({"encoder_q_std": 2e-5, "link_torque_std": 0.7})
    out = live_filter(sc, spec)
    assert out.filter.encoder_q_std == 2e-5 and out.filter.link_torque_std == 0.7
    for key in ("motor_torque_std", "theta_rate_std", "encoder_qd_std"):
        assert getattr(out.filter, key) == getattr(sc.filter, key)
    assert live_filter(sc, _spec({})) is sc


def test_a_filter_measured_from_a_log_is_refused_live_in_one_line() -> None:
    sc = load_scenario("paper-sim")
    with pytest.raises(ConfigError) as info:
        live_filter(sc, _spec({"encoder_q_std": "log"}))
    text = str(info.value)
    assert "encoder_q_std" in text and "live" in text and "\n" not in text


def test_the_node_parameters_keep_the_spec_filter() -> None:
    """``spec_parameters`` (what the node reads back from its ROS parameters) keeps the
    file's ``[filter]`` keys, as it keeps the ``[effort]`` noise keys."""

    class FakeNode:
        def declare_parameter(self, name: str, value: Any, descriptor: Any = None) -> Any:
            return SimpleNamespace(value=value)

        def get_name(self) -> str:
            return "amsfe_node"

    spec = _spec({"encoder_qd_std": 4e-4, "motor_torque_std": 0.5})
    got = spec_parameters(FakeNode(), spec, ("joint1", "joint2"))
    assert dict(got.filter_options) == {"encoder_qd_std": 4e-4, "motor_torque_std": 0.5}
