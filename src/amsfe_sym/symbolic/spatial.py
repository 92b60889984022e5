"""Spatial algebra on CasADi SX, in Pinocchio's conventions.

Motions are 6-vectors ``[v; w]`` (linear first), forces ``[f; tau]``.  A placement
``X = (R, p)`` maps child coordinates to parent ones (Pinocchio's ``liMi``).  Rigid-body
inertias are Pinocchio's 10 dynamic parameters ``[m, h (= m c), Ixx, Ixy, Iyy, Ixz, Iyz,
Izz]`` with the rotational inertia about the body frame's origin; they enter the model
linearly, which is how the unknown parameters theta are bound (see ``amsfe_sym.load``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Placement",
    "cross",
    "force_act",
    "force_cross",
    "inertia_times",
    "motion_act_inv",
    "motion_cross",
    "rodrigues",
]

SXLike = ca.SX


def cross(a: SXLike, b: SXLike) -> SXLike:
    """3-vector cross product a x b."""
    return ca.vertcat(
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


@dataclass(frozen=True)
class Placement:
    """A rigid placement (R, p): x_parent = R x_child + p."""

    R: SXLike
    p: SXLike

    @staticmethod
    def constant(R: NDArray[np.float64], p: NDArray[np.float64]) -> Placement:
        return Placement(ca.SX(ca.DM(R)), ca.SX(ca.DM(np.asarray(p).reshape(3, 1))))

    def __mul__(self, other: Placement) -> Placement:
        return Placement(ca.mtimes(self.R, other.R), ca.mtimes(self.R, other.p) + self.p)

    def act_point(self, x: SXLike) -> SXLike:
        """Child-frame point -> parent-frame point."""
        return ca.mtimes(self.R, x) + self.p


def rodrigues(axis: NDArray[np.float64], angle: SXLike) -> SXLike:
    """Rotation by ``angle`` [rad] about the unit ``axis`` (Rodrigues' formula)."""
    a = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    s, c = ca.sin(angle), ca.cos(angle)
    return ca.SX(ca.DM(np.eye(3))) + s * ca.SX(ca.DM(K)) + (1 - c) * ca.SX(ca.DM(K @ K))


def motion_act_inv(X: Placement, m: SXLike) -> SXLike:
    """Parent-frame motion -> child-frame motion (Pinocchio ``actInv``)."""
    v, w = m[0:3], m[3:6]
    Rt = X.R.T
    return ca.vertcat(ca.mtimes(Rt, v - cross(X.p, w)), ca.mtimes(Rt, w))


def force_act(X: Placement, f: SXLike) -> SXLike:
    """Child-frame force -> parent-frame force (Pinocchio ``act``)."""
    fl = ca.mtimes(X.R, f[0:3])
    return ca.vertcat(fl, ca.mtimes(X.R, f[3:6]) + cross(X.p, fl))


def motion_cross(v: SXLike, m: SXLike) -> SXLike:
    """Motion cross product v x m."""
    return ca.vertcat(cross(v[3:6], m[0:3]) + cross(v[0:3], m[3:6]), cross(v[3:6], m[3:6]))


def force_cross(v: SXLike, f: SXLike) -> SXLike:
    """Force cross product v x* f."""
    return ca.vertcat(cross(v[3:6], f[0:3]), cross(v[3:6], f[3:6]) + cross(v[0:3], f[0:3]))


def inertia_times(pi: SXLike, m: SXLike) -> SXLike:
    """Spatial inertia (dynamic parameters ``pi``) times motion ``m``.

    Returns ``[m v - h x w; h x v + I w]`` for ``m = [v; w]``.
    """
    mass, h = pi[0], pi[1:4]
    I_o = ca.vertcat(
        ca.horzcat(pi[4], pi[5], pi[7]),
        ca.horzcat(pi[5], pi[6], pi[8]),
        ca.horzcat(pi[7], pi[8], pi[9]),
    )
    v, w = m[0:3], m[3:6]
    return ca.vertcat(mass * v - cross(h, w), cross(h, v) + ca.mtimes(I_o, w))


def inertia_act(X: Placement, pi: SXLike) -> SXLike:
    """A body's 10 dynamic parameters expressed in its parent's frame (Pinocchio
    ``Inertia::se3Action``): mass unchanged, ``h' = R h + m p``, and about the parent's
    origin ``I' = R I R^T - [R h]x [p]x - [p]x [R h]x - m [p]x [p]x`` (no division by the
    mass, so a massless or theta-weighted body is fine)."""
    m, h = pi[0], pi[1:4]
    rot = ca.vertcat(
        ca.horzcat(pi[4], pi[5], pi[7]),
        ca.horzcat(pi[5], pi[6], pi[8]),
        ca.horzcat(pi[7], pi[8], pi[9]),
    )
    Rh = ca.mtimes(X.R, h)
    px, Rhx = ca.skew(X.p), ca.skew(Rh)
    rot2 = (
        ca.mtimes([X.R, rot, X.R.T])
        - ca.mtimes(Rhx, px)
        - ca.mtimes(px, Rhx)
        - m * ca.mtimes(px, px)
    )
    h2 = Rh + m * X.p
    return ca.vertcat(m, h2, rot2[0, 0], rot2[0, 1], rot2[1, 1], rot2[0, 2], rot2[1, 2], rot2[2, 2])
