"""The estimators' numerics as generated functions (the compiled runtime, docs/how-to/runtime-c.md).

Each function is an MX graph over the robot's own ``transition_step`` and ``camera_measure``
(so the model is emitted once, whatever the integrator) with dense matrix products emitted as
loops (code grows as ``N^2``, not ``N^3``); for small state dimensions (``N <=
EXPAND_MAX_STATES``) the per-frame functions of :data:`EXPANDED` are expanded into SX
(straight-line code, 5x faster); small SX helpers for the Cholesky
factorisations whose pivots decide positive definiteness.  They compute; they never decide:
the hand-written C glue (``runtime/c/amsfe_runtime.c`` and the ``amsfe_est_*.c`` beside it)
compares NIS with the gates, reads the ``*_ok`` flags and keeps the history buffers.  Every
function mirrors one function of the Python reference (``estimation/ekf.py``,
``estimation/oosm.py``) line by line, so both paths agree to rounding.  Tuning enters as
inputs: ``qw`` (diagonal of Qw), ``r`` (diagonal of R).

Names and signatures (``N`` states, ``n`` joints, ``m = 2n + p`` noise inputs):

- ``est_predict(x[N], P[N,N], u[n], qw[m]) -> x_pred, P_pred, A, Qd`` (eqs. 13-14);
- ``est_camera_update(x_prior, P, x_lin, z[2], r[2]) -> x_post, P_post, nis, s_ok, chk``: one
  Gauss-Newton step of the iterated EKF linearised at ``x_lin`` (``x_lin = x_prior``: the plain
  EKF update);
- ``est_oosm_accumulate(Phi, Q, A, Qd) -> A Phi, A Q A^T + Qd`` (eq. 23, one step);
- ``est_oosm_correct(x, P, x_r, M, C, Phi, z[2], r[2]) -> x_new, P_new, nis, szz_ok, chk``
  (eqs. 19-20, 26);
- ``est_clone_predict(xa[Na], Pa[Na,Na], u, qw) -> xa_pred, Pa_pred, P_state`` and
  ``est_clone_camera(xa, Pa, c[N], sel[S], z[2], r[2]) -> xa_post, Pa_post, nis, s_ok, chk``:
  stochastic cloning on the augmented state ``xa = [x; c_1; ..; c_S]`` with ``S`` clone slots
  (``Na = (1 + S) N``); a free slot holds zeros (its rows and columns stay exactly zero), the
  one-hot ``sel`` picks the slot the frame's clone is in, ``c`` is that clone.

The encoder updates (their H selects states), the A1 retrodiction and every
positive-definiteness check are hand-written C kernels (``runtime/c/amsfe_kernels.c``): as
generated SX they were fully unrolled Cholesky solves, 74k of the Panda's 228k lines.

``chk`` is the sum of the absolute values of the model outputs the update used (``h``,
``dh/dx``, ``Hc Fb``): non-finite exactly when one of them is, which the Python reference
raises on.
"""

from __future__ import annotations

import casadi as ca

from amsfe_sym.symbolic.linalg import plus_identity

__all__ = ["EXPANDED", "EXPAND_MAX_STATES", "estimator_functions"]

#: Up to this many states the per-frame functions of :data:`EXPANDED` are expanded into SX
#: (straight-line C without MX call and loop overhead; paper_2link, pure C at -O1:
#: est_camera_update 5.1 -> 1.0 us, at 3-4x the lines).  The tick's algebra (predict, encoder
#: update, Cholesky check, eq. 23) and the A1 retrodiction run in the C kernels instead
#: (docs/how-to/runtime-c.md); ``est_predict`` and ``est_oosm_accumulate`` stay for cloning and
#: tests.
EXPAND_MAX_STATES = 10
#: The functions expanded (``est_oosm_correct`` holds a QR solve, which has no SX form; the
#: cloning updates on the augmented state grow as ``Na^3``: 22k lines for the 2-link arm).
EXPANDED = frozenset({"est_camera_update"})


