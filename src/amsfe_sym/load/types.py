"""What loading a robot produces: the validated :class:`Robot` (Pinocchio model, modelled
joints, theta bindings, camera, actuator constants) and its parts."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from amsfe_sym.load.spec import RobotSpec, ThetaSpec

__all__ = ["CameraModel", "JointInfo", "JointKind", "Robot", "ThetaBinding"]

JointKind = Literal["revolute", "continuous", "prismatic"]


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
    #: Motor torque limit per joint [N m] (inf: none): the spec's, else the URDF's effort.
    u_max: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

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
