"""Tests of the desired trajectories: closed-form derivatives, shapes, paper values, config."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError, ShapeError
from amsfe_sym.signals.trajectory import (
    KINDS,
    Constant,
    PaperExperiment,
    Sinusoid,
    Trajectory,
    TrajectoryPoint,
    from_config,
    tip_circle,
)

TRAJECTORIES: list[Trajectory] = [
    Sinusoid.paper_sim(),
    Sinusoid(
        amplitude=[0.3, 1.2, 0.05],
        omega=[2.0, 0.7, 9.0],
        phase=[0.1, -1.0, 2.0],
        offset=[0.5, 0, -1],
    ),
    PaperExperiment(),
    PaperExperiment("printed"),
    Constant([0.5, -0.5]),
]
IDS = ["paper_sim", "sinusoid3", "experiment", "experiment_printed", "constant"]


@pytest.mark.parametrize("traj", TRAJECTORIES, ids=IDS)
def test_derivatives_match_central_differences(traj: Trajectory) -> None:
    t = np.linspace(0.0, 5.0, 41)
    h = 1e-5
    p = traj.evaluate(t)
    plus, minus = traj.evaluate(t + h), traj.evaluate(t - h)
    np.testing.assert_allclose(p.qd, (plus.q - minus.q) / (2 * h), atol=1e-6, rtol=0)
    np.testing.assert_allclose(p.qdd, (plus.qd - minus.qd) / (2 * h), atol=1e-6, rtol=0)


@pytest.mark.parametrize("traj", TRAJECTORIES, ids=IDS)
def test_shapes_scalar_and_vector_time(traj: Trajectory) -> None:
    n = traj.n
    for t in (0.3, np.float64(0.3), np.array(0.3)):
        point = traj.evaluate(t)
        assert isinstance(point, TrajectoryPoint)
        assert all(a.shape == (n,) for a in point)
    point_v = traj.evaluate([0.0, 0.3, 1.0])
    assert all(a.shape == (3, n) for a in point_v)
    np.testing.assert_array_equal(point_v.q[1], traj.evaluate(0.3).q)
    q, qd, qdd = traj.evaluate(np.array([]))  # unpacks like a tuple
    assert q.shape == qd.shape == qdd.shape == (0, n)


def test_bad_times() -> None:
    traj = Sinusoid.paper_sim()
    with pytest.raises(ShapeError, match="1-D"):
        traj.evaluate(np.zeros((2, 2)))
    with pytest.raises(ConfigError):
        traj.evaluate(float("nan"))


def test_paper_sim_values_at_zero() -> None:
    q, qd, qdd = Sinusoid.paper_sim().evaluate(0.0)
    np.testing.assert_allclose(q, [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(qd, [math.pi, 0.0], atol=1e-15)
    np.testing.assert_allclose(qdd, [0.0, -(math.pi**2)], atol=1e-14)
    # q1 = sin(pi t), q2 = cos(pi t) at any time
    t = np.linspace(0, 3, 13)
    q_t = Sinusoid.paper_sim().evaluate(t).q
    np.testing.assert_allclose(
        q_t, np.column_stack([np.sin(np.pi * t), np.cos(np.pi * t)]), atol=1e-15
    )


def test_paper_experiment_readings() -> None:
    t = np.array([0.0, 1.5, 10.0])
    corrected = PaperExperiment().evaluate(t)
    printed = PaperExperiment(reading="printed").evaluate(t)
    np.testing.assert_allclose(corrected.q[:, 0], 0.4 - t / 75)
    np.testing.assert_allclose(printed.q[:, 0], (0.4 - t) / 75)
    np.testing.assert_allclose(corrected.qd, -1 / 75)
    np.testing.assert_array_equal(corrected.qd, printed.qd)
    np.testing.assert_array_equal(corrected.qdd, 0.0)
    with pytest.raises(ConfigError, match="corrected"):
        PaperExperiment(reading="typo")
    with pytest.raises(ConfigError):
        PaperExperiment(l1=0.0)


def test_paper_experiment_tip_circle() -> None:
    exp = PaperExperiment(l1=0.6)
    xy = exp.tip(0.0)
    np.testing.assert_allclose(xy, [0.6 * math.cos(0.4), 0.6 * math.sin(0.4)])
    xy_v = exp.tip(np.linspace(0, 10, 7))
    assert xy_v.shape == (7, 2)
    np.testing.assert_allclose(np.hypot(xy_v[:, 0], xy_v[:, 1]), 0.6)
    assert tip_circle(np.zeros((2, 3)), 1.0).shape == (2, 3, 2)


def test_constant() -> None:
    q, qd, qdd = Constant([0.5, 0.5]).evaluate(2.0)
    np.testing.assert_array_equal(q, [0.5, 0.5])
    np.testing.assert_array_equal(qd, 0.0)
    np.testing.assert_array_equal(qdd, 0.0)
    assert Constant(0.2).n == 1


def test_sinusoid_broadcast_and_validation() -> None:
    s = Sinusoid(amplitude=1.0, omega=[1.0, 2.0, 3.0])
    assert s.n == 3
    np.testing.assert_array_equal(s.amplitude, [1.0, 1.0, 1.0])
    with pytest.raises(ConfigError, match="lengths"):
        Sinusoid(amplitude=[1.0, 1.0], omega=[1.0, 2.0, 3.0])
    with pytest.raises(ConfigError):
        Sinusoid(amplitude=[1.0, np.inf], omega=1.0)


def test_from_config_sinusoid_matches_paper_sim() -> None:
    table = {
        "kind": "sinusoid",
        "amplitude": [1, 1],
        "omega": [math.pi, math.pi],
        "phase": [0, math.pi / 2],
        "offset": [0, 0],
    }
    t = np.linspace(0, 2, 9)
    a, b = from_config(table).evaluate(t), Sinusoid.paper_sim().evaluate(t)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(x, y, atol=1e-15)
    assert isinstance(from_config({"kind": "paper_sim"}), Sinusoid)


@pytest.mark.parametrize(
    ("table", "cls"),
    [
        ({"kind": "constant", "q": [0.5, 0.5]}, Constant),
        ({"kind": "paper_experiment"}, PaperExperiment),
        ({"kind": "paper_experiment", "reading": "printed", "l1": 0.65}, PaperExperiment),
        ({"kind": "sinusoid", "amplitude": 1, "omega": 2}, Sinusoid),
    ],
)
def test_from_config_kinds(table: dict[str, Any], cls: type) -> None:
    assert isinstance(from_config(table), cls)


@pytest.mark.parametrize(
    ("table", "pattern"),
    [
        ({"kind": "spline"}, "trajectory kind"),
        ({}, "trajectory kind"),
        ({"kind": "sinusoid", "amplitude": [1]}, r"missing \['omega'\]"),
        ({"kind": "constant", "q": [0.0], "speed": 1}, r"unknown \['speed'\]"),
        ({"kind": "paper_experiment", "reading": "other"}, "reading"),
    ],
)
def test_from_config_errors(table: dict[str, Any], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern) as info:
        from_config(table)
    if "kind" in pattern:
        assert all(k in str(info.value) for k in KINDS)
    with pytest.raises(ConfigError):
        from_config([1, 2])  # type: ignore[arg-type]
