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
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.errors import ModelError, SpecError, UnsupportedJointError, UrdfError, describe
from amsfe_sym.spec import RobotSpec, ThetaSpec, load_spec
from amsfe_sym.urdf_topology import check_topology

__all__ = ["CameraModel", "JointInfo", "Robot", "ThetaBinding", "load_robot"]

log = logging.getLogger(__name__)

JointKind = Literal["revolute", "continuous", "prismatic"]
_SUPPORTED_URDF_TYPES = {"revolute", "continuous", "prismatic", "fixed"}
#: Default actuator constants for a bare URDF (documented in docs/robot-spec.md).
DEFAULT_KS, DEFAULT_MM, DEFAULT_FM = 1000.0, 0.1, 1.0
_INERTIA_TOL = 1e-9


@dataclass(frozen=True)
class JointInfo:
    """One modelled joint: name, kind, unit axis in its own frame, Pinocchio indices."""

    name: str
    kind: JointKind
    axis: tuple[float, float, float]
    pin_id: int
    idx_q: int
    idx_v: int


@dataclass(frozen=True)
class CameraModel:
    """Resolved pinhole camera.

    Attributes:
        K: Intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] [px].
        R_cw: Rotation world -> camera (rows: camera x right, y down, z forward).
        position: Camera centre in the world frame [m].
        width, height: Image size [px].
        period, delay: l and d in steps (eq. 11).
    """

    K: NDArray[np.float64]
    R_cw: NDArray[np.float64]
    position: NDArray[np.float64]
    width: int
    height: int
    period: int
    delay: int

    def project(self, r_world: NDArray[np.float64]) -> NDArray[np.float64]:
        """Independent numpy pinhole projection of a world point [m] to pixels (eq. 6)."""
        pc = self.R_cw @ (np.asarray(r_world, dtype=float) - self.position)
        return np.array(
            [
                self.K[0, 0] * pc[0] / pc[2] + self.K[0, 2],
                self.K[1, 1] * pc[1] / pc[2] + self.K[1, 2],
            ]
        )


@dataclass(frozen=True)
class ThetaBinding:
    """How one unknown parameter enters the model.

    For mass-like kinds, the body inertia of Pinocchio joint ``pin_joint`` becomes
    ``nominal + (theta - origin) * unit`` where ``unit`` is a 10-vector of dynamic
    parameters (Pinocchio's ``toDynamicParameters`` order: m, m c, I at the joint origin),
    ``nominal`` is the URDF's (kept in the Pinocchio model) and ``origin`` is the value
    theta has in the URDF: 0 for a payload, the link's nominal mass for ``link_mass``.
    For ``joint_stiffness``, ``q_index`` is the joint whose Ks theta replaces.
    """

    spec: ThetaSpec
    pin_joint: int = 0
    unit: NDArray[np.float64] = field(default_factory=lambda: np.zeros(10))
    origin: float = 0.0
    q_index: int = -1

    @property
    def kind(self) -> str:
        return self.spec.kind


