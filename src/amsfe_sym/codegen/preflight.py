"""Checks of a scenario against its robot that need no compiled library.

Generating a 7-DOF arm's library takes about a minute; a scenario with a 6-value ``q0`` used
to be refused only after that, one wrong vector per run.  :func:`check_scenario_shapes`
counts the modelled joints from the spec and the URDF's XML (no Pinocchio, no CasADi) and
reports every wrong-length vector in one message, before anything is generated.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from amsfe_sym.core.values import PERIOD_MAX, PERIOD_MIN, SUBSTEPS_MAX
from amsfe_sym.errors import ConfigError, SpecError, describe
from amsfe_sym.load.spec import RobotSpec
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.signals.trajectory import from_config as trajectory_from_config

__all__ = [
    "check_model_bounds",
    "check_period",
    "check_scenario_shapes",
    "check_substeps",
    "modelled_joints",
]


def modelled_joints(spec: RobotSpec) -> list[str] | None:
    """Names of the joints in q, from the spec and the URDF's XML (None if unreadable: the
    loader then reports the URDF's defect itself)."""
    if spec.model.joints is not None:
        return list(spec.model.joints)
    try:
        root = ET.parse(spec.urdf).getroot()
    except (OSError, ET.ParseError):
        return None
    movable = [
        str(j.get("name")) for j in root.findall("joint") if j.get("type", "fixed") != "fixed"
    ]
    return [j for j in movable if j not in spec.model.locked]


def check_scenario_shapes(sc: Scenario, spec: RobotSpec) -> None:
    """Refuse, in one message listing all of them, scenario vectors whose length is not the
    robot's joint count n (or its parameter count p for ``[estimate0] theta``); and a
    duration of less than one step or whose records would not fit in memory
    (:func:`~amsfe_sym.scenario.run_ticks`).

    Raises:
        ConfigError: one or more vectors have the wrong length, or a bad duration.
    """
    joints = modelled_joints(spec)
    if joints is None:
        return
    n, p = len(joints), len(spec.theta)
    vectors: dict[str, tuple[tuple[float, ...], int]] = {
        "[plant] q0": (sc.plant.q0, n),
        "[plant] qd0": (sc.plant.qd0, n),
        "[estimate0] q": (sc.estimate0.q, n),
        "[estimate0] qd": (sc.estimate0.qd, n),
    }
    if sc.plant.motor0 == "explicit":
        vectors["[plant] qm0"] = (sc.plant.qm0, n)
        vectors["[plant] qmd0"] = (sc.plant.qmd0, n)
    if sc.estimate0.theta:
        vectors["[estimate0] theta"] = (sc.estimate0.theta, p)
    run_ticks(sc, spec.model.T, n, 4 * n + p)  # a duration of < 1 step or too much memory
    wrong = [f"{k} has {len(v)}" for k, (v, m) in vectors.items() if len(v) != m]
    wrong_theta = "[estimate0] theta" in " ".join(wrong)
    traj_n = trajectory_from_config(dict(sc.trajectory)).n
    if traj_n != n:
        wrong.append(f"[trajectory] has {traj_n}")
    if wrong:
        where = str(sc.source) if sc.source is not None else sc.name
        expected = f"{n} values per joint vector (robot {spec.name}: {joints})"
        if wrong_theta:
            expected += f" and {p} in [estimate0] theta"
        raise ConfigError(
            describe(
                f"{where}: vector lengths",
                expected,
                "; ".join(wrong),
                f"give {n} values per joint vector, in the order {joints}",
            )
        )


def check_period(T: object, what: str = "--period") -> float:
    """``T`` [s] if it is a finite number in [:data:`~amsfe_sym.core.values.PERIOD_MIN`,
    :data:`~amsfe_sym.core.values.PERIOD_MAX`] (docs/input-rules.md).

    Raises:
        SpecError: anything else (1e300, 1e-320, nan, a string), in one line with the range.
    """
    ok = isinstance(T, int | float) and not isinstance(T, bool) and math.isfinite(T)
    if not (ok and PERIOD_MIN <= T <= PERIOD_MAX):  # type: ignore[operator]
        raise SpecError(
            describe(
                what,
                f"a sampling interval in [{PERIOD_MIN:g}, {PERIOD_MAX:g}] s",
                repr(T),
                "give the log's period in seconds, e.g. 0.0333",
            )
        )
    return float(T)  # type: ignore[arg-type]


def check_substeps(m: int, what: str, T: float, chosen: bool) -> int:
    """``m`` rk4 steps per ``T`` if 1 <= m <= :data:`~amsfe_sym.core.values.SUBSTEPS_MAX`
    (each is unrolled in the generated graph: 10^10 of them never finished).  ``chosen``:
    m was chosen from the joint modes for T, so the fix is a shorter period.

    Raises:
        SpecError: m out of range, with the longest period that fits when ``chosen``.
    """
    if 1 <= m <= SUBSTEPS_MAX:
        return m
    if chosen:
        longest = T * SUBSTEPS_MAX / m
        fix = (
            f"the joint modes need {m} rk4 steps per T = {T:g} s: generate at --period "
            f"{float(f'{longest:.3g}'):g} or shorter (the log's rate, or record faster)"
        )
    else:
        fix = f"pass --substeps from 1 to {SUBSTEPS_MAX} (or omit it: chosen from the modes)"
    raise SpecError(describe(what, f"1 to {SUBSTEPS_MAX} rk4 steps per T", str(m), fix))


def check_model_bounds(spec: RobotSpec) -> None:
    """Refuse a spec whose T or unrolled step counts are out of range (a spec built in
    memory, which the robot.toml reader did not see), before any lock or file is made.

    Raises:
        SpecError: T outside [PERIOD_MIN, PERIOD_MAX] or a step count outside
            [1, SUBSTEPS_MAX].
    """
    m = spec.model
    check_period(m.T, f"robot {spec.name}: [model] T")
    for key in ("model_substeps", "plant_substeps", "inverse_iterations"):
        check_substeps(int(getattr(m, key)), f"robot {spec.name}: [model] {key}", m.T, False)
