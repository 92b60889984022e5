"""The ``rk4`` model's fused step ``transition_step`` and the split stage it and the C chain
(``runtime/c/amsfe_model.c``) are built on: the stage without its dense solves with the mass
matrix, which are done in loops (CasADi's ``ldl`` linear solver in the MX graph, an LDL^T in
C in the chain) instead of unrolled in the generated code (docs/explanation/codegen.md).
Called through :class:`.transition.Transition` (``tr`` below; not imported: it imports
this module), which caches what they build."""

from __future__ import annotations

from typing import Any

import casadi as ca

from amsfe_sym.symbolic.linalg import ldl_solve, plus_identity

__all__ = [
    "dynamics_jacobian_function",
    "plant_rhs_over_stage",
    "stage_split_functions",
    "step_function",
]


def stage_split_functions(tr: Any) -> tuple[ca.Function, ca.Function]:
    """The stage of :meth:`.Transition.rk4_stage_function` without its dense solves, as two SX
    functions (CSE); the caller solves with M (the C chain of
    ``runtime/c/amsfe_model.c`` by one LDL^T of M in loops, the MX step by CasADi's
    ``ldl`` linear solver):

    ``rk4_stage_rhs (xp[4n], u[n], theta[p]) -> (kr, M)``: ``kr`` is k with its qdd rows
    replaced by the unsolved ``rhs = Ks (qm - q) - b(q, qd)`` (so ``qdd = M^-1 rhs``),
    ``M = M(q, theta)`` (CRBA, n x n, dense);

    ``rk4_stage_jac (xp, u, theta, qdd[n]) -> Jr``: J = dk/d[xp; theta] (4n x N, sparse)
    with its qdd rows replaced by the unsolved ``dtau = d(Ks (qm - q))/dz -
    dRNEA(q, qd, a)/dz |_{a = qdd}`` (so ``dqdd/dz = M^-1 dtau``); ``qdd`` is an input
    because dRNEA/dz is evaluated at the solved acceleration.  Since the solve acts on
    the rows only, ``(M^-1 dtau) [S; E] = M^-1 (dtau [S; E])``: the chain multiplies Jr
    by the sensitivities first and solves the n qdd rows of the product.
    """
    n, p = tr.tree.n, tr.tree.p
    xp, u, th = ca.SX.sym("xp", 4 * n), ca.SX.sym("u", n), ca.SX.sym("theta", p)
    a = ca.SX.sym("qdd", n)
    q, qd, qm, qmd = xp[0:n], xp[n : 2 * n], xp[2 * n : 3 * n], xp[3 * n : 4 * n]
    Ks = tr.stiffness(th)
    delta = qm - q
    rhs = Ks * delta - tr.tree.bias(q, qd, th)
    qmdd = (u - ca.DM(tr.robot.Fm) * qmd - Ks * delta) / ca.DM(tr.robot.Mm)
    M = ca.densify(tr.tree.mass_matrix(q, th))
    fr = ca.Function(
        "rk4_stage_rhs",
        [xp, u, th],
        [ca.vertcat(qd, rhs, qmd, qmdd), M],
        ["xp", "u", "theta"],
        ["kr", "M"],
        {"cse": True},
    )
    z = ca.vertcat(xp, th)
    dtau = ca.jacobian(Ks * delta, z) - tr._rnea_derivative(q, qd, a, th, z)
    J_lin = ca.jacobian(ca.vertcat(qd, qmd, qmdd), z)  # linear in z
    Jr = ca.vertcat(J_lin[0:n, :], dtau, J_lin[n:, :])
    fj = ca.Function(
        "rk4_stage_jac",
        [xp, u, th, a],
        [Jr],
        ["xp", "u", "theta", "qdd"],
        ["Jr"],
        {"cse": True},
    )
    return fr, fj


