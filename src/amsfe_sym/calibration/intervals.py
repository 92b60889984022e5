"""The calibration's intervals and what the motion determines (docs/calibrate.md, "The
method", steps 3-4): each parameter's linearised 1-sigma from the final jacobian, the
parameters' correlation, and the parameter groups whose 95 % interval is over its limit
(held, or for the camera's pose refused)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import LogError, describe

__all__ = ["GROUP", "RANK_TOLERANCE", "UNDETERMINED", "Z95", "correlation", "stds"]
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


def stds(J: FloatArray, s2: float) -> tuple[FloatArray, FloatArray]:
    """1-sigma of each parameter, ``sqrt(diag(s2 (J^T J)^-1))``, with ``inf`` for a parameter
    the jacobian does not see (a zero column, or a share of a null direction), and the
    singular values of ``J`` with unit-norm columns."""
    cols = np.linalg.norm(J, axis=0)
    std = np.full(J.shape[1], np.inf)
    seen = cols > 0
    if not seen.any():
        return std, np.zeros(0)
    _, S, Vt = np.linalg.svd(J[:, seen] / cols[seen], full_matrices=False)
    good = S / S[0] > RANK_TOLERANCE
    var = (Vt[good].T ** 2) @ (1.0 / S[good] ** 2)
    null = (np.abs(Vt[~good]) > 0.1).any(axis=0) if (~good).any() else np.zeros(seen.sum(), bool)
    sd = np.sqrt(s2 * var) / cols[seen]
    sd[null] = np.inf
    std[seen] = sd
    return std, S


def correlation(J: FloatArray, free: NDArray[np.bool_]) -> FloatArray:
    """The correlation matrix (p, p) of the free parameters from ``(J^T J)^+`` (``J``: the
    jacobian over them), NaN in the rows and columns of the held ones."""
    out = np.full((free.size, free.size), np.nan)
    cols = np.linalg.norm(J, axis=0)
    cols[cols == 0] = 1.0
    C = np.linalg.pinv((J / cols).T @ (J / cols))
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