def _chol_factor(S: ca.MX) -> tuple[list[list[ca.MX]], ca.MX]:
    """Unrolled lower Cholesky factor of ``S`` (scalar operations) and a flag: 1 when every
    pivot is > 0.

    A NaN pivot compares false, so the flag is 0 for a non-finite ``S`` too (LAPACK ``potrf``
    refuses the same matrices).
    """
    m = S.shape[0]
    L = [[ca.MX(0.0) for _ in range(m)] for _ in range(m)]
    ok = ca.MX(1.0)
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d = d - L[j][k] * L[j][k]
        ok = ok * (d > 0)
        ljj = ca.sqrt(d)
        L[j][j] = ljj
        for i in range(j + 1, m):
            s = S[i, j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s / ljj
    return L, ok


def _chol_solve_function(m: int, cols: int, name: str) -> ca.Function:
    """``(S[m,m], B[m,cols]) -> (S^-1 B, ok)`` by Cholesky (``ok`` as in _chol_factor): an
    MX graph whose substitutions act on whole rows of B, so the generated C is one loop over
    the columns per operation (unrolled per column it was 1,074 lines for the Panda's
    cloning update; the same operations in the same order)."""
    S, B = ca.MX.sym("S", m, m), ca.MX.sym("B", m, cols)
    L, ok = _chol_factor(S)
    y: list[ca.MX] = []
    for i in range(m):  # L Y = B
        s = B[i, :]
        for k in range(i):
            s = s - L[i][k] * y[k]
        y.append(s / L[i][i])
    xs: list[ca.MX] = [ca.MX(0.0)] * m
    for i in range(m - 1, -1, -1):  # L^T X = Y
        s = y[i]
        for k in range(i + 1, m):
            s = s - L[k][i] * xs[k]
        xs[i] = s / L[i][i]
    return ca.Function(name, [S, B], [ca.vertcat(*xs), ok], ["S", "B"], ["X", "ok"])


def _sym(X: ca.MX) -> ca.MX:
    return 0.5 * (X + X.T)


def _abs_sum(*terms: ca.MX) -> ca.MX:
    return sum((ca.sum1(ca.sum2(ca.fabs(t))) for t in terms), ca.MX(0.0))


def _joseph(
    x: ca.MX, P: ca.MX, nu: ca.MX, H: ca.MX | ca.DM, r: ca.MX, solve: ca.Function
) -> tuple[ca.MX, ca.MX, ca.MX, ca.MX]:
    """ekf.joseph_update: ``(x+, P+, nis, s_ok)``, Joseph form, no gating (the glue gates)."""
    N = P.shape[0]
    PHt = ca.mtimes(P, H.T)
    S = _sym(ca.mtimes(H, PHt) + ca.diag(r))
    X, ok = solve(S, ca.horzcat(nu, PHt.T))
    S_inv_nu, K = X[:, 0], X[:, 1:].T
    nis = ca.dot(nu, S_inv_nu)
    x_post = x + ca.mtimes(PHt, S_inv_nu)
    IKH = plus_identity(-ca.mtimes(K, H))  # I - K H, no N x N constant in the C
    KR = K * ca.repmat(r.T, N, 1)
    P_post = _sym(ca.mtimes(ca.mtimes(IKH, P), IKH.T) + ca.mtimes(KR, K.T))
    return x_post, P_post, nis, ok


def estimator_functions(
    functions: dict[str, ca.Function],
    n: int,
    p: int,
    layout: dict[str, slice],
    clone_slots: int,
) -> list[ca.Function]:
    """The estimator functions of one robot, built over its model functions.

    Args:
        functions: The robot's functions (needs ``transition_step`` and ``camera_measure``).
        n: Joints.
        p: Parameters theta.
        layout: State blocks ``q, qd, qm, qmd, theta`` as slices (eq. 2).
        clone_slots: ``S``, clones the cloning functions carry (camera delay // period + 1).

    Returns:
        The functions listed in the module docstring.
    """
    N, m = 4 * n + p, 2 * n + p
    step, cam = functions["transition_step"], functions["camera_measure"]
    sq, sth = layout["q"], layout["theta"]
    solve_cam = _chol_solve_function(2, 1 + N, "est_solve_camera")

    def sym(name: str, rows: int, cols: int = 1) -> ca.MX:
        return ca.MX.sym(name, rows, cols)

    x, P, u, qw = sym("x", N), sym("P", N, N), sym("u", n), sym("qw", m)

    def camera_h(xs: ca.MX) -> tuple[ca.MX, ca.MX]:
        y, J, _depth = cam(xs[sq], xs[sth])
        H = ca.MX.zeros(2, N)
        H[:, sq] = J
        return y, H

    # eqs. (13)-(14)
    x1, A, G = step(x, u)
    Qd = ca.mtimes(G * ca.repmat(qw.T, N, 1), G.T)
    predict = ca.Function(
        "est_predict",
        [x, P, u, qw],
        [x1, _sym(ca.mtimes(ca.mtimes(A, P), A.T) + Qd), A, Qd],
        ["x", "P", "u", "qw"],
        ["x_pred", "P_pred", "A", "Qd"],
    )

    # camera, one iterated-EKF step at x_lin
    x_lin, z_c, r_c = sym("x_lin", N), sym("z", 2), sym("r", 2)
    y, Hc = camera_h(x_lin)
    nu_c = z_c - y - ca.mtimes(Hc, x - x_lin)
    xc, Pc, nis_c, ok_c = _joseph(x, P, nu_c, Hc, r_c, solve_cam)
    camera = ca.Function(
        "est_camera_update",
        [x, P, x_lin, z_c, r_c],
        [xc, Pc, nis_c, ok_c, _abs_sum(y, Hc)],
        ["x_prior", "P", "x_lin", "z", "r"],
        ["x_post", "P_post", "nis", "s_ok", "chk"],
    )

    # oosm, eq. (23) one step of the accumulation
    Phi, Q, Aj, Qj = sym("Phi", N, N), sym("Q", N, N), sym("A", N, N), sym("Qd", N, N)
    accumulate = ca.Function(
        "est_oosm_accumulate",
        [Phi, Q, Aj, Qj],
        [ca.mtimes(Aj, Phi), ca.mtimes(ca.mtimes(Aj, Q), Aj.T) + Qj],
        ["Phi", "Q", "A", "Qd"],
        ["Phi_next", "Q_next"],
    )

    # oosm correction, eqs. (19)-(20), (26) (oosm.a1_correct)
    x_r, M, C = sym("x_r", N), sym("M", N, N), sym("C", N, N)
    y_r, Hr = camera_h(x_r)
    G_r = ca.solve(Phi.T, Hr.T, "qr").T  # Hc Fb = Hc Phi^-1
    Szz = _sym(ca.mtimes(ca.mtimes(G_r, M), G_r.T) + ca.diag(r_c))
    nu_r = z_c - y_r
    Pxz = ca.mtimes(C, G_r.T)
    Xz, ok_z = solve_cam(Szz, ca.horzcat(nu_r, Pxz.T))
    nis_r = ca.dot(nu_r, Xz[:, 0])
    W = Xz[:, 1:].T
    P_new = _sym(P - ca.mtimes(W, Pxz.T))
    correct = ca.Function(
        "est_oosm_correct",
        [x, P, x_r, M, C, Phi, z_c, r_c],
        [x + ca.mtimes(W, nu_r), P_new, nis_r, ok_z, _abs_sum(y_r, Hr, G_r)],
        ["x", "P", "x_r", "M", "C", "Phi", "z", "r"],
        ["x_new", "P_new", "nis", "szz_ok", "chk"],
    )

    # cloning (estimation/cloning.py) on the augmented state with S slots
    S_, Na = clone_slots, (1 + clone_slots) * N
    xa, Pa = sym("xa", Na), sym("Pa", Na, Na)
    xp, Pp, Ap, _Qp = predict(xa[:N], Pa[:N, :N], u, qw)
    cross = ca.mtimes(Ap, Pa[:N, N:])
    Pa_pred = ca.vertcat(ca.horzcat(Pp, cross), ca.horzcat(cross.T, Pa[N:, N:]))
    clone_predict = ca.Function(
        "est_clone_predict",
        [xa, Pa, u, qw],
        [ca.vertcat(xp, xa[N:]), Pa_pred, Pp],
        ["xa", "Pa", "u", "qw"],
        ["xa_pred", "Pa_pred", "P_state"],
    )
    c, sel = sym("c", N), sym("sel", S_)
    y_c, Hcc = camera_h(c)
    Hca = ca.horzcat(ca.MX.zeros(2, N), *[sel[i] * Hcc for i in range(S_)])
    solve_cam_a = _chol_solve_function(2, 1 + Na, "est_solve_clone_camera")
    xca, Pca, nis_ca, ok_ca = _joseph(xa, Pa, z_c - y_c, Hca, r_c, solve_cam_a)
    clone_camera = ca.Function(
        "est_clone_camera",
        [xa, Pa, c, sel, z_c, r_c],
        [xca, Pca, nis_ca, ok_ca, _abs_sum(y_c, Hcc)],
        ["xa", "Pa", "c", "sel", "z", "r"],
        ["xa_post", "Pa_post", "nis", "s_ok", "chk"],
    )
    out = [predict, camera, accumulate, correct, clone_predict, clone_camera]
    if N <= EXPAND_MAX_STATES:
        out = [f.expand() if f.name() in EXPANDED else f for f in out]
    return out
