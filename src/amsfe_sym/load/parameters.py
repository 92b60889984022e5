"""Actuator constants (spec values or defaults) and the binding of theta to the model."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.errors import SpecError, describe
from amsfe_sym.load.spec import RobotSpec, ThetaSpec
from amsfe_sym.load.types import JointInfo, ThetaBinding

__all__ = ["DEFAULT_FM", "DEFAULT_KS", "DEFAULT_MM", "bind_theta", "default_stiffness", "per_joint"]

#: Default actuator constants for a bare URDF (documented in docs/reference/robot-spec.md).
DEFAULT_KS, DEFAULT_MM, DEFAULT_FM = 1000.0, 0.1, 1.0


def default_stiffness(
    model: pin.Model, joints: tuple[JointInfo, ...], Mm: NDArray[np.float64], T: float
) -> NDArray[np.float64]:
    """Default Ks [N m/rad] when the spec gives none: 1000, lowered per joint so that the
    joint's link-against-motor mode keeps w T <= 0.5 (w^2 = Ks (1/J + 1/Mm), J the smallest
    diagonal entry of M seen at 32 random q); light wrists would otherwise make the discrete
    model diverge at T = 1 ms."""
    data = model.createData()
    rng = np.random.default_rng(0)
    J = np.full(len(joints), np.inf)
    for _ in range(32):
        q = pin.neutral(model)
        for j in joints:
            a = rng.uniform(-math.pi, math.pi)
            if j.kind == "continuous":
                q[j.idx_q], q[j.idx_q + 1] = math.cos(a), math.sin(a)
            elif j.kind == "revolute":
                q[j.idx_q] = a
        J = np.minimum(J, np.diag(pin.crba(model, data, q)))
    J = np.maximum(J, 1e-12)
    cap = (0.5 / T) ** 2 / (1.0 / J + 1.0 / Mm)
    return np.minimum(np.full(len(joints), DEFAULT_KS), cap)


def per_joint(
    values: tuple[float, ...] | None, default: float, n: int, what: str, spec: RobotSpec
) -> NDArray[np.float64]:
    if values is None:
        return np.full(n, default)
    if len(values) != n:
        raise SpecError(
            describe(
                f"{spec.spec_path}: [actuators] {what}",
                f"{n} values (one per modelled joint)",
                f"{len(values)}",
                "give one value per joint in [model] joints order",
            )
        )
    return np.array(values, dtype=float)


def bind_theta(
    t: ThetaSpec,
    model: pin.Model,
    joints: tuple[JointInfo, ...],
    link_inertias: dict[str, tuple[float, NDArray[np.float64], NDArray[np.float64]]],
    spec: RobotSpec,
) -> ThetaBinding:
    where = f"{spec.spec_path}: theta {t.name!r}"
    if t.kind == "joint_stiffness":
        names = [j.name for j in joints]
        if t.target not in names:
            raise SpecError(
                describe(
                    f"{where} target",
                    f"a modelled joint {names}",
                    repr(t.target),
                    "name one of the modelled joints as target",
                )
            )
        return ThetaBinding(spec=t, q_index=names.index(t.target))
    if not model.existFrame(t.target):
        raise SpecError(
            describe(
                f"{where} target",
                "a link or frame name",
                repr(t.target),
                "name a link of the URDF as target",
            )
        )
    frame = model.frames[model.getFrameId(t.target)]
    jid = frame.parentJoint
    if jid == 0:
        raise SpecError(
            describe(
                f"{where} target",
                "a frame that moves with a modelled joint",
                f"{t.target!r} fixed to the world",
                "a mass on the fixed base changes nothing; pick a moving link",
            )
        )
    if t.kind == "payload_mass":
        c = frame.placement.act(np.array(t.offset, dtype=float))
        unit = pin.Inertia(1.0, c, np.zeros((3, 3))).toDynamicParameters()
        return ThetaBinding(spec=t, pin_joint=jid, unit=np.asarray(unit, dtype=float))
    # link_mass: theta is the link's mass; its inertia scales with it, its com stays put.
    if t.target not in link_inertias or link_inertias[t.target][0] <= 0:
        raise SpecError(
            describe(
                f"{where} target",
                "a link with a positive nominal <mass> (its shape scales with theta)",
                repr(t.target),
                "pick a link with an <inertial>, or use payload_mass",
            )
        )
    m0, com, inertia = link_inertias[t.target]
    nominal = frame.placement.act(pin.Inertia(m0, com, inertia))
    unit = np.asarray(nominal.toDynamicParameters(), dtype=float) / m0
    return ThetaBinding(spec=t, pin_joint=jid, unit=unit, origin=m0)
