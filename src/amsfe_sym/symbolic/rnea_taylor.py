"""Time derivatives of the inverse dynamics along a trajectory, by one recursive pass.

``tau(t) = RNEA(q(t), qd(t), qdd(t), theta)`` and its first two time derivatives, given the
trajectory's derivatives up to the snap: the recursive Newton-Euler algorithm run on
second-order Taylor polynomials ("jets" ``[x, dx/dt, d2x/dt2]``) instead of numbers.  Every
bilinear operation ``f(a, b)`` of the recursion (rotations of motions and forces, cross
products, ...) becomes ``[f(a0, b0), f(a1, b0) + f(a0, b1), f(a2, b0) + 2 f(a1, b1) + f(a0,
b2)]`` (Leibniz), linear ones act on each coefficient, and a joint's rotation enters through
the derivatives of its angle and cross products with its constant axis (``_JointJet``).
This is what nested forward-mode AD computes, without its redundant mixed terms:
``control_motor_reference`` is about a third smaller (Panda 7.8k -> 5.0k
instructions, a chain of 12 joints 12.6k -> 8.6k).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.spatial import Placement, cross, force_cross, inertia_times, motion_cross

__all__ = ["rnea_jet"]

Jet = list[ca.SX]  # [x, dx/dt, d2x/dt2]


def _bil(f: Callable[[ca.SX, ca.SX], ca.SX], a: Jet, b: Jet) -> Jet:
    """The jet of a bilinear ``f(a, b)`` (Leibniz rule)."""
    return [
        f(a[0], b[0]),
        f(a[1], b[0]) + f(a[0], b[1]),
        f(a[2], b[0]) + 2 * f(a[1], b[1]) + f(a[0], b[2]),
    ]


def _lin(f: Callable[[ca.SX], ca.SX], a: Jet) -> Jet:
    return [f(x) for x in a]


def _add(a: Jet, b: Jet) -> Jet:
    return [x + y for x, y in zip(a, b, strict=True)]


def _const(x: ca.SX) -> Jet:
    return [x, ca.SX.zeros(x.shape), ca.SX.zeros(x.shape)]


class _JointJet:
    """The joint frame in its parent's frame along the trajectory: ``R(t) = R0 rod(q(t))``
    for a revolute joint, whose time derivatives are ``R' = q' R K`` and ``R'' = (q'' K +
    q'^2 K^2) R`` with ``K = [axis]x`` on the right, so a rotated jet costs three products
    with ``R`` at ``q`` (shared with the kinematics) and cross products with the constant
    axis; ``p(t) = p0 + R0 axis q(t)`` for a prismatic one (``R`` constant)."""

    def __init__(self, tree: RigidBodyTree, k: int, X: Placement, q: Jet) -> None:
        b = tree.bodies[k]
        self.R = X.R
        self.q = q
        if b.kind == "prismatic":
            d = ca.mtimes(b.placement.R, ca.SX(ca.DM(b.axis.reshape(3, 1))))
            self.K: ca.SX | None = None
            self.p = [X.p, d * q[1], d * q[2]]
        else:
            a = np.asarray(b.axis, dtype=float)
            self.K = ca.SX(ca.DM([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]))
            self.p = _const(X.p)

    def rot_t(self, u: Jet) -> Jet:
        """Jet of ``R^T u``."""
        y = [ca.mtimes(self.R.T, x) for x in u]
        if self.K is None:
            return y
        K, q1, q2 = self.K, self.q[1], self.q[2]
        Ky0 = ca.mtimes(K, y[0])
        return [
            y[0],
            y[1] - q1 * Ky0,
            y[2] - 2 * q1 * ca.mtimes(K, y[1]) - q2 * Ky0 + q1 * q1 * ca.mtimes(K, Ky0),
        ]

    def rot(self, f: Jet) -> Jet:
        """Jet of ``R f``."""
        if self.K is None:
            return [ca.mtimes(self.R, x) for x in f]
        K, q1, q2 = self.K, self.q[1], self.q[2]
        Kf0 = ca.mtimes(K, f[0])
        g = [
            f[0],
            f[1] + q1 * Kf0,
            f[2] + 2 * q1 * ca.mtimes(K, f[1]) + q2 * Kf0 + q1 * q1 * ca.mtimes(K, Kf0),
        ]
        return [ca.mtimes(self.R, x) for x in g]


def _act_inv(X: _JointJet, m: Jet) -> Jet:
    """Jet of ``motion_act_inv((R, p), m)``."""
    w = _lin(lambda x: x[3:6], m)
    u = _add(_lin(lambda x: x[0:3], m), _lin(lambda x: -x, _bil(cross, X.p, w)))
    return [ca.vertcat(lin, ang) for lin, ang in zip(X.rot_t(u), X.rot_t(w), strict=True)]


def _act_force(X: _JointJet, f: Jet) -> Jet:
    """Jet of ``force_act((R, p), f)``."""
    fl = X.rot(_lin(lambda x: x[0:3], f))
    fa = _add(X.rot(_lin(lambda x: x[3:6], f)), _bil(cross, X.p, fl))
    return [ca.vertcat(x, y) for x, y in zip(fl, fa, strict=True)]


def rnea_jet(tree: RigidBodyTree, q: Jet, qd: Jet, qdd: Jet, theta: ca.SX) -> Jet:
    """``[tau, dtau/dt, d2tau/dt2]`` of ``tau = RNEA(q, qd, qdd, theta)`` with gravity, for
    the jets ``q = [q, qd, qdd]``, ``qd = [qd, qdd, jerk]``, ``qdd = [qdd, jerk, snap]``
    (theta constant).  Equal to :meth:`RigidBodyTree.rnea` and its AD time derivatives
    (tests/test_rnea_derivatives.py)."""
    n = tree.n
    pis = tree.inertia_params(theta)
    a0 = _const(ca.SX(ca.DM(np.concatenate([-tree.gravity, np.zeros(3)]))))
    Xq = tree.joint_transforms(q[0])
    X: list[_JointJet] = []
    v: list[Jet] = []
    a: list[Jet] = []
    f: list[Jet] = []
    for k, b in enumerate(tree.bodies):
        S = tree._subspace(k)
        Xk = _JointJet(tree, k, Xq[k], [q[i][k] for i in range(3)])
        X.append(Xk)
        vJ = [S * qd[i][k] for i in range(3)]
        Sa = [S * qdd[i][k] for i in range(3)]
        if b.parent < 0:
            vk = vJ
            ak = _add(_act_inv(Xk, a0), Sa)
        else:
            vk = _add(_act_inv(Xk, v[b.parent]), vJ)
            ak = _add(_add(_act_inv(Xk, a[b.parent]), Sa), _bil(motion_cross, vk, vJ))
        v.append(vk)
        a.append(ak)
        hk = [inertia_times(pis[k], x) for x in vk]
        fk = _add([inertia_times(pis[k], x) for x in ak], _bil(force_cross, vk, hk))
        f.append(fk)
    tau: list[list[ca.SX]] = [[ca.SX(0)] * n for _ in range(3)]
    for k in reversed(range(n)):
        b = tree.bodies[k]
        S = tree._subspace(k)
        for i in range(3):
            tau[i][k] = ca.dot(S, f[k][i])
        if b.parent >= 0:
            f[b.parent] = _add(f[b.parent], _act_force(X[k], f[k]))
    return [ca.vertcat(*t) for t in tau]
