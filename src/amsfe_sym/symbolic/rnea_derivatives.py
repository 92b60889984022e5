"""Analytic derivatives of the recursive Newton-Euler algorithm on SX (docs/explanation/codegen.md).

Carpentier and Mansard, "Analytical Derivatives of Rigid Body Dynamics Algorithms" (RSS
2018); Pinocchio's ``computeRNEADerivatives`` (``rnea-derivatives.hxx``).  One forward pass
and one backward pass over the tree, in the world frame, share the kinematics: every
quantity of body k is a 6-vector or a 6x6 matrix, and each entry of the n x n outputs is a
couple of 6-vector dot products, instead of n reverse-mode sweeps of the whole RNEA
expression (the bench chains of ``amsfe bench``, SX instructions with CSE: 6.0k against
7.2k at 7 joints, 13.3k against 23.0k at 12; the Panda 6.4k against 10.1k).

Notation (world frame, motions ``[v; w]``, forces ``[f; tau]``, :mod:`.spatial`): ``S_k``
the joint's motion axis, ``v_k``, ``a_k`` the body's velocity and acceleration (``a_0 = -g``:
gravity as a fictitious acceleration), ``Y_k`` its spatial inertia, ``h_k = Y_k v_k``,
``f_k = Y_k a_k + v_k x* h_k``; ``Yc_i``, ``Bc_i``, ``F_i`` the sums of ``Y_k``, ``B_k``,
``f_k`` over the subtree of i (world-frame quantities add without transforms) and
``tau_i = S_i . F_i``.  Moving ``q_j`` moves the subtree of j rigidly by the twist ``S_j``,
which changes every world quantity ``X`` of it by ``S_j x X`` and cancels in ``tau``; what is
left (Carpentier and Mansard sec. IV; the Leibniz and Jacobi identities of the cross
products) are, per joint j,

- ``dV_j = v_p(j) x S_j``, the non-rigid change of the subtree's velocities per ``q_j``;
- ``dA_j = a_p(j) x S_j + v_p(j) x dV_j``, of their accelerations;
- ``B_k = v_k x* Y_k - Y_k (v_k x) + (. x* h_k)``, the change of ``f_k`` per non-rigid
  change of ``v_k`` (Pinocchio's ``variation`` plus its force-cross matrix),

and then, for j an ancestor of i or i itself (``j <= i``)::

    dtau_i/dq_j  = S_i . (Yc_i dA_j + Bc_i dV_j)
    dtau_i/dqd_j = S_i . (2 Yc_i dV_j + Bc_i S_j)

and for i a strict ancestor of j (``i < j``) ``dtau_i/dq_j = S_i . (Yc_j dA_j + Bc_j dV_j +
S_j x* F_j)``, ``dtau_i/dqd_j = S_i . (2 Yc_j dV_j + Bc_j S_j)``.  The parameters theta enter
the inertias affinely (:meth:`RigidBodyTree.inertia_params`), so ``dtau_i/dtheta_t`` is
``S_i`` dotted with the force of the unit inertia of theta_t at body k (``i <= k``).
Entries of unrelated joints (neither ancestor of the other) are structural zeros.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.spatial import (
    Placement,
    cross,
    force_cross,
    inertia_act,
    inertia_times,
    motion_cross,
)

__all__ = ["rnea_derivatives"]


def _motion_act(X: Placement, m: ca.SX) -> ca.SX:
    """Child-frame motion -> parent-frame motion (Pinocchio ``act`` on a motion)."""
    w = ca.mtimes(X.R, m[3:6])
    return ca.vertcat(ca.mtimes(X.R, m[0:3]) + cross(X.p, w), w)


def _sym_variation(pi: ca.SX, v: ca.SX) -> ca.SX:
    """``P + P^T`` with ``P = Y (v x)`` (6x6, symmetric): ``-(P + P^T) d = v x* (Y d) - Y (v x
    d)``, the change of ``f = Y a + v x* (Y v)`` when ``v`` changes by ``d`` and ``a`` by
    ``-(v x d)`` apart from the ``d x* h`` term (:func:`_force_cross_matrix`).  With ``Y =
    [[m 1, -[c]x], [[c]x, I]]`` and ``v x = [[[w]x, [v]x], [0, [w]x]]`` the blocks of ``P`` are
    products of skew matrices (Pinocchio's ``Inertia::variation``)."""
    m, c = pi[0], pi[1:4]
    rot = ca.vertcat(
        ca.horzcat(pi[4], pi[5], pi[7]),
        ca.horzcat(pi[5], pi[6], pi[8]),
        ca.horzcat(pi[7], pi[8], pi[9]),
    )
    W, L, C = ca.skew(v[3:6]), ca.skew(v[0:3]), ca.skew(c)
    CW = ca.mtimes(C, W)
    P = ca.blockcat([[m * W, m * L - CW], [CW, ca.mtimes(C, L) + ca.mtimes(rot, W)]])
    out = ca.SX.zeros(6, 6)  # the same node above and below the diagonal: 21 sums, not 36
    for row in range(6):
        for col in range(row + 1):
            out[row, col] = out[col, row] = P[row, col] + P[col, row]
    return out


def _force_cross_matrix(h: ca.SX, d: ca.SX) -> ca.SX:
    """``d x* h`` (the matrix ``H(h)`` applied to ``d``; ``H(h)^T = -H(h)``)."""
    return force_cross(d, h)


def _ancestors(tree: RigidBodyTree, k: int) -> list[int]:
    """k and its ancestors, from k towards the root."""
    out = [k]
    while tree.bodies[out[-1]].parent >= 0:
        out.append(tree.bodies[out[-1]].parent)
    return out


def rnea_derivatives(
    tree: RigidBodyTree, q: ca.SX, qd: ca.SX, qdd: ca.SX, theta: ca.SX
) -> tuple[ca.SX, ca.SX, ca.SX]:
    """``(dtau/dq, dtau/dqd, dtau/dtheta)`` of ``tau = RNEA(q, qd, qdd, theta)`` with gravity.

    Returns sparse SX matrices (n x n, n x n, n x p) whose structural nonzeros are the pairs
    of joints on one branch (and, for theta, the joints supporting the bound body); equal to
    Pinocchio's ``computeRNEADerivatives`` (tests/test_rnea_derivatives.py).
    """
    n, p = tree.n, tree.p
    bodies = tree.bodies
    X = tree.joint_transforms(q)
    pis = tree.inertia_params(theta)
    zero6 = ca.SX.zeros(6, 1)
    a0 = ca.SX(ca.DM(np.concatenate([-tree.gravity, np.zeros(3)])))
    oM: list[Placement] = []
    S: list[ca.SX] = []
    v: list[ca.SX] = []
    a: list[ca.SX] = []
    dV: list[ca.SX] = []
    dA: list[ca.SX] = []
    Yc: list[ca.SX] = []  # composite inertias (10 parameters, world frame)
    Pc: list[ca.SX] = []  # composite P + P^T (6x6, symmetric), see _sym_variation
    hc: list[ca.SX] = []  # composite momenta h
    F: list[ca.SX] = []  # composite forces
    for k, b in enumerate(bodies):
        oMk = X[k] if b.parent < 0 else oM[b.parent] * X[k]
        oM.append(oMk)
        vp = zero6 if b.parent < 0 else v[b.parent]
        ap = a0 if b.parent < 0 else a[b.parent]
        Sk = _motion_act(oMk, tree._subspace(k))
        dVk = motion_cross(vp, Sk)
        vk = vp + Sk * qd[k]
        ak = ap + Sk * qdd[k] + dVk * qd[k]
        Yk = inertia_act(oMk, pis[k])
        hk = inertia_times(Yk, vk)
        S.append(Sk)
        v.append(vk)
        a.append(ak)
        dV.append(dVk)
        dA.append(motion_cross(ap, Sk) + motion_cross(vp, dVk))
        Yc.append(Yk)
        Pc.append(_sym_variation(Yk, vk))
        hc.append(hk)
        F.append(inertia_times(Yk, ak) + force_cross(vk, hk))
    # theta: the force of each bound unit inertia at its body (before the sums below)
    dF_th: list[list[tuple[int, ca.SX]]] = [[] for _ in range(n)]
    for k, b in enumerate(bodies):
        for t, _origin, unit in b.units:
            Yu = inertia_act(oM[k], ca.SX(ca.DM(unit)))
            fu = inertia_times(Yu, a[k]) + force_cross(v[k], inertia_times(Yu, v[k]))
            dF_th[k].append((t, fu))
    for k in reversed(range(n)):
        parent = bodies[k].parent
        if parent >= 0:
            Yc[parent] = Yc[parent] + Yc[k]
            Pc[parent] = Pc[parent] + Pc[k]
            hc[parent] = hc[parent] + hc[k]
            F[parent] = F[parent] + F[k]
    dq, dv, dth = ca.SX(n, n), ca.SX(n, n), ca.SX(n, p)
    BS: list[ca.SX] = []
    for j in range(n):
        # column j, rows i < j (strict ancestors): S_i . dF_j
        # B d = -(P + P^T) d + d x* h for the composite P, h of the subtree of j
        PS = ca.mtimes(Pc[j], S[j])
        HS = _force_cross_matrix(hc[j], S[j])
        BdV = _force_cross_matrix(hc[j], dV[j]) - ca.mtimes(Pc[j], dV[j])
        dFq = inertia_times(Yc[j], dA[j]) + BdV + force_cross(S[j], F[j])
        dFv = 2 * inertia_times(Yc[j], dV[j]) + HS - PS
        BS.append(-PS - HS)  # B^T S_j
        for i in _ancestors(tree, j)[1:]:
            dq[i, j] = ca.dot(S[i], dFq)
            dv[i, j] = ca.dot(S[i], dFv)
    for i in range(n):
        YS = inertia_times(Yc[i], S[i])
        YS2 = 2 * YS
        for j in _ancestors(tree, i):
            dq[i, j] = ca.dot(YS, dA[j]) + ca.dot(BS[i], dV[j])
            dv[i, j] = ca.dot(YS2, dV[j]) + ca.dot(BS[i], S[j])
    for k in range(n):
        for t, fu in dF_th[k]:
            for i in _ancestors(tree, k):
                dth[i, t] = dth[i, t] + ca.dot(S[i], fu)
    return dq, dv, dth
