"""The calibration's intervals and what the motion determines (docs/calibrate.md, "The
method", steps 3-4): each parameter's linearised 1-sigma from the final jacobian, the
parameters' correlation, and the parameter groups whose 95 % interval is over its limit
(held, or for the camera's pose refused)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import LogError, describe

__all__ = ["GROUP", "RANK_TOLERANCE", "SANDWICH_FRAMES_PER_PARAMETER", "UNDETERMINED", "Z95"]
__all__ += ["ErrorModel", "bandwidth", "block_variances", "correlation", "error_model"]
__all__ += ["prewhitening", "stds"]
__all__ += ["undetermined"]

#: 95 % half-width above which a parameter is "not determined by the motion" (the parameter
#: group's unit: rotation [deg], position and offset [m], time [s]).  The marker's orientation
#: (the corner fit) is the corners' model: held only when far from known, 5 deg (ViSP's
#: 8-frame eye-to-hand set: +-2.5 deg; held at its start there instead, the camera's pose
#: moved and the residual rose from 3.70 to 5.00 px per axis, tools/visp_eye_to_hand.py).
UNDETERMINED = {
    "rotation": 1.0,
    "camera": 0.02,
    "offset": 0.02,
    "time_offset": 0.01,
    "marker_rotation": 5.0,
}
#: The 95 % two-sided normal quantile.
Z95 = 1.959963984540054

#: Each parameter's group (:data:`~amsfe_sym.calibration.model.CORNER_PARAMETERS` order).
GROUP: tuple[str, ...] = ("rotation",) * 3 + ("camera",) * 3 + ("offset",) * 3
GROUP += ("time_offset",) + ("marker_rotation",) * 3
_UNIT = (180.0 / np.pi,) * 3 + (1.0,) * 7 + (180.0 / np.pi,) * 3


#: A singular value of the column-scaled jacobian below this share of the largest: its
#: direction is not determined at all (the parameters in it get an infinite std).
RANK_TOLERANCE = 1e-9


#: Frames per fitted parameter from which the errors' covariance is measured from the
#: residuals themselves (:func:`error_model`: the frame-cluster sandwich with correlation
#: across consecutive frames); with fewer, the per-frame block model.
SANDWICH_FRAMES_PER_PARAMETER = 10
#: The largest lag-1 autocorrelation the bandwidth rule takes from a score (a unit root
#: would give an unbounded bandwidth).
MAX_RHO = 0.97


@dataclass(frozen=True)
class ErrorModel:
    """How the fit's pixel errors are taken to be correlated, and the middle of the
    sandwich ``(J^T J)^-1 M (J^T J)^-1`` they give (docs/calibrate.md, "Intervals").

    Attributes:
        kind: ``"sandwich"`` (many frames: ``M`` from the residuals, each frame's points as
            one cluster, Bartlett-weighted across consecutive frames) or ``"block"`` (few
            frames: each frame's points share a common shift, ``M = sigma2 J^T J + tau2
            J^T B J``).
        middle: ``M`` (p, p) [px^2 x the jacobian's units squared].
        sigma2: The independent part of each coordinate's variance [px^2] (the sandwich:
            the residual variance ``RSS / (n - p)``, for reference).
        tau2: The variance of a frame's common shift, per axis [px^2] (0 with one point a
            frame, where it cannot be told from ``sigma2``; the sandwich: not modelled).
        bandwidth: The sandwich's Bartlett bandwidth [frames] (0: frames independent).
    """

    kind: str
    middle: FloatArray
    sigma2: float
    tau2: float
    bandwidth: int


def error_model(J: FloatArray, r: FloatArray) -> ErrorModel:
    """The fit's error model from its jacobian ``J`` (m, k, p) and residuals ``r`` (m, k)
    [px] over its m frames in time order, k = 2P coordinates a frame (P points, u and v of
    each in turn).

    With at least :data:`SANDWICH_FRAMES_PER_PARAMETER` frames a parameter, a sandwich robust
    to both kinds of shared error: each frame's score ``g_i = J_i^T r_i`` (its points as one
    cluster: a shift common to its corners is in it), and ``M = m / (m - p) (G_0 + sum_l
    w_l (G_l + G_l^T))``, ``G_l = sum_i g_i g_(i-l)^T``, Bartlett weights ``w_l = 1 - l /
    (L + 1)`` (Newey-West) with the bandwidth ``L`` from the scores' own lag-1
    autocorrelation (:func:`bandwidth`).  With fewer frames (a few poses of a hand-eye set)
    the residuals cannot measure ``M`` in every direction, so the block model: a frame's
    coordinates' errors ``sigma2 I + tau2 B`` (``B``: 1 between two of its points' u, and
    between their v), ``sigma2`` and ``tau2`` from the residuals by moments
    (:func:`block_variances`)."""
    m, k, p = J.shape
    J2 = J.reshape(m * k, p)
    H = J2.T @ J2
    n = m * k
    s2 = float(np.sum(r**2)) / max(n - p, 1)
    if m >= SANDWICH_FRAMES_PER_PARAMETER * p:
        g = np.einsum("ikp,ik->ip", J, r)
        A = prewhitening(g)
        u = g[1:] - g[:-1] @ A.T
        L = bandwidth(u)
        Mu = u.T @ u
        for lag in range(1, L + 1):
            G = u[lag:].T @ u[:-lag]
            Mu += (1.0 - lag / (L + 1)) * (G + G.T)
        B = np.linalg.inv(np.eye(p) - A)
        M = B @ Mu @ B.T * (m / u.shape[0])
        return ErrorModel("sandwich", M * m / (m - p), s2, 0.0, L)
    sigma2, tau2 = block_variances(J, r)
    return ErrorModel("block", sigma2 * H + tau2 * _shift_gram(J), sigma2, tau2, 0)


def _shift_gram(J: FloatArray) -> FloatArray:
    """``J^T B J`` (p, p) for the jacobian ``J`` (m, k, p) of m frames of k/2 points:
    ``B`` couples a frame's points' u with each other and their v (a shift common to the
    frame), so each frame's rows summed per axis."""
    m, k, p = J.shape
    S = J.reshape(m, k // 2, 2, p).sum(axis=1)  # each frame's points summed, per axis
    return np.asarray(np.einsum("iap,iaq->pq", S, S))


def prewhitening(g: FloatArray) -> FloatArray:
    """The VAR(1) ``A`` (p, p) of the scores ``g`` (m, p) in time order, ``g_i = A g_(i-1) +
    u_i`` by least squares, its singular values clipped to :data:`MAX_RHO` (Andrews and
    Monahan 1992: the sandwich's middle is then ``(I - A)^-1 M_u (I - A)^-T``, far less
    biased for strongly correlated scores than the Bartlett sum of ``g`` itself)."""
    x, y = g[:-1], g[1:]
    A = np.linalg.lstsq(x, y, rcond=None)[0].T
    U, S, Vt = np.linalg.svd(A)
    return np.asarray((U * np.minimum(S, MAX_RHO)) @ Vt)


def bandwidth(g: FloatArray) -> int:
    """The Bartlett bandwidth [frames] for the scores ``g`` (m, p) in time order: Andrews'
    (1991) AR(1) plug-in, ``1.1447 (alpha m)^(1/3)``, with ``alpha = sum 4 rho^2 /
    ((1 - rho)^6 (1 + rho)^2) / sum 1 / (1 - rho)^4`` over the standardised scores' lag-1
    autocorrelations ``rho`` (clipped to [0, :data:`MAX_RHO`]); 0 when they are
    uncorrelated (white noise)."""
    m = g.shape[0]
    if m < 3:
        return 0
    z = g - g.mean(axis=0)
    var = np.sum(z**2, axis=0)
    ok = var > 0
    if not ok.any():
        return 0
    rho = np.sum(z[1:, ok] * z[:-1, ok], axis=0) / var[ok]
    rho = np.clip(rho, 0.0, MAX_RHO)
    alpha = float(np.sum(4 * rho**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)))
    alpha /= float(np.sum(1 / (1 - rho) ** 4))
    return int(min(np.floor(1.1447 * (alpha * m) ** (1 / 3)), m // 4))


def block_variances(J: FloatArray, r: FloatArray) -> tuple[float, float]:
    """``sigma2``, ``tau2`` [px^2] of the block model (:func:`error_model`) by moments: the
    residuals' sum of squares ``r^T r`` and of each frame's per-axis sums ``r^T B r``
    against their expectations ``tr(A (I - P) C (I - P))`` (``P`` the fit's hat matrix,
    ``C = sigma2 I + tau2 B``), which take out what the fit absorbed; ``tau2`` clipped at 0
    (then ``sigma2`` from ``r^T r`` alone).  One point a frame: ``tau2 = 0``."""
    m, k, p = J.shape
    n = m * k
    J2 = J.reshape(n, p)
    Hi = np.linalg.pinv(J2.T @ J2)
    rank = float(np.trace(Hi @ (J2.T @ J2)))
    rr = float(np.sum(r**2))
    if k == 2:
        return rr / max(n - rank, 1.0), 0.0
    npts = k // 2
    Gb = _shift_gram(J)  # J^T B J
    rs = r.reshape(m, npts, 2).sum(axis=1)
    rbr = float(np.sum(rs**2))  # r^T B r
    tPB = float(np.trace(Hi @ Gb))  # tr(P B)
    tPBPB = float(np.trace(Hi @ Gb @ Hi @ Gb))
    # E[r^T r] = sigma2 (n - rank) + tau2 (n - tPB);  B^2 = npts B, tr(B) = n
    # E[r^T B r] = sigma2 (n - tPB) + tau2 (npts n - 2 npts tPB + tPBPB)
    A = np.array([[n - rank, n - tPB], [n - tPB, npts * n - 2 * npts * tPB + tPBPB]])
    sigma2, tau2 = np.linalg.solve(A, [rr, rbr])
    if tau2 <= 0:
        return rr / max(n - rank, 1.0), 0.0
    if sigma2 <= 0:
        return 0.0, rr / max(n - tPB, 1.0)
    return float(sigma2), float(tau2)


def stds(J: FloatArray, middle: FloatArray) -> tuple[FloatArray, FloatArray]:
    """1-sigma of each parameter, ``sqrt(diag((J^T J)^-1 M (J^T J)^-1))`` (``M``:
    ``middle``, :func:`error_model`; ``s2 J^T J`` gives the white-noise ``s2 (J^T
    J)^-1``), with ``inf`` for a parameter the jacobian does not see (a zero column, or a
    share of a null direction), and the singular values of ``J`` with unit-norm columns."""
    cols = np.linalg.norm(J, axis=0)
    std = np.full(J.shape[1], np.inf)
    seen = cols > 0
    if not seen.any():
        return std, np.zeros(0)
    _, S, Vt = np.linalg.svd(J[:, seen] / cols[seen], full_matrices=False)
    good = S / S[0] > RANK_TOLERANCE
    Ms = middle[np.ix_(seen, seen)] / np.outer(cols[seen], cols[seen])
    A = Vt[good].T / S[good] ** 2  # (J_s^T J_s)^+ = A Vt[good]
    C = A @ (Vt[good] @ Ms @ Vt[good].T) @ A.T
    var = np.clip(np.diag(C), 0.0, None)
    null = (np.abs(Vt[~good]) > 0.1).any(axis=0) if (~good).any() else np.zeros(seen.sum(), bool)
    sd = np.sqrt(var) / cols[seen]
    sd[null] = np.inf
    std[seen] = sd
    return std, S


def correlation(J: FloatArray, free: NDArray[np.bool_], middle: FloatArray) -> FloatArray:
    """The correlation matrix (p, p) of the free parameters from ``(J^T J)^+ M (J^T
    J)^+`` (``J``: the jacobian over them, ``M``: ``middle``), NaN in the rows and columns
    of the held ones."""
    out = np.full((free.size, free.size), np.nan)
    cols = np.linalg.norm(J, axis=0)
    cols[cols == 0] = 1.0
    Hp = np.linalg.pinv((J / cols).T @ (J / cols))
    C = Hp @ (middle / np.outer(cols, cols)) @ Hp
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    idx = np.flatnonzero(free)
    out[np.ix_(idx, idx)] = C / np.outer(d, d)
    return out


def undetermined(
    std: FloatArray, free: NDArray[np.bool_], limits: dict[str, float]
) -> dict[str, str]:
    """Parameter groups whose 95 % half-width is over ``limits`` (:data:`UNDETERMINED`;
    module docstring, step 4); a camera pose among them is refused when nothing else is
    newly held (else the fit is repeated first: a held parameter frees a degree of
    freedom, and the pose's interval narrows)."""
    out: dict[str, str] = {}
    refusal = ""
    for group, limit in limits.items():
        ks = [k for k in range(free.size) if GROUP[k] == group and free[k]]
        if not ks:
            continue
        hw = max(Z95 * std[k] * _UNIT[k] for k in ks)
        if np.isfinite(hw) and hw <= limit:
            continue
        unit = {"rotation": "deg", "marker_rotation": "deg", "time_offset": "s"}.get(group, "m")
        why = (
            f"its linearised 95 % interval is +-{hw:.3g} {unit} wide (limit {limit:g} {unit}): "
            + _WHY[group]
        )
        if group in ("rotation", "camera"):
            refusal = refusal or why
            continue
        out[group] = why
    if refusal and not out:
        raise LogError(
            describe(
                "calibration: the camera pose",
                "a log whose motion determines it",
                refusal,
                "record the arm moving through more of the camera's view, or, with images, "
                "fit the marker's 4 corners (amsfe calibrate --corners)",
            )
        )
    return out


_WHY = {
    "rotation": "the tracked point covers too little of the view",
    "camera": "the tracked point covers too little of the view",
    "offset": "the tracked frame does not turn enough in the log (held at the spec's offset)",
    "marker_rotation": "the marker's corners do not tell its orientation (held at the start's)",
    "time_offset": "the tracked point hardly moves at the exposures, so a shift in time "
    "changes no pixel (held at 0; move the arm faster)",
}