@dataclass(frozen=True)
class Robot:
    """A validated robot: reduced Pinocchio model plus everything the spec resolves to.

    The Pinocchio model's inertias are the URDF's: for every mass-like theta the body
    inertia is ``model.inertias[j] + sum_i (theta_i - origin_i) * unit_i`` (see
    :meth:`pin_model_at`).
    """

    spec: RobotSpec
    model: pin.Model
    joints: tuple[JointInfo, ...]
    tracked_frame: str
    tracked_frame_id: int
    tracked_offset: NDArray[np.float64]
    camera: CameraModel
    Ks: NDArray[np.float64]
    Mm: NDArray[np.float64]
    Fm: NDArray[np.float64]
    theta: tuple[ThetaBinding, ...]
    gravity: NDArray[np.float64]

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def n(self) -> int:
        """Number of modelled joints."""
        return len(self.joints)

    @property
    def p(self) -> int:
        """Number of unknown parameters."""
        return len(self.theta)

    @property
    def N(self) -> int:
        """State dimension 4n + p (eq. 2)."""
        return 4 * self.n + self.p

    @property
    def theta_true(self) -> NDArray[np.float64]:
        return np.array([t.spec.true for t in self.theta], dtype=float)

    @property
    def theta_initial(self) -> NDArray[np.float64]:
        return np.array([t.spec.initial for t in self.theta], dtype=float)

    def to_pin_q(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map one angle per joint to Pinocchio's configuration (cos, sin for continuous)."""
        qp = np.zeros(self.model.nq)
        for i, j in enumerate(self.joints):
            if j.kind == "continuous":
                qp[j.idx_q] = math.cos(q[i])
                qp[j.idx_q + 1] = math.sin(q[i])
            else:
                qp[j.idx_q] = q[i]
        return qp

    def pin_model_at(self, theta: Sequence[float] | NDArray[np.float64]) -> pin.Model:
        """A copy of the Pinocchio model with the mass-like parameters set to ``theta``."""
        model = self.model.copy()
        model.gravity = pin.Motion(np.concatenate([self.gravity, np.zeros(3)]))
        for b, th in zip(self.theta, theta, strict=True):
            if b.kind in ("payload_mass", "link_mass"):
                params = (
                    model.inertias[b.pin_joint].toDynamicParameters() + (th - b.origin) * b.unit
                )
                model.inertias[b.pin_joint] = pin.Inertia.FromDynamicParameters(params)
        return model

    def stiffness_at(self, theta: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
        """Ks [N m/rad] with the joint-stiffness parameters set to ``theta``."""
        ks = self.Ks.copy()
        for b, th in zip(self.theta, theta, strict=True):
            if b.kind == "joint_stiffness":
                ks[b.q_index] = th
        return ks


# --------------------------------------------------------------------------------------


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
    urdf = _validate_urdf(urdf_path, locked=set(spec.model.locked))
    try:
        full = pin.buildModelFromUrdf(str(urdf_path))
    except Exception as exc:  # Pinocchio raises plain RuntimeError / ValueError
        raise UrdfError(
            describe(str(urdf_path), "a URDF Pinocchio can parse", f"error {exc}", "fix the file")
        ) from exc
    link_inertias = _link_inertias(urdf)

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
    joints = tuple(_joint_info(model, i) for i in range(1, model.njoints))
    n = len(joints)

    # --- tracked frame -------------------------------------------------------------------
    frame = spec.tracked.frame or _chain_tip(model)
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
    Ks = _per_joint(spec.actuators.Ks, DEFAULT_KS, n, "Ks", spec)
    Mm = _per_joint(spec.actuators.Mm, DEFAULT_MM, n, "Mm", spec)
    Fm = _per_joint(spec.actuators.Fm, DEFAULT_FM, n, "Fm", spec)
    if spec.actuators.Ks is None:
        Ks = _default_stiffness(model, joints, Mm, spec.model.T)

    # --- theta ---------------------------------------------------------------------------
    bindings = tuple(_bind_theta(t, model, joints, link_inertias, spec) for t in spec.theta)
    gravity = np.array(spec.model.gravity, dtype=float)

    robot_obj = Robot(
        spec=spec,
        model=model,
        joints=joints,
        tracked_frame=frame,
        tracked_frame_id=frame_id,
        tracked_offset=np.array(spec.tracked.offset, dtype=float),
        camera=_camera(spec, model, frame_id),
        Ks=Ks,
        Mm=Mm,
        Fm=Fm,
        theta=bindings,
        gravity=gravity,
    )
    _check_mass_matrix(robot_obj)
    return robot_obj


# --------------------------------------------------------------------------------------
# URDF validation (before Pinocchio, which accepts several invalid things silently)


def _validate_urdf(path: Path, locked: set[str] | frozenset[str] = frozenset()) -> Any:
    """Check XML, joint types, mimic, links, axes, masses and inertias; return yourdfpy's URDF.

    Order matters: a strict XML parse first (yourdfpy falls back to a recovering parser and
    returns a robot without joints on malformed XML), then the joints' links (yourdfpy fails
    with a bare ``list.remove`` error on a missing one), then yourdfpy's own parse and
    ``validate()``, then the physical checks on its objects, which it does not make.
    A ``<mimic>`` tag is accepted on fixed joints and on joints the spec locks.
    """
    import yourdfpy

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise UrdfError(
            describe(str(path), "well-formed XML", f"a parse error ({exc})", "fix the XML syntax")
        ) from exc
    if root.tag != "robot":
        raise UrdfError(
            describe(str(path), "a <robot> root element", f"<{root.tag}>", "is this a URDF?")
        )
    links = {ln.get("name") for ln in root.findall("link")}
    if not links:
        raise UrdfError(describe(str(path), "at least one <link>", "none", "add links"))
    for j in root.findall("joint"):
        name = j.get("name", "?")
        for tag in ("parent", "child"):
            el = j.find(tag)
            link = None if el is None else el.get("link")
            if link not in links:
                raise UrdfError(
                    describe(
                        f"{path}: joint {name!r} <{tag}>",
                        "the name of a <link> in the file",
                        repr(link),
                        "add the link or fix the name",
                    )
                )
    check_topology(root, path)  # one tree: before urdfdom/yourdfpy's misleading messages
    try:
        urdf = yourdfpy.URDF.load(
            str(path),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
        valid = urdf.validate()
    except Exception as exc:  # yourdfpy raises plain ValueError / KeyError / lxml errors
        raise UrdfError(
            describe(str(path), "a URDF yourdfpy can parse", f"error {exc!r}", "fix the file")
        ) from exc
    if not valid:
        raise UrdfError(
            describe(
                str(path),
                "a URDF passing yourdfpy's validate()",
                "a failed check",
                "see yourdfpy's log messages above",
            )
        )
    for j in urdf.robot.joints:
        where = f"{path}: joint {j.name!r}"
        if j.type not in _SUPPORTED_URDF_TYPES:
            raise UnsupportedJointError(
                describe(
                    where,
                    "type revolute, continuous, prismatic or fixed",
                    f"type {j.type!r}",
                    "make it fixed, or lock/replace it; floating bases are not modelled",
                )
            )
        if j.type != "fixed" and j.name not in locked and j.mimic is not None:
            raise UnsupportedJointError(
                describe(
                    where,
                    "independent joints",
                    "a <mimic> joint",
                    "remove <mimic> (model it as its own joint), make it fixed or lock it",
                )
            )
        if j.type != "fixed" and j.axis is not None and float(np.linalg.norm(j.axis)) < 1e-12:
            raise UrdfError(
                describe(
                    f"{where} <axis>",
                    "a non-zero axis",
                    "xyz = 0 0 0",
                    'give the joint axis, e.g. xyz="0 0 1"',
                )
            )
    for ln in urdf.robot.links:
        if ln.inertial is None:
            continue
        where = f"{path}: link {ln.name!r}"
        mass = float(ln.inertial.mass if ln.inertial.mass is not None else 0.0)
        if not math.isfinite(mass) or mass < 0:
            raise UrdfError(
                describe(f"{where} <mass>", "a finite mass >= 0 [kg]", f"{mass}", "fix the mass")
            )
        if ln.inertial.inertia is not None:
            _check_inertia(np.asarray(ln.inertial.inertia, dtype=float), where)
    return urdf


def _check_inertia(inertia: NDArray[np.float64], where: str) -> None:
    """Positive semi-definite and principal moments satisfying the triangle inequality."""
    if not np.all(np.isfinite(inertia)):
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "finite values",
                "inf or NaN",
                "write the six inertia entries as finite numbers [kg m^2]",
            )
        )
    eig = np.linalg.eigvalsh(inertia)
    scale = max(float(np.max(np.abs(eig))), 1e-12)
    if eig[0] < -_INERTIA_TOL * scale:
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "a positive semi-definite tensor",
                f"principal moments {np.round(eig, 9).tolist()}",
                "check signs of the products of inertia (URDF stores +ixy, not -ixy)",
            )
        )
    a, b, c = eig
    if a + b < c - _INERTIA_TOL * scale:
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "principal moments with I1 + I2 >= I3 (triangle inequality)",
                f"{np.round(eig, 9).tolist()}",
                "no rigid body has these moments; recompute the inertia tensor",
            )
        )


