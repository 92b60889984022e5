"""Load a robot: validate the URDF (XML, yourdfpy, physics), build the Pinocchio model,
resolve the spec.

This is the first stage of the one-way pipeline (load -> symbolic -> codegen -> runtime).
It refuses everything the later stages cannot model, with one clear error naming the file,
the element and the fix, before anything is written anywhere:

- joint types other than revolute, continuous, prismatic and fixed (floating, planar,
  spherical) and mimic joints (:class:`~amsfe_sym.errors.UnsupportedJointError`);
- malformed XML, dangling links, zero joint axes, negative masses, inertia tensors that are
  not positive semi-definite or break the triangle inequality
  (:class:`~amsfe_sym.errors.UrdfError`);
- a modelled joint whose whole subtree carries no mass or inertia, so that M(q) is singular
  (:class:`~amsfe_sym.errors.ModelError`);
- unknown joint or frame names in the spec (:class:`~amsfe_sym.errors.SpecError`).

Pinocchio stores a continuous joint as (cos, sin); amsfe_sym uses one angle per joint, so
:meth:`Robot.to_pin_q` converts.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from amsfe_sym.errors import ModelError, SpecError, UrdfError, describe
from amsfe_sym.load.camera import resolve_camera
from amsfe_sym.load.checks import check_mass_matrix
from amsfe_sym.load.joints import chain_tip, joint_info
from amsfe_sym.load.parameters import (
    DEFAULT_FM,
    DEFAULT_KS,
    DEFAULT_MM,
    bind_theta,
    default_stiffness,
    per_joint,
)
from amsfe_sym.load.spec import RobotSpec, load_spec
from amsfe_sym.load.types import CameraModel, JointInfo, Robot, ThetaBinding
from amsfe_sym.load.urdf import link_inertias, validate_urdf

__all__ = ["CameraModel", "JointInfo", "Robot", "ThetaBinding", "load_robot"]

log = logging.getLogger(__name__)


def load_robot(robot: str | Path | RobotSpec, lock: dict[str, float] | None = None) -> Robot:
    """Validate and load a robot.

    Args:
        robot: A shipped robot name, a robot folder, a ``robot.toml``, a URDF path, or a
            :class:`RobotSpec`.
        lock: Extra joints to hold fixed, name -> value [rad or m].

    Returns:
        The validated :class:`Robot`.

    Raises:
        UrdfError, UnsupportedJointError, ModelError, SpecError: see the module docstring.
    """
    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    if lock:
        spec = spec.with_locked(lock)
    urdf_path = spec.urdf
    urdf = validate_urdf(urdf_path, locked=set(spec.model.locked))
    try:
        full = pin.buildModelFromUrdf(str(urdf_path))
    except Exception as exc:  # Pinocchio raises plain RuntimeError / ValueError
        raise UrdfError(
            describe(str(urdf_path), "a URDF Pinocchio can parse", f"error {exc}", "fix the file")
        ) from exc
    inertias = link_inertias(urdf)

    # --- classify joints, decide which are modelled and which locked --------------------
    movable = [full.names[i] for i in range(1, full.njoints)]
    for name in list(spec.model.locked) + list(spec.model.joints or ()):
        if name not in movable:
            raise SpecError(
                describe(
                    f"{spec.spec_path or urdf_path}: joint {name!r}",
                    f"a movable joint of {urdf_path.name} ({movable})",
                    "no such movable joint",
                    "fix the name in [model] joints / locked or --lock",
                )
            )
    if spec.model.joints is not None:
        modelled = [m for m in movable if m in spec.model.joints]
        if modelled != list(spec.model.joints):
            raise SpecError(
                describe(
                    f"{spec.spec_path}: [model] joints",
                    f"joints in the model's tree order {modelled}",
                    str(list(spec.model.joints)),
                    "list them in that order (it is the order of q)",
                )
            )
    else:
        modelled = [m for m in movable if m not in spec.model.locked]
    to_lock = [m for m in movable if m not in modelled]
    if not modelled:
        raise ModelError(
            describe(str(urdf_path), "at least one modelled joint", "none", "unlock a joint")
        )
    q_ref = pin.neutral(full)
    for name in to_lock:
        jid = full.getJointId(name)
        val = float(spec.model.locked.get(name, 0.0))
        j = full.joints[jid]
        if j.nq == 2:
            q_ref[j.idx_q], q_ref[j.idx_q + 1] = math.cos(val), math.sin(val)
        else:
            q_ref[j.idx_q] = val
        if name not in spec.model.locked:
            log.info("joint %s is not modelled: locked at 0", name)
    model = (
        pin.buildReducedModel(full, [full.getJointId(n) for n in to_lock], q_ref)
        if to_lock
        else full
    )
    joints = tuple(joint_info(model, i) for i in range(1, model.njoints))
    n = len(joints)

    # --- tracked frame -------------------------------------------------------------------
    frame = spec.tracked.frame or chain_tip(model)
    if not model.existFrame(frame):
        raise SpecError(
            describe(
                f"{spec.spec_path or urdf_path}: [tracked] frame",
                "a link or frame of the URDF",
                repr(frame),
                f"use one of {[f.name for f in model.frames][:20]}",
            )
        )
    frame_id = model.getFrameId(frame)

    # --- actuators -----------------------------------------------------------------------
    Ks = per_joint(spec.actuators.Ks, DEFAULT_KS, n, "Ks", spec)
    Mm = per_joint(spec.actuators.Mm, DEFAULT_MM, n, "Mm", spec)
    Fm = per_joint(spec.actuators.Fm, DEFAULT_FM, n, "Fm", spec)
    if spec.actuators.Ks is None:
        Ks = default_stiffness(model, joints, Mm, spec.model.T)
    effort = np.array([float(model.effortLimit[j.idx_v]) for j in joints])
    u_max = per_joint(spec.actuators.u_max, 0.0, n, "u_max", spec)
    if spec.actuators.u_max is None:  # the URDF's effort where it gives one (> 0)
        u_max = np.where(np.isfinite(effort) & (effort > 0), effort, np.inf)

    # --- theta ---------------------------------------------------------------------------
    bindings = tuple(bind_theta(t, model, joints, inertias, spec) for t in spec.theta)
    gravity = np.array(spec.model.gravity, dtype=float)

    robot_obj = Robot(
        spec=spec,
        model=model,
        joints=joints,
        tracked_frame=frame,
        tracked_frame_id=frame_id,
        tracked_offset=np.array(spec.tracked.offset, dtype=float),
        camera=resolve_camera(spec, model, frame_id),
        Ks=Ks,
        Mm=Mm,
        Fm=Fm,
        theta=bindings,
        gravity=gravity,
        u_max=u_max,
    )
    check_mass_matrix(robot_obj)
    return robot_obj
