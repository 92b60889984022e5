"""The modelled joints of a Pinocchio model and the default tracked frame."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from amsfe_sym.errors import UnsupportedJointError, describe
from amsfe_sym.load.types import JointInfo, JointKind

__all__ = ["chain_tip", "joint_info"]


def joint_info(model: pin.Model, jid: int) -> JointInfo:
    j = model.joints[jid]
    short = j.shortname()
    name = model.names[jid]
    data = j.createData()
    j.calc(data, pin.neutral(model)[j.idx_q : j.idx_q + j.nq])
    S = np.array(data.S).reshape(6)
    if short.startswith("JointModelR") and j.nv == 1:
        kind: JointKind = "continuous" if j.nq == 2 else "revolute"
        axis = S[3:]
    elif short.startswith("JointModelP") and not short.startswith("JointModelPlanar") and j.nv == 1:
        kind = "prismatic"
        axis = S[:3]
    else:  # pragma: no cover - _validate_urdf refuses these first
        raise UnsupportedJointError(
            describe(f"joint {name!r}", "revolute, continuous or prismatic", short, "make it fixed")
        )
    axis = axis / np.linalg.norm(axis)
    return JointInfo(
        name=name,
        kind=kind,
        axis=(float(axis[0]), float(axis[1]), float(axis[2])),
        pin_id=jid,
        idx_q=j.idx_q,
        idx_v=j.idx_v,
    )


def chain_tip(model: pin.Model) -> str:
    """The deepest body frame of the last joint (the 'tip of the chain')."""
    last = model.njoints - 1
    best = None
    for f in model.frames:
        if f.parentJoint == last and f.type in (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT):
            best = f.name
    return best if best is not None else model.names[last]