def dynamics_jacobian_function(tr: Any) -> ca.Function:
    """``forward_dynamics_jacobian (xp[4n], theta[p]) -> (qdd[n], dqdd[n x N])``: the link
    acceleration of the flexible-joint model, ``M(q) qdd + b(q, qd) = Ks (qm - q)``, and its
    exact jacobian with respect to ``z = [q, qd, qm, qmd, theta]`` [1/s^2, 1/s, ...], as an MX
    graph over the split stage (:func:`stage_split_functions`: one CRBA, one RNEA and its
    analytic derivatives, two solves with CasADi's ``ldl``).

    What Pinocchio's ``computeABADerivatives(q, v, tau)`` computes for a rigid arm, with the
    spring torque as tau: ``dqdd/dq = ddq_dq - M^-1 diag(Ks)``, ``dqdd/dqd = ddq_dv``,
    ``dqdd/dqm = M^-1 diag(Ks)`` (tests/test_generated.py); ``amsfe bench`` times the two
    side by side ("dynamics jacobian vs computeABADerivatives", docs/explanation/codegen.md).
    The chain of
    ``runtime/c/amsfe_model.c`` does the same work per stage with its solves in C loops.
    """
    n, p = tr.tree.n, tr.tree.p
    stage_r, stage_j = tr.rk4_stage_split_functions()
    xp, th = ca.MX.sym("xp", 4 * n), ca.MX.sym("theta", p)
    u = ca.MX.zeros(n, 1)  # the link rows do not depend on the motor torque
    kr, M = stage_r(xp, u, th)
    qdd = ca.solve(M, kr[n : 2 * n], "ldl")
    Jr = stage_j(xp, u, th, qdd)
    dqdd = ca.densify(ca.solve(M, ca.densify(Jr[n : 2 * n, :]), "ldl"))
    return ca.Function(
        "forward_dynamics_jacobian", [xp, th], [qdd, dqdd], ["xp", "theta"], ["qdd", "dqdd_dz"]
    )


def plant_rhs_over_stage(tr: Any) -> ca.Function:
    """The plant's right-hand side ``plant_rhs (xp, u, theta, tau_d) -> d/dt xp`` as an MX
    graph over ``rk4_stage_rhs`` (so a library with the split stage emits the dynamics once):
    the motor torque ``u + tau_m`` is the stage's input, the link rows ``rhs + tau_l`` are
    solved with the stage's M by ``rk4_mass_solve``, the unrolled LDL^T of
    :func:`.linalg.ldl_solve` as a small SX function (CasADi's ``ldl`` linear solver made
    ``plant_step`` 37 % slower on the Panda, this 10 %; docs/explanation/codegen.md).  The
    same operations in the same order as :meth:`.Transition.plant_rhs`, so equal to it to
    rounding."""
    n, p = tr.tree.n, tr.tree.p
    stage_r, _ = tr.rk4_stage_split_functions()
    Ms, bs = ca.SX.sym("M", n, n), ca.SX.sym("b", n)
    solve = ca.Function(
        "rk4_mass_solve", [Ms, bs], [ldl_solve(Ms, bs)], ["M", "b"], ["x"], {"cse": True}
    )
    xp, u = ca.MX.sym("xp", 4 * n), ca.MX.sym("u", n)
    th, td = ca.MX.sym("theta", p), ca.MX.sym("tau_d", 2 * n)
    kr, M = stage_r(xp, u + td[n:], th)
    f = ca.MX(kr)  # kr with its qdd rows solved, in place (fewer copies than a vertcat)
    f.nz[n : 2 * n] = solve(M, kr[n : 2 * n] + td[:n])
    return ca.Function("plant_rhs", [xp, u, th, td], [f], ["xp", "u", "theta", "tau_d"], ["f"])