def _link_inertias(urdf: Any) -> dict[str, tuple[float, NDArray[np.float64], NDArray[np.float64]]]:
    """Each link's own (mass [kg], centre of mass [m], inertia about it in the link frame)."""
    out = {}
    for ln in urdf.robot.links:
        if ln.inertial is None:
            continue
        mass = float(ln.inertial.mass or 0.0)
        origin = np.eye(4) if ln.inertial.origin is None else np.asarray(ln.inertial.origin)
        R = origin[:3, :3]
        inertia = (
            np.zeros((3, 3)) if ln.inertial.inertia is None else np.asarray(ln.inertial.inertia)
        )
        out[ln.name] = (mass, origin[:3, 3].copy(), R @ inertia @ R.T)
    return out


# --------------------------------------------------------------------------------------
# model pieces


def _joint_info(model: pin.Model, jid: int) -> JointInfo:
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


def _chain_tip(model: pin.Model) -> str:
    """The deepest body frame of the last joint (the 'tip of the chain')."""
    last = model.njoints - 1
    best = None
    for f in model.frames:
        if f.parentJoint == last and f.type in (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT):
            best = f.name
    return best if best is not None else model.names[last]


def _default_stiffness(
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


def _per_joint(
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


def _bind_theta(
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


def _workspace(
    model: pin.Model, frame_id: int, offset: tuple[float, float, float], count: int = 256
) -> tuple[NDArray[np.float64], float]:
    """Centre [m] and radius [m] of the tracked point's reachable set, from random q."""
    data = model.createData()
    rng = np.random.default_rng(0)  # deterministic: the default camera is part of the model
    pts = []
    for _ in range(count):
        q = pin.neutral(model)
        for jid in range(1, model.njoints):
            j = model.joints[jid]
            if j.nq == 2:  # continuous: (cos, sin)
                a = rng.uniform(-math.pi, math.pi)
                q[j.idx_q], q[j.idx_q + 1] = math.cos(a), math.sin(a)
            else:
                lo, hi = model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]
                lo = max(lo, -math.pi) if np.isfinite(lo) else -math.pi
                hi = min(hi, math.pi) if np.isfinite(hi) else math.pi
                q[j.idx_q] = rng.uniform(lo, hi) if hi > lo else 0.0
        pin.framesForwardKinematics(model, data, q)
        pts.append(data.oMf[frame_id].act(np.asarray(offset, dtype=float)))
    P = np.array(pts)
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0))
    radius = float(np.max(np.linalg.norm(P - centre, axis=1)))
    return centre, max(radius, 0.05)


