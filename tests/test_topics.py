"""The topic spec and roles (docs/reference/topics.md): one definition for logs and live nodes."""

from __future__ import annotations

from pathlib import Path

import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.topics import ROLES, TopicSpec, joint_order, read_topic_spec
from amsfe_sym.topics.spec import parse_topic_spec


def test_defaults_are_the_roles_topics() -> None:
    spec = TopicSpec()
    for name, role in ROLES.items():
        assert spec.topic(name) == role.topic
    assert spec.explicit == frozenset()
    assert spec.effort_kind is None


def test_one_topic_plays_several_roles(tmp_path: Path) -> None:
    p = tmp_path / "spec.toml"
    p.write_text(
        '[topics]\nencoders = "/joint_states"\neffort = "/joint_states"\n'
        '[effort]\nkind = "joint_torque"\n[qos]\nreliability = "best_effort"\ndepth = 5\n'
    )
    spec = read_topic_spec(p)
    assert spec.roles_of("/joint_states") == ["encoders", "effort"]
    assert spec.explicit == {"encoders", "effort"}
    assert (spec.effort_kind, spec.reliability, spec.depth) == ("joint_torque", "best_effort", 5)
    assert spec.source == p


def test_torque_is_read_as_effort() -> None:
    spec = parse_topic_spec({"topics": {"torque": "/tau"}})
    assert spec.effort == "/tau" and spec.torque == "/tau"
    with pytest.raises(ConfigError, match="one of 'torque' and 'effort'"):
        parse_topic_spec({"topics": {"effort": "/a", "torque": "/b"}})


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ({"topic": {}}, "sections among"),
        ({"topics": {"encoder": "/x"}}, "keys among"),
        ({"topics": {"encoders": "x"}}, "a topic name"),
        ({"joints": {"names": ["a", "b", "a"]}}, r"\['a'\] repeated"),
        ({"effort": {"kind": "current"}}, "one of"),
        ({"timing": {"grid_tolerance": 0.5}}, r"a number in \(0, 0.5\)"),
        ({"timing": {"max_gap_steps": True}}, "an integer >= 0"),
        ({"qos": {"reliability": "best"}}, "'reliable' or 'best_effort'"),
        ({"qos": {"depth": 0}}, "an integer >= 1"),
    ],
)
def test_bad_specs_are_refused_with_a_fix(doc: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        parse_topic_spec(doc)
    assert "Fix:" in str(info.value) and not str(info.value).rstrip().endswith("Fix:")


def test_joint_order_ignores_extras_and_refuses_missing_or_twice() -> None:
    names = ["finger_1", "j2", "j1", "finger_2"]
    assert joint_order(names, ["j1", "j2"], "here") == [2, 1]
    with pytest.raises(ConfigError, match=r"missing \['j3'\]"):
        joint_order(names, ["j1", "j3"], "here")
    with pytest.raises(ConfigError, match="more than once"):
        joint_order(["j1", "j1", "j2"], ["j1", "j2"], "here")
