"""Sweep axes on the robot itself: model error between the simulated plant and the model.

The plant runs with each parameter's ``true`` value; the estimator starts from, and the
encoder-only controllers (``dtsmc``) keep, its ``initial`` value (the nominal model).  So
the model error of a run is ``true - initial``.  Two kinds of axis keys:

``robot.theta.NAME.true``, ``robot.theta.NAME.initial``
    a value of the robot spec's parameter ``NAME`` (e.g. ``robot.theta.payload.true``: the
    payload the plant carries [kg]; the nominal model's stays 0 kg on ``paper_2link``).
``robot.stiffness_error``
    relative stiffness error of every joint spring, e = Ks_true / Ks_model - 1 [-]: each
    modelled joint gets a ``joint_stiffness`` parameter ``Ks_<joint>`` (unless the robot
    has one) with ``initial`` = the spec's Ks and ``true`` = Ks (1 + e).  The parameter
    count p grows by n: AMSFE estimates the springs too, DTSMC keeps the nominal ones.

Each distinct set of values is a derived :class:`~amsfe_sym.load.spec.RobotSpec` with a name of
its own (``<robot>_r<hash>``: a C identifier, as CasADi needs), so its library is cached
beside the robot's and never evicts it; a worker derives it from the scenario's robot on its
own machine.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import replace

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.load.spec import RobotSpec, ThetaSpec, load_spec
from amsfe_sym.scenario import Scenario

__all__ = ["ROBOT_PREFIX", "check_robot_key", "derive_spec"]

#: Axis keys starting with this change the robot, not the scenario.
ROBOT_PREFIX = "robot."
_STIFFNESS = "robot.stiffness_error"


def _unknown(key: str, spec: RobotSpec) -> ConfigError:
    names = [t.name for t in spec.theta]
    known = [f"robot.theta.{n}.{f}" for n in names for f in ("true", "initial")]
    return ConfigError(
        describe(
            f"[axes] {key!r}",
            "a robot axis key",
            "no such key",
            "use one of " + ", ".join([*known, _STIFFNESS]),
        )
    )


def check_robot_key(key: str, sc: Scenario) -> None:
    """Refuse a ``robot.*`` key the scenario's robot does not have (one line)."""
    spec = load_spec(sc.robot)
    if key == _STIFFNESS:
        _stiffness(spec)  # raises if the spec cannot say its springs
        return
    parts = key.split(".")
    names = {t.name for t in spec.theta}
    if len(parts) != 4 or parts[1] != "theta" or parts[2] not in names:
        raise _unknown(key, spec)
    if parts[3] not in ("true", "initial"):
        raise _unknown(key, spec)


def _stiffness(spec: RobotSpec) -> tuple[list[str], tuple[float, ...]]:
    from amsfe_sym.codegen.preflight import modelled_joints

    joints = modelled_joints(spec)
    Ks = spec.actuators.Ks
    if joints is None or Ks is None or len(Ks) != len(joints):
        raise ConfigError(
            describe(
                f"[axes] {_STIFFNESS!r} on robot {spec.name!r}",
                "a robot spec with [model] joints and one [actuators] Ks per joint",
                f"joints {joints}, Ks {Ks}",
                "give the robot's [actuators] Ks explicitly",
            )
        )
    return joints, Ks


def derive_spec(spec: RobotSpec, values: Mapping[str, float]) -> RobotSpec:
    """``spec`` with the ``robot.*`` axis ``values`` applied, named ``<name>-r<hash>``.

    Args:
        spec: The robot's spec (of the scenario's ``robot``).
        values: Axis key -> value (``robot.theta.NAME.true`` [the parameter's unit],
            ``robot.theta.NAME.initial``, ``robot.stiffness_error`` [-]).

    Raises:
        ConfigError: an unknown key, or a stiffness error that leaves a spring <= 0.
    """
    if not values:
        return spec
    theta = list(spec.theta)
    if _STIFFNESS in values:
        e = float(values[_STIFFNESS])
        if not 1.0 + e > 0.0:
            raise ConfigError(
                describe(_STIFFNESS, "a relative error > -1", repr(e), "use e.g. -0.5 .. 1.0")
            )
        joints, Ks = _stiffness(spec)
        bound = {t.target: i for i, t in enumerate(theta) if t.kind == "joint_stiffness"}
        for joint, k in zip(joints, Ks, strict=True):
            if joint in bound:
                t = theta[bound[joint]]
                theta[bound[joint]] = replace(t, true=t.initial * (1.0 + e))
            else:
                theta.append(ThetaSpec(f"Ks_{joint}", "joint_stiffness", joint, k * (1 + e), k))
    for key, v in values.items():
        if key == _STIFFNESS:
            continue
        parts = key.split(".")
        idx = [i for i, t in enumerate(theta) if len(parts) == 4 and t.name == parts[2]]
        if (
            len(parts) != 4
            or parts[1] != "theta"
            or not idx
            or parts[3]
            not in (
                "true",
                "initial",
            )
        ):
            raise _unknown(key, spec)
        t = theta[idx[0]]
        theta[idx[0]] = (
            replace(t, true=float(v)) if parts[3] == "true" else replace(t, initial=float(v))
        )
    tag = hashlib.sha256(json.dumps(dict(values), sort_keys=True).encode()).hexdigest()[:10]
    return replace(spec, name=f"{spec.name}_r{tag}", theta=tuple(theta))
