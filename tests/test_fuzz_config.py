"""Fuzzing the configuration readers (issue 20 item 7): robot.toml and scenario files with
values of every TOML type put where the shipped files have theirs.  Every input either
parses, or is refused with an AmsfeError (one line: expected, found, fix); never another
exception, and a value that parses is finite where a number is expected."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amsfe_sym.core.toml import tomllib
from amsfe_sym.errors import AmsfeError
from amsfe_sym.load.spec import parse_spec, robots_dir
from amsfe_sym.scenario import parse_scenario, scenarios_dir

#: Values of every TOML type, the troublesome ones included.
VALUES = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.one_of(st.floats(allow_nan=True), st.booleans(), st.text(max_size=3)), max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _leaves(data: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Paths to every scalar or list value of a parsed TOML document."""
    if isinstance(data, dict):
        return [p for k, v in data.items() for p in _leaves(v, (*path, k))]
    if isinstance(data, list) and data and all(isinstance(x, dict) for x in data):
        return [p for i, v in enumerate(data) for p in _leaves(v, (*path, i))]
    return [path]


def _replace(data: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(data, dict):
        return {**data, head: _replace(data[head], rest, value)}
    out = list(data)
    out[head] = _replace(out[head], rest, value)
    return out


def _finite_numbers(obj: Any) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj) or obj == math.inf  # inf: "no limit" where documented
    if isinstance(obj, tuple | list):
        return all(_finite_numbers(x) for x in obj)
    return True


ROBOT = robots_dir() / "paper_2link" / "robot.toml"
ROBOT_DATA = tomllib.loads(ROBOT.read_text())
ROBOT_LEAVES = [p for p in _leaves(ROBOT_DATA) if p != ("urdf",)]
SCENARIO = scenarios_dir() / "paper-sim.toml"
SCENARIO_DATA = tomllib.loads(SCENARIO.read_text())
SCENARIO_LEAVES = _leaves(SCENARIO_DATA)

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(st.sampled_from(ROBOT_LEAVES), VALUES)
def test_robot_toml_values(path: tuple[Any, ...], value: Any) -> None:
    data = _replace(ROBOT_DATA, path, value)
    try:
        spec = parse_spec(data, ROBOT)
    except AmsfeError as exc:
        assert "\n" not in str(exc)
        return
    m = spec.model
    assert math.isfinite(m.T) and m.T > 0
    assert isinstance(m.plant_substeps, int) and isinstance(m.inverse_iterations, int)
    assert isinstance(m.model_substeps, int) and m.model_substeps >= 1
    assert _finite_numbers(tuple(spec.camera.__dict__.values()))


@FUZZ
@given(st.sampled_from(SCENARIO_LEAVES), VALUES)
def test_scenario_values(path: tuple[Any, ...], value: Any) -> None:
    data = _replace(SCENARIO_DATA, path, value)
    try:
        sc = parse_scenario(data, SCENARIO)
    except AmsfeError as exc:
        assert "\n" not in str(exc)
        return
    assert math.isfinite(sc.duration) and sc.duration > 0
    assert isinstance(sc.seed, int)
    assert _finite_numbers(tuple(sc.plant.q0) + tuple(sc.plant.qd0))


@pytest.mark.parametrize("name", ["robot.toml", "scenario.toml"])
def test_a_file_that_is_not_utf8_is_one_line(tmp_path: Path, name: str) -> None:
    from amsfe_sym.load.spec import load_spec
    from amsfe_sym.scenario import load_scenario

    p = tmp_path / name
    p.write_bytes(b'urdf = "x.urdf"\n# caf\xe9\n')
    with pytest.raises(AmsfeError, match="UTF-8"):
        (load_spec if name == "robot.toml" else load_scenario)(p)


# ---- issue 37: the topic spec accepted `torque` then `effort` (the second silently won)
# and refused `effort` then `torque`; the outcome must not depend on the keys' order
_TOPIC_TABLES = {
    "topics": st.dictionaries(
        st.sampled_from(["encoders", "effort", "torque", "camera", "truth"]),
        st.sampled_from(["/joint_states", "/a", "/b"]),
        max_size=4,
    ),
    "effort": st.dictionaries(
        st.sampled_from(["kind", "joint_torque_std"]),
        st.one_of(st.sampled_from(["applied", "none"]), st.floats(0, 2)),
        max_size=2,
    ),
    "filter": st.dictionaries(
        st.sampled_from(["encoder_q_std", "buffer_steps", "gate_probability"]),
        st.one_of(st.integers(0, 3), st.floats(0, 2), st.just("log")),
        max_size=3,
    ),
}


def _outcome(data: dict[str, Any]) -> Any:
    from amsfe_sym.topics.spec import parse_topic_spec

    try:
        spec = parse_topic_spec(data)
    except AmsfeError as exc:
        return type(exc)
    return replace(spec, filter_options=(), effort_options=()), dict(spec.filter_options)


@FUZZ
@given(st.fixed_dictionaries({}, optional=_TOPIC_TABLES))
def test_topic_spec_outcome_does_not_depend_on_key_order(data: dict[str, Any]) -> None:
    backwards = {s: dict(reversed(list(t.items()))) for s, t in reversed(list(data.items()))}
    assert _outcome(data) == _outcome(backwards)


@pytest.mark.parametrize(
    "table", [{"torque": "/a", "effort": "/b"}, {"effort": "/b", "torque": "/a"}]
)
def test_torque_and_effort_together_are_refused_in_either_order(table: dict[str, str]) -> None:
    from amsfe_sym.topics.spec import parse_topic_spec

    with pytest.raises(AmsfeError, match="one of 'torque' and 'effort'"):
        parse_topic_spec({"topics": table})