def _camera(spec: RobotSpec, model: pin.Model, frame_id: int) -> CameraModel:
    """Resolve the camera.

    Defaults (bare URDF, or keys left out): the camera looks at the centre of the tracked
    point's workspace (sampled at random q) from 3 workspace radii away along -y, and the
    focal length puts the whole workspace sphere inside 90 % of the shorter image side.
    """
    c = spec.camera
    if c.look_at is None or c.position is None or c.fx is None:  # a default needs the workspace
        centre, radius = _workspace(model, frame_id, spec.tracked.offset)
    look_at = np.array(c.look_at, dtype=float) if c.look_at is not None else centre
    up = np.array(c.up, dtype=float)
    if c.position is not None:
        position = np.array(c.position, dtype=float)
    else:
        position = look_at + np.array([0.0, -3.0 * radius, 0.0])
    fwd = look_at - position
    if np.linalg.norm(fwd) < 1e-9:
        raise SpecError(
            describe(
                f"{spec.spec_path}: [camera]", "look_at != position", "equal points", "move one"
            )
        )
    z = fwd / np.linalg.norm(fwd)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise SpecError(
            describe(
                f"{spec.spec_path}: [camera] up",
                "a direction not parallel to the optical axis",
                str(up.tolist()),
                "choose another up vector",
            )
        )
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R_cw = np.vstack([x, y, z])
    if c.fx is not None:
        fx = c.fx
    else:
        # the sphere (centre, radius) seen from `position`: its farthest image offset is
        # f * tan(angle to centre + half-angle of the sphere)
        to_c = centre - position
        dist = float(np.linalg.norm(to_c))
        ang = math.acos(float(np.clip(np.dot(to_c / max(dist, 1e-12), z), -1.0, 1.0)))
        half_angle = math.asin(min(radius / max(dist, 1e-12), 0.99))
        fx = 0.45 * min(c.width, c.height) / math.tan(min(ang + half_angle, 1.4))
    fy = c.fy if c.fy is not None else fx
    cx = c.cx if c.cx is not None else c.width / 2.0
    cy = c.cy if c.cy is not None else c.height / 2.0
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return CameraModel(
        K=K,
        R_cw=R_cw,
        position=position,
        width=c.width,
        height=c.height,
        period=c.period,
        delay=c.delay,
    )


def _check_mass_matrix(robot: Robot) -> None:
    """Refuse a modelled joint whose subtree has no mass or inertia (M singular)."""
    model = robot.pin_model_at(robot.theta_true)
    data = model.createData()
    n = robot.n
    # subtree test first: a joint whose subtree has zero mass and zero rotational inertia
    for j in robot.joints:
        sub = [k for k in range(1, model.njoints) if _is_ancestor(model, j.pin_id, k)]
        total = sum(model.inertias[k].mass for k in sub)
        rot = sum(float(np.abs(model.inertias[k].inertia).sum()) for k in sub)
        if total <= 0 and rot <= 0:
            raise ModelError(
                describe(
                    f"{robot.spec.urdf}: joint {j.name!r}",
                    "some mass or inertia in the subtree the joint moves",
                    "a massless subtree, so M(q) is singular",
                    "add the links' <inertial> data, or lock the joint (--lock / [model] locked)",
                )
            )
    rng = np.random.default_rng(0)
    worst = math.inf
    for _ in range(8):
        q = rng.uniform(-math.pi, math.pi, n)
        M = pin.crba(model, data, robot.to_pin_q(q))
        M = np.triu(M) + np.triu(M, 1).T
        worst = min(worst, float(np.linalg.eigvalsh(M)[0]))
    if worst <= 1e-12 * max(1.0, float(np.abs(M).max())):
        diag = np.diag(M)
        j = robot.joints[int(np.argmin(diag))]
        raise ModelError(
            describe(
                f"{robot.spec.urdf}: mass matrix",
                "positive definite M(q)",
                f"smallest eigenvalue {worst:.3g} (weakest joint {j.name!r})",
                "a modelled joint moves no inertia about its axis; lock it or fix <inertial>",
            )
        )


def _is_ancestor(model: pin.Model, a: int, k: int) -> bool:
    while k > 0:
        if k == a:
            return True
        k = model.parents[k]
    return False
