"""Issue 37 items 5 and 6 (the topic spec side): every noise, size and depth key of a topic
spec bounded, with the range in one line; ``encoder_q_std = 0`` (printed as applied, but 0
meant "the simulated sensor's noise", which a log does not have) refused with the fix."""

from __future__ import annotations

from typing import Any

import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.topics.spec import parse_topic_spec


@pytest.mark.parametrize(
    ("section", "key", "value", "words"),
    [
        ("filter", "encoder_q_std", 1e300, ["(0, 1e+06]", "1e+300"]),
        ("filter", "encoder_q_std", 0, ['"log"', "a log does not know"]),
        ("filter", "encoder_qd_std", 0.0, ['"log"']),
        ("filter", "camera_pixel_std", 0, ["sensor's std"]),
        ("filter", "link_torque_std", 1e7, ["[0, 1e+06]"]),
        ("filter", "buffer_steps", 2_000_000_000, ["[1, 100000]"]),
        ("filter", "gate_probability", 3.0, ["[0, 1]"]),
        ("qos", "depth", 2_000_000_000, ["[1, 100000]"]),
    ],
)
def test_bounded_keys_are_refused_with_their_range(
    section: str, key: str, value: Any, words: list[str]
) -> None:
    with pytest.raises(ConfigError) as info:
        parse_topic_spec({section: {key: value}})
    msg = str(info.value)
    assert "\n" not in msg and f"[{section}] {key}" in msg
    for w in words:
        assert w in msg, (w, msg)


def test_values_inside_the_bounds_are_kept() -> None:
    spec = parse_topic_spec(
        {
            "filter": {"encoder_q_std": 1e-5, "buffer_steps": 100_000, "theta_rate_std": 0.0},
            "qos": {"depth": 5000},
        }
    )
    assert dict(spec.filter_options) == {
        "encoder_q_std": 1e-5,
        "buffer_steps": 100_000,
        "theta_rate_std": 0.0,
    }
    assert spec.depth == 5000


@pytest.mark.parametrize("kind", ["applied", "none"])
def test_link_positions_need_a_joint_torque(kind: str) -> None:
    """``positions = "link"`` with kind applied was ignored without a word (issue 37)."""
    with pytest.raises(ConfigError, match="link angles would be taken as motor angles"):
        parse_topic_spec({"joints": {"positions": "link"}, "effort": {"kind": kind}})
    spec = parse_topic_spec({"joints": {"positions": "link"}, "effort": {"kind": "joint_torque"}})
    assert spec.positions == "link"
