"""Checks of a scenario against its robot that need no compiled library.

Generating a 7-DOF arm's library takes about a minute; a scenario with a 6-value ``q0`` used
to be refused only after that, one wrong vector per run.  :func:`check_scenario_shapes`
counts the modelled joints from the spec and the URDF's XML (no Pinocchio, no CasADi) and
reports every wrong-length vector in one message, before anything is generated.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.load.spec import RobotSpec
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.signals.trajectory import from_config as trajectory_from_config

__all__ = ["check_scenario_shapes", "modelled_joints"]


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
