"""The marker's corners from its 4 outer edges (docs/camera.md, "The corners"): each edge
sampled along its normal, the sub-pixel 50 % crossing between the dark border and the light
quiet zone located on each profile, one curve fitted per edge, adjacent curves intersected.

Under a symmetric blur the 50 % level of a straight dark-light step is the step itself, so
the edge points are unbiased; OpenCV's ``cornerSubPix`` on the marker's corners is not (on
the simulated camera's renders it stops 0.1-0.45 px inside the true corner, more with more
blur: tools/marker_view_accuracy.py ``--bias``; the marker's own bits lie in its window).
The corners come back in the raw (distorted) image as the
detector's other corners do.  With the camera's :class:`~amsfe_sym.vision.camera_info.
CameraInfo` the edge points are undistorted and a straight line is fitted per edge; without
it (the log reader detects before it has read the CameraInfo) a parabola per edge in the raw
image takes the lens's bend of a straight edge to second order.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.vision.camera_info import CameraInfo, distort, undistort

__all__ = ["edge_corners", "edge_points", "unbend"]

FloatArray = NDArray[np.float64]

#: Passes of (levels at the edge +- a, then the edge at their mean) on each profile.
LEVEL_PASSES = 4
#: How far beyond +- a the profiles reach [px] (the approximate corners' error).
SLACK = 1.0
#: The shortest edge [px] fitted by a parabola in the raw image (shorter: a line).  The
#: lens bends a straight edge by its sagitta, 0.07 px over 50 px and 1.1 px over 200 px at
#: the corner of the simulated camera's image (0.18 and 2.8 px with the strong lens); a
#: parabola's third coefficient costs noise on short edges: on renders at blur 0.8 px the
#: corners' RMS error was lowest with the threshold at 40-60 px (tools/marker_view_accuracy.py).
CURVE_FROM = 50.0
#: Profile step along an edge's normal [px].
STEP = 0.25
#: Most samples along one edge (spaced evenly between its two corner margins).
MAX_SAMPLES = 40
#: Farthest the levels are read on each side of an edge [px] (half a module below that).
MAX_REACH = 4.0


def edge_points(
    grey: NDArray[np.uint8], corners: FloatArray, modules: int
) -> list[FloatArray] | None:
    """Sub-pixel points (N_k, 2) [px, raw image, integer = pixel centre] on each of the
    marker's 4 outer edges, edge k from ``corners[k]`` to ``corners[k+1]`` (OpenCV's
    order), or None when an edge gives fewer than 3 points.

    ``modules``: the marker's side in modules (bits + 2 border bits).  Each profile is
    sampled every :data:`STEP` px (bicubic) across the approximate edge, ``a`` = half a
    module (at most :data:`MAX_REACH`) and :data:`SLACK` more on each side.  The edge's dark
    and light levels are the medians over its profiles of the values at ``a`` inside and
    outside each profile's edge (so the dark one stays in the black border, and a blur wider
    than ``a`` moves both alike); each profile's edge is then its crossing of the levels'
    mean nearest the last one (linear between samples), and the two steps are repeated
    :data:`LEVEL_PASSES` times from the approximate edge (an approximate edge 0.2 px off
    would otherwise tilt the levels).  Samples stay a module (at least 3 px) away from the
    corners, where the other edge bends the level line.
    """
    import cv2

    c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    centre = c.mean(axis=0)
    A, B = c, np.roll(c, -1, axis=0)
    length = np.linalg.norm(B - A, axis=1)  # (4,)
    if not np.all(length > 4.0):
        return None
    d = (B - A) / length[:, None]
    n = np.column_stack([-d[:, 1], d[:, 0]])
    outward = np.sign(np.einsum("ij,ij->i", 0.5 * (A + B) - centre, n))
    n *= outward[:, None]
    module = float(length.mean()) / modules
    reach = min(0.5 * module, MAX_REACH)
    margin = max(module, 3.0)
    s = np.arange(-reach - SLACK, reach + SLACK + 1e-9, STEP)  # (M,) outward positive
    count = int(min(MAX_SAMPLES, max(3, np.floor(length.min() - 2 * margin) + 1)))
    t = np.linspace(0.0, 1.0, count)
    u = margin + t[None, :] * (length[:, None] - 2 * margin)  # (4, count) along each edge
    base = A[:, None, :] + u[..., None] * d[:, None, :]  # (4, count, 2)
    pts = base[:, :, None, :] + s[None, None, :, None] * n[:, None, None, :]  # (4, count, M, 2)
    flat = pts.reshape(4 * count, len(s), 2)
    # only the pixels the bicubic samples touch, as float (the region and the whole image's
    # searches then read the same values)
    h, w = grey.shape[:2]
    x0, y0 = np.maximum(np.floor(flat.reshape(-1, 2).min(axis=0)).astype(int) - 3, 0)
    x1, y1 = np.ceil(flat.reshape(-1, 2).max(axis=0)).astype(int) + 4
    patch = np.asarray(grey[y0 : min(y1, h), x0 : min(x1, w)], dtype=np.float32)
    local = (flat - np.array([x0, y0], dtype=np.float64)).astype(np.float32)
    prof = (
        cv2.remap(
            patch, local[..., 0], local[..., 1], cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE
        )
        .reshape(4, count, len(s))
        .astype(np.float64)
    )
    off = np.zeros((4, count))  # each profile's edge [px] along the normal
    ok = np.ones((4, count), dtype=bool)
    mid = 0.5 * (s[:-1] + s[1:])
    rows, cols = np.ogrid[:4, :count]
    for _ in range(LEVEL_PASSES):
        dark = _median_rows(_at(prof, s, off - reach), ok)
        light = _median_rows(_at(prof, s, off + reach), ok)
        level = (0.5 * (dark + light))[:, None, None]
        above = prof >= level  # (4, count, M)
        rise = ~above[..., :-1] & above[..., 1:]  # a dark -> light crossing in (j, j+1)
        dist = np.where(rise, np.abs(mid[None, None, :] - off[..., None]), np.inf)
        j = np.argmin(dist, axis=2)  # (4, count): the crossing nearest the last edge
        ok = np.isfinite(dist[rows, cols, j])
        ok &= (light - dark)[:, None] > 0
        v0, v1 = prof[rows, cols, j], prof[rows, cols, j + 1]
        frac = (level[..., 0] - v0) / np.where(v1 > v0, v1 - v0, 1.0)
        off = np.where(ok, s[j] + STEP * frac, off)
    found = base + off[..., None] * n[:, None, :]
    out = [found[k][ok[k]] for k in range(4)]
    return out if all(len(p) >= 3 for p in out) else None


def _at(prof: FloatArray, s: FloatArray, x: FloatArray) -> FloatArray:
    """The profiles ``prof`` (4, count, M), sampled at ``s`` (M,), at ``x`` (4, count)
    (linear between samples, clamped to the ends)."""
    f = np.clip((x - s[0]) / STEP, 0.0, len(s) - 1.000001)
    j = np.floor(f).astype(int)
    w = f - j
    rows, cols = np.ogrid[: prof.shape[0], : prof.shape[1]]
    out: FloatArray = (1.0 - w) * prof[rows, cols, j] + w * prof[rows, cols, j + 1]
    return out


def _median_rows(v: FloatArray, ok: NDArray[np.bool_]) -> FloatArray:
    """The median of each row of ``v`` (R, N) over its ``ok`` entries (all of a row that has
    none), as ``np.median`` would give it, for all rows at once."""
    ok = ok | ~ok.any(axis=1, keepdims=True)
    srt = np.sort(np.where(ok, v, np.inf), axis=1)
    k = ok.sum(axis=1)
    r = np.arange(len(v))
    out: FloatArray = 0.5 * (srt[r, (k - 1) // 2] + srt[r, k // 2])
    return out


def edge_corners(
    grey: NDArray[np.uint8],
    corners: FloatArray,
    modules: int,
    info: CameraInfo | None = None,
    curve_from: float = CURVE_FROM,
) -> FloatArray | None:
    """The marker's 4 corners (4, 2) [px, raw image] from its edges (:func:`edge_points`),
    ``corners`` the approximate ones (OpenCV's order); None when an edge gives too few
    points.

    ``info``: the camera's lens; its edge points are undistorted, a line (total least
    squares) fitted per edge, adjacent lines intersected and the corners distorted back.
    None: a parabola per edge of ``curve_from`` px or longer in the raw image (least squares
    of the offset along the edge's normal; a line for shorter edges), adjacent curves
    intersected by Newton's method.
    """
    found = edge_points(grey, corners, modules)
    if found is None:
        return None
    if info is not None and not info.rectified:
        lines = [_line(undistort(info, p)) for p in found]
        return distort(info, np.array([_meet(lines[k - 1], lines[k]) for k in range(4)]))
    long = np.linalg.norm(np.asarray(corners) - np.roll(corners, -1, axis=0), axis=1) >= curve_from
    curves = [_parabola(p, bool(bend)) for p, bend in zip(found, long, strict=True)]
    return np.array([_meet_curves(curves[k - 1], curves[k]) for k in range(4)])


def _line(p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(a point, a unit direction) of the total-least-squares line through ``p`` (N, 2)."""
    m = p.mean(axis=0)
    q = p - m
    sxx, syy, sxy = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # (the scatter's principal axis)
    return m, np.array([np.cos(angle), np.sin(angle)])


def _meet(a: tuple[FloatArray, FloatArray], b: tuple[FloatArray, FloatArray]) -> FloatArray:
    """The intersection of two lines (point, direction)."""
    (p, d), (q, e) = a, b
    t = np.linalg.solve(np.column_stack([d, -e]), q - p)
    out: FloatArray = p + t[0] * d
    return out


Curve = tuple[FloatArray, FloatArray, FloatArray, FloatArray]  # origin, d, n, (c0, c1, c2)


def _parabola(p: FloatArray, bend: bool = True) -> Curve:
    """The parabola ``origin + u d + (c0 + c1 u + c2 u^2) n`` through ``p`` (N, 2) by least
    squares, ``d`` the points' principal direction, ``u`` from their mean; a straight line
    (``c2 = 0``) for fewer than 5 points."""
    m, d = _line(p)
    n = np.array([-d[1], d[0]])
    u, w = (p - m) @ d, (p - m) @ n
    deg = 2 if bend and len(p) >= 5 else 1
    V = np.vander(u, deg + 1, increasing=True)
    coef = np.linalg.solve(V.T @ V, V.T @ w)  # (u from the mean: well conditioned)
    return m, d, n, np.pad(coef, (0, 3 - len(coef)))


def _meet_curves(a: Curve, b: Curve) -> FloatArray:
    """The intersection of two parabolas (Newton's method from their points' means; the
    2 x 2 steps by Cramer's rule, in floats: ~20 of them a frame)."""
    (max_, may), (dax, day), (nax, nay), (a0, a1, a2) = (tuple(map(float, v)) for v in a)
    (mbx, mby), (dbx, dby), (nbx, nby), (b0, b1, b2) = (tuple(map(float, v)) for v in b)
    ua = ub = 0.0
    for _ in range(8):  # (the first step: where the tangents at the points' means meet)
        wa, ga = a0 + ua * (a1 + ua * a2), a1 + 2.0 * a2 * ua
        wb, gb = b0 + ub * (b1 + ub * b2), b1 + 2.0 * b2 * ub
        rx = (mbx + ub * dbx + wb * nbx) - (max_ + ua * dax + wa * nax)
        ry = (mby + ub * dby + wb * nby) - (may + ua * day + wa * nay)
        tax, tay = dax + ga * nax, day + ga * nay  # the tangents
        tbx, tby = dbx + gb * nbx, dby + gb * nby
        det = tbx * tay - tax * tby  # of [ta, -tb]
        sa, sb = (tbx * ry - tby * rx) / det, (tax * ry - tay * rx) / det
        ua, ub = ua + sa, ub + sb
        if max(abs(sa), abs(sb)) < 1e-10:
            break
    wa = a0 + ua * (a1 + ua * a2)
    return np.array([max_ + ua * dax + wa * nax, may + ua * day + wa * nay])


#: Points a side in :func:`unbend`'s model of an edge fit.
UNBEND_POINTS = 41


def unbend(
    info: CameraInfo, corners: FloatArray, modules: int, curve_from: float = CURVE_FROM
) -> FloatArray:
    """Corners (M, 4, 2) [px, raw image] found by :func:`edge_corners` without the
    CameraInfo, less the error its straight lines make: an edge shorter than ``curve_from``
    is fitted as a line in the raw image, where the lens bends it, so the line lies off the
    edge's ends by a part of its sagitta and the corners move (on the simulated camera's
    30-45 px markers, their centre ~0.015 px away from the image's centre, the same way on
    every frame: docs/camera.md, "The corners").  With the lens ``info`` that error is
    modelled and taken off: each edge's straight segment between the undistorted corners,
    distorted, sampled over the span :func:`edge_points` samples (a module, at least 3 px,
    from each corner) and fitted as :func:`edge_corners` fits it (a total-least-squares line;
    a longer edge, fitted by a parabola, as its tangent at the corner), adjacent fits
    intersected; the corners less (those intersections - the distorted corners).  A
    rectified ``info``: the corners as they are."""
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    if info.rectified or c.size == 0:
        return c.copy()
    M = len(c)
    und = undistort(info, c.reshape(-1, 2)).reshape(M, 4, 2)
    true = distort(info, und.reshape(-1, 2)).reshape(M, 4, 2)
    length = np.linalg.norm(c - np.roll(c, -1, axis=1), axis=2)  # (M, 4) raw edge k: k -> k+1
    margin = np.maximum(length.mean(axis=1, keepdims=True) / modules, 3.0)  # (M, 1)
    lo = np.clip(margin / length, 0.0, 0.5)  # fractions of each edge sampled
    t = np.linspace(0.0, 1.0, UNBEND_POINTS)
    f = lo[..., None] + t * (1.0 - 2.0 * lo[..., None])  # (M, 4, P)
    a, b = und, np.roll(und, -1, axis=1)
    pts = a[:, :, None, :] + f[..., None] * (b - a)[:, :, None, :]  # (M, 4, P, 2)
    raw = distort(info, pts.reshape(-1, 2)).reshape(pts.shape)
    mean = raw.mean(axis=2)  # (M, 4, 2): each edge's line: mean, direction
    q = raw - mean[:, :, None, :]
    sxx, syy = (q[..., 0] ** 2).sum(axis=2), (q[..., 1] ** 2).sum(axis=2)
    sxy = (q[..., 0] * q[..., 1]).sum(axis=2)
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (M, 4, 2)
    curved = length >= curve_from
    # corner j meets edge j-1 (its end) and edge j (its start); a curved edge's tangent there
    eps = 1e-3
    step = (b - a) / np.maximum(np.linalg.norm(b - a, axis=2, keepdims=True), 1e-300)
    ahead = distort(info, (a + eps * step).reshape(-1, 2)).reshape(M, 4, 2)
    behind = distort(info, (b - eps * step).reshape(-1, 2)).reshape(M, 4, 2)
    start_dir, end_dir = ahead - true, np.roll(true, -1, axis=1) - behind
    p1 = np.where(curved[..., None], true, mean)  # edge j at corner j
    d1 = np.where(curved[..., None], start_dir, direction)
    p0 = np.roll(np.where(curved[..., None], np.roll(true, -1, axis=1), mean), 1, axis=1)
    d0 = np.roll(np.where(curved[..., None], end_dir, direction), 1, axis=1)  # edge j-1
    # p0 + s d0 = p1 + r d1 (Cramer's rule)
    rhs = p1 - p0
    det = d0[..., 0] * (-d1[..., 1]) - d0[..., 1] * (-d1[..., 0])
    s = (rhs[..., 0] * (-d1[..., 1]) - rhs[..., 1] * (-d1[..., 0])) / det
    fitted = p0 + s[..., None] * d0
    out: FloatArray = c - (fitted - true)
    return out