#: The rk4 substeps of the contract's ``transition_step`` beyond the first, and the RK4
#: steps of ``transition``, the inverse and ``plant_step`` (:func:`.transition.rk4_steps`),
#: are one substep function called in a loop (CasADi's ``Function.fold``) when there are
#: more than one: its body is emitted once in the C file, where unrolled every substep was
#: its own copy (the 30 Hz Panda's 62: docs/explanation/codegen.md).  ``False`` unrolls
#: them (kept to compare against).  The cache key hashes this module's source, not the
#: value at run time: a library generated after setting it in a process must go to its own
#: folder with ``force=True`` (``tools/fold_substeps.py`` does), or the cache would take it
#: for the folded one.
FOLD_SUBSTEPS = True


def step_function(tr: Any, expand: bool = True) -> ca.Function:
    """x+ = F(x, u), A = dF/dx and Gamma = dF/dw of the ``rk4`` model in one function.

    F is ``model_substeps`` classical RK4 steps of h = T / m over T, u held.  A is
    propagated through the stages (forward sensitivities: ``dk_i/dx = J_i [dxp_i/dx;
    E_theta]`` with the sparse stage jacobians), not by differentiating the MX graph
    (that took ~390 us on a 7-DOF arm).  Gamma follows from A: the impulses enter as
    ``qd += M(q)^-1 w_l``, ``qmd += w_m / Mm`` at the start of the step and ``theta +=
    T w_theta``.

    With ``expand`` the stages are SX, straight-line C (UR5: 16 us; as MX calls 41
    us) over :meth:`.Transition.rk4_stage_function` (the solves unrolled) and
    :meth:`.Transition.rk4_minv_function`.  Without, it is an MX graph over the two stage functions
    of :func:`stage_split_functions`, the solves with M by CasADi's ``ldl`` linear
    solver (loops in the generated C; it does not expand to SX), Gamma's M(q)^-1 from the
    first stage's M (its point is x): the same arrangement as the C chain.

    With ``tr.fold`` (default :data:`FOLD_SUBSTEPS`) and more than one substep, the first
    substep (whose sensitivity starts from the identity, a sparser product) is built
    inline and the other m - 1 are ``rk4_substep (P = [xp, S], u, theta) -> P+`` called in
    a loop (:func:`substep_function`, ``Function.fold``): the same operations, its code
    emitted once; with ``expand`` the substep function is SX and the step an MX graph
    calling it.

    Returns:
        ``transition_step (x, u) -> (x_next, A, Gamma)`` (the inverse's Newton steps use
        its A too).
    """
    n, p, T = tr.tree.n, tr.tree.p, tr.T
    N = 4 * n + p
    h = T / tr.substeps
    x, u = ca.MX.sym("x", N), ca.MX.sym("u", n)
    xp, th = x[: 4 * n], x[4 * n :]
    xp, Sx, M0 = _substep(tr, expand, xp, None, u, th, h)  # Sx = [I 0] before it
    folded = tr.fold and tr.substeps > 1
    if folded:
        body = substep_function(tr, expand, h)
        P = body.fold(tr.substeps - 1)(ca.horzcat(xp, Sx), u, th)
        xp, Sx = P[:, 0], P[:, 1:]
    else:
        for _ in range(tr.substeps - 1):
            xp, Sx, _M = _substep(tr, expand, xp, Sx, u, th, h)
    E = ca.DM.eye(N)[4 * n :, :]
    A = ca.densify(ca.vertcat(Sx, E))
    Mm = ca.DM(tr.robot.Mm)
    if M0 is None:  # A[:, qd] M^-1
        G_l = ca.mtimes(A[:, n : 2 * n], tr.rk4_minv_function()(x[:n], th))
    else:  # (M^-1 A[:, qd]^T)^T, M symmetric
        G_l = ca.solve(M0, A[:, n : 2 * n].T, "ldl").T
    G = ca.densify(
        ca.horzcat(
            G_l,
            A[:, 3 * n : 4 * n] / ca.repmat(Mm.T, N, 1),
            ca.vertcat(ca.DM.zeros(4 * n, p), T * ca.DM.eye(p)),
        )
    )
    step = ca.Function(
        "transition_step",
        [x, u],
        [ca.vertcat(xp, th), A, G],
        ["x", "u"],
        ["x_next", "A", "Gamma"],
    )
    return step.expand() if expand and not folded else step


