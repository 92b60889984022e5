"""Small dense symbolic linear algebra that code-generates well.

CasADi's SX ``solve`` builds a large, less accurate expression; for the symmetric positive
definite mass matrix an unrolled LDL^T (no pivoting needed for SPD) is compact and exact.
"""

from __future__ import annotations

import casadi as ca

__all__ = ["ldl_solve", "plus_identity"]


def ldl_solve(A: ca.SX, b: ca.SX) -> ca.SX:
    """Solve A x = b for symmetric positive definite A (n x n) by an unrolled LDL^T.

    Args:
        A: Symmetric positive definite matrix (only the lower triangle is read).
        b: Right-hand side, n x k.

    Returns:
        x, n x k.
    """
    n = A.shape[0]
    L = [[ca.SX(0) for _ in range(n)] for _ in range(n)]
    D = [ca.SX(0) for _ in range(n)]
    for j in range(n):
        dj = A[j, j]
        for k in range(j):
            dj = dj - L[j][k] * L[j][k] * D[k]
        D[j] = dj
        for i in range(j + 1, n):
            lij = A[i, j]
            for k in range(j):
                lij = lij - L[i][k] * L[j][k] * D[k]
            L[i][j] = lij / dj
    cols = []
    for c in range(b.shape[1]):
        y = [ca.SX(0) for _ in range(n)]
        for i in range(n):
            yi = b[i, c]
            for k in range(i):
                yi = yi - L[i][k] * y[k]
            y[i] = yi
        z = [y[i] / D[i] for i in range(n)]
        x = [ca.SX(0) for _ in range(n)]
        for i in reversed(range(n)):
            xi = z[i]
            for k in range(i + 1, n):
                xi = xi - L[k][i] * x[k]
            x[i] = xi
        cols.append(ca.vertcat(*x))
    return ca.horzcat(*cols)


def plus_identity(X: ca.MX) -> ca.MX:
    """``X + I`` (ones added to the leading diagonal of X, which may be rectangular and sparse:
    the result has X's pattern and the diagonal, as ``DM.eye + X`` has) without a
    constant identity in the generated C: ``I - K H`` and the like, written with a dense
    identity, put the whole N x N matrix of zeros and ones in the C file (the Panda's cloning
    update: 947 lines for its 87 x 87 identity).  Equal to ``DM.eye + X`` bit for bit
    (``0 + x = x`` and ``1 + x`` whichever operand comes first)."""
    r, c = X.shape
    k = min(r, c)
    sp = X.sparsity().unite(ca.Sparsity.triplet(r, c, list(range(k)), list(range(k))))
    Y = ca.project(X, sp)  # X's pattern and the diagonal (a structural zero gets 1)
    diag = [sp.get_nz(i, i) for i in range(k)]
    Y.nz[diag] = Y.nz[diag] + 1.0
    return Y
