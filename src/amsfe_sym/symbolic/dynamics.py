"""Rigid-body kinematics and dynamics in CasADi SX, by walking Pinocchio's model tree.

The PyPI ``pin`` wheel has no ``pinocchio.casadi``, so this module rebuilds the recursive
Newton-Euler algorithm (Featherstone, RBDA ch. 5; Pinocchio's ``rnea``) on SX from the
model's parents, joint placements, joint axes and body inertias.  Everything is checked
against Pinocchio's numeric ``crba``/``nle``/``rnea`` and frame placements in the tests.

Conventions: q has one entry per modelled joint (a continuous joint is one angle), the
unknown parameters theta enter the body inertias linearly (``Robot.theta``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from amsfe_sym.load import Robot
from amsfe_sym.symbolic.spatial import (
    Placement,
    force_act,
    force_cross,
    inertia_act,
    inertia_times,
    motion_act_inv,
    motion_cross,
    rodrigues,
)

__all__ = ["RigidBodyTree"]


@dataclass(frozen=True)
class _Body:
    parent: int  # index into the body list, -1 for the world
    kind: str
    axis: NDArray[np.float64]
    placement: Placement  # joint frame in the parent joint frame at q = 0
    pi0: NDArray[np.float64]  # dynamic parameters of the theta-free inertia
    units: tuple[tuple[int, float, NDArray[np.float64]], ...]  # (theta index, origin, direction)


class RigidBodyTree:
    """The robot's kinematic tree as SX building blocks.

    Args:
        robot: A validated robot from :func:`amsfe_sym.load.load_robot`.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        model = robot.model
        self.n = robot.n
        self.p = robot.p
        bodies = []
        for k, j in enumerate(robot.joints):
            jid = j.pin_id
            if jid != k + 1:  # pragma: no cover - reduced models number joints 1..n
                raise AssertionError("unexpected Pinocchio joint numbering")
            pl = model.jointPlacements[jid]
            units = tuple(
                (i, b.origin, b.unit)
                for i, b in enumerate(robot.theta)
                if b.kind in ("payload_mass", "link_mass") and b.pin_joint == jid
            )
            bodies.append(
                _Body(
                    parent=model.parents[jid] - 1,
                    kind=j.kind,
                    axis=np.array(j.axis),
                    placement=Placement.constant(pl.rotation, pl.translation),
                    pi0=np.asarray(model.inertias[jid].toDynamicParameters(), dtype=float),
                    units=units,
                )
            )
        self.bodies = tuple(bodies)
        self.gravity = np.asarray(robot.gravity, dtype=float)

    # ---------------------------------------------------------------- kinematics
    def joint_transforms(self, q: ca.SX) -> list[Placement]:
        """liMi for every joint: the joint frame at q in its parent's frame."""
        out = []
        for k, b in enumerate(self.bodies):
            if b.kind == "prismatic":
                motion = Placement(ca.SX.eye(3), ca.SX(ca.DM(b.axis.reshape(3, 1))) * q[k])
            else:
                motion = Placement(rodrigues(b.axis, q[k]), ca.SX.zeros(3, 1))
            out.append(b.placement * motion)
        return out

    def world_placements(self, q: ca.SX) -> list[Placement]:
        """oMi for every joint."""
        local = self.joint_transforms(q)
        world: list[Placement] = []
        for k, b in enumerate(self.bodies):
            world.append(local[k] if b.parent < 0 else world[b.parent] * local[k])
        return world

    def frame_point(self, q: ca.SX, frame_id: int, offset: NDArray[np.float64]) -> ca.SX:
        """World position [m] of ``offset`` expressed in Pinocchio frame ``frame_id`` (eq. 7)."""
        model = self.robot.model
        frame = model.frames[frame_id]
        fp = Placement.constant(frame.placement.rotation, frame.placement.translation)
        point = ca.SX(ca.DM(np.asarray(offset, dtype=float).reshape(3, 1)))
        if frame.parentJoint == 0:
            return fp.act_point(point)
        oMi = self.world_placements(q)[frame.parentJoint - 1]
        return (oMi * fp).act_point(point)

    # ---------------------------------------------------------------- dynamics
    def inertia_params(self, theta: ca.SX) -> list[ca.SX]:
        """Each body's 10 dynamic parameters, with theta bound in."""
        out = []
        for b in self.bodies:
            pi = ca.SX(ca.DM(b.pi0))
            for i, origin, unit in b.units:
                pi = pi + (theta[i] - origin) * ca.SX(ca.DM(unit))
            out.append(pi)
        return out

    def _subspace(self, k: int) -> ca.SX:
        b = self.bodies[k]
        if b.kind == "prismatic":
            return ca.SX(ca.DM(np.concatenate([b.axis, np.zeros(3)])))
        return ca.SX(ca.DM(np.concatenate([np.zeros(3), b.axis])))

    def rnea(
        self, q: ca.SX, qd: ca.SX, qdd: ca.SX, theta: ca.SX, with_gravity: bool = True
    ) -> ca.SX:
        """Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q) (recursive Newton-Euler)."""
        X = self.joint_transforms(q)
        pis = self.inertia_params(theta)
        a0 = ca.SX(ca.DM(np.concatenate([-self.gravity, np.zeros(3)]))) if with_gravity else None
        v: list[ca.SX] = []
        a: list[ca.SX] = []
        f: list[ca.SX] = []
        for k, b in enumerate(self.bodies):
            S = self._subspace(k)
            vJ = S * qd[k]
            if b.parent < 0:
                vk = vJ
                ak = S * qdd[k] if a0 is None else motion_act_inv(X[k], a0) + S * qdd[k]
            else:
                vk = motion_act_inv(X[k], v[b.parent]) + vJ
                ak = motion_act_inv(X[k], a[b.parent]) + S * qdd[k] + motion_cross(vk, vJ)
            v.append(vk)
            a.append(ak)
            f.append(inertia_times(pis[k], ak) + force_cross(vk, inertia_times(pis[k], vk)))
        tau = [ca.SX(0)] * self.n
        for k in reversed(range(self.n)):
            b = self.bodies[k]
            tau[k] = ca.dot(self._subspace(k), f[k])
            if b.parent >= 0:
                f[b.parent] = f[b.parent] + force_act(X[k], f[k])
        return ca.vertcat(*tau)

    def mass_matrix(self, q: ca.SX, theta: ca.SX) -> ca.SX:
        """M(q, theta), n x n, by the composite rigid body algorithm (Featherstone, RBDA
        sec. 6.2; Pinocchio's ``crba``): one pass of the joint transforms shared by every
        column, the bodies' spatial inertias accumulated towards the root, then each joint's
        ``Ic_i S_i`` carried up its chain of ancestors.  On the Panda this is about a
        quarter of the expression of n RNEA columns (each recomputing the kinematics)."""
        X = self.joint_transforms(q)
        Ic = self.inertia_params(theta)  # composite inertias, as 10 parameters each
        for k in reversed(range(self.n)):
            parent = self.bodies[k].parent
            if parent >= 0:
                Ic[parent] = Ic[parent] + inertia_act(X[k], Ic[k])
        M = ca.SX.zeros(self.n, self.n)
        for i in range(self.n):
            F = inertia_times(Ic[i], self._subspace(i))  # Ic_i S_i, a force in frame i
            M[i, i] = ca.dot(self._subspace(i), F)
            j = i
            while self.bodies[j].parent >= 0:
                F = force_act(X[j], F)
                j = self.bodies[j].parent
                M[i, j] = M[j, i] = ca.dot(self._subspace(j), F)
        return M

    def bias(self, q: ca.SX, qd: ca.SX, theta: ca.SX) -> ca.SX:
        """b(q, qd, theta) = C(q, qd) qd + g(q), so that M qdd + b = tau (Pinocchio's nle)."""
        return self.rnea(q, qd, ca.SX.zeros(self.n, 1), theta, with_gravity=True)

    def gravity_torque(self, q: ca.SX, theta: ca.SX) -> ca.SX:
        """g(q, theta) = dV/dq."""
        zero = ca.SX.zeros(self.n, 1)
        return self.rnea(q, zero, zero, theta, with_gravity=True)