def substep_function(tr: Any, expand: bool, h: float) -> ca.Function:
    """One rk4 substep of h [s] with its sensitivity, ``rk4_substep (P[4n x (1 + N)], u[n],
    theta[p]) -> P+``, ``P = [xp, S]`` with ``S = dxp/dx`` (the state and its sensitivity
    packed in one matrix, the one accumulated input ``Function.fold`` takes); SX when
    ``expand``; built once per robot and h."""
    key = f"rk4_substep:{expand}:{h!r}"
    if key not in tr._cache:
        n, p = tr.tree.n, tr.tree.p
        P, u, th = ca.MX.sym("P", 4 * n, 1 + 4 * n + p), ca.MX.sym("u", n), ca.MX.sym("theta", p)
        xp, Sx, _M = _substep(tr, expand, P[:, 0], P[:, 1:], u, th, h)
        fn = ca.Function(
            "rk4_substep",
            [P, u, th],
            [ca.densify(ca.horzcat(xp, Sx))],
            ["P", "u", "theta"],
            ["P_next"],
        )
        tr._cache[key] = fn.expand() if expand else fn
    return tr._cache[key]


def _substep(
    tr: Any, expand: bool, xp: ca.MX, Sx: ca.MX | None, u: ca.MX, th: ca.MX, h: float
) -> tuple[ca.MX, ca.MX, ca.MX | None]:
    """One classical RK4 substep of h [s] from ``xp`` and its sensitivity ``Sx = dxp/dx``
    (4n x N; ``None`` for ``[I 0]``, the first substep, whose products it skips): returns
    ``(xp+, Sx+, M)`` with ``M`` the first stage's mass matrix (split stage) or ``None``
    (the unrolled stage of ``expand``)."""
    n, p = tr.tree.n, tr.tree.p
    N = 4 * n + p
    E = ca.DM.eye(N)[4 * n :, :]
    if expand:
        full = tr.rk4_stage_function()

        def stage(xi: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX | None]:
            k, J = full(xi, u, th)
            return k, J, None

    else:
        stage_r, stage_j = tr.rk4_stage_split_functions()

        def stage(xi: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX | None]:
            kr, M = stage_r(xi, u, th)
            qdd = ca.solve(M, kr[n : 2 * n], "ldl")
            Jr = stage_j(xi, u, th, qdd)
            return ca.vertcat(kr[0:n], qdd, kr[2 * n :]), Jr, M

    def solved(D: ca.MX, M: ca.MX | None) -> ca.MX:
        """D with its qdd rows solved by M (the split stage's unsolved rows)."""
        if M is None:
            return D
        return ca.vertcat(D[0:n, :], ca.solve(M, D[n : 2 * n, :], "ldl"), D[2 * n :, :])

    k1, d1, M1 = stage(xp)
    d1 = solved(d1 if Sx is None else ca.mtimes(d1, ca.vertcat(Sx, E)), M1)
    ks, ds = [k1], [d1]
    for c in (0.5, 0.5, 1.0):
        xi = xp + c * h * ks[-1]
        Si = plus_identity(c * h * ds[-1]) if Sx is None else Sx + c * h * ds[-1]
        ki, Ji, Mi = stage(xi)
        ks.append(ki)
        ds.append(solved(ca.mtimes(Ji, ca.vertcat(Si, E)), Mi))
    xp = xp + (h / 6.0) * (ks[0] + 2 * ks[1] + 2 * ks[2] + ks[3])
    dS = (h / 6.0) * (ds[0] + 2 * ds[1] + 2 * ds[2] + ds[3])
    return xp, plus_identity(dS) if Sx is None else Sx + dS, M1
