"""The calibration as one batch: an initial guess from OpenCV's ``solvePnP``, then nonlinear
least squares over the reprojection error with a robust loss, linearised intervals, and a
verdict per parameter on whether the motion determined it (docs/calibrate.md).

Steps:

1. **Initial guess.**  For trial time offsets every :data:`SCAN_STEP_S` over
   ``+-max_offset``, the tracked points at ``stamp - dt`` with the spec's marker offset and the
   pixels go to ``cv2.solvePnP`` (SQPnP); the trial with the smallest reprojection error gives
   the camera pose and ``dt``.  The spec's own camera pose (at ``dt = 0``) is the start
   instead when it reprojects better: with few frames and a marker offset typed centimetres
   off, the PnP of the tracked points can be far worse than a pose measured by eye (ViSP's
   8-frame eye-to-hand set: 507 px against 197 px, tools/visp_eye_to_hand.py).
2. **Robust fit.**  ``scipy.optimize.least_squares`` (trust region reflective) over all ten
   parameters with the Huber loss, its scale :data:`HUBER_SCALE` times the pixel noise
   (``pixel_std``).  From a start more than :data:`FAR_START` Huber scales off (RMS), a
   squared-loss fit comes first: there every residual is in the loss's linear part, and the
   robust fit alone wandered to a wrong minimum (ViSP's eye-to-hand set with its own
   intrinsics: a camera 1 m away, tools/visp_eye_to_hand.py).  The pixel noise is then
   measured from the residuals (1.4826 MAD) and frames farther than :data:`OUTLIER_SIGMAS`
   of it are dropped as outliers.
3. **Final fit** on the inliers with the plain squared loss, from the robust fit.  Its
   covariance is ``s^2 (J^T J)^-1`` with ``s^2`` the residual variance (RSS / (2m - p)): a
   linearised interval, ``+-1.96 sigma`` for 95 %.  Inliers with no more residuals than
   parameters (2m <= p) are refused: their fit is exact and its interval zero, not known.
4. **What the motion determines.**  A parameter whose 95 % half-width exceeds
   :data:`UNDETERMINED` is held at its initial value (the spec's marker offset, a zero time
   offset) and the fit repeated without it; the result names it and why.  The camera's pose is
   never held: a log that cannot determine it is refused (one line).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from amsfe_sym.calibration.initial import SCAN_STEP_S, InitialGuess, initial_guess, spread_check
from amsfe_sym.calibration.model import NP, ReprojectionModel
from amsfe_sym.calibration.observations import NO_ENCODER, LinkAngles, Observations
from amsfe_sym.errors import LogError, describe
from amsfe_sym.load.types import Robot

__all__ = [
    "HUBER_SCALE",
    "OUTLIER_SIGMAS",
    "SCAN_STEP_S",
    "UNDETERMINED",
    "Calibration",
    "InitialGuess",
    "calibrate",
    "initial_guess",
]

FloatArray = NDArray[np.float64]

#: Huber loss scale, in pixel noise standard deviations.
HUBER_SCALE = 3.0
#: A frame whose reprojection error exceeds this many pixel-noise sigmas is an outlier.
OUTLIER_SIGMAS = 5.0
#: 95 % half-width above which a parameter is "not determined by the motion" (the parameter
#: group's unit: rotation [deg], position and offset [m], time [s]).
UNDETERMINED = {"rotation": 1.0, "camera": 0.02, "offset": 0.02, "time_offset": 0.01}
#: A start whose reprojection RMS exceeds this many Huber scales gets a squared-loss fit
#: before the robust one (module docstring, step 2).
FAR_START = 10.0
#: The 95 % two-sided normal quantile.
Z95 = 1.959963984540054

_GROUP = ("rotation",) * 3 + ("camera",) * 3 + ("offset",) * 3 + ("time_offset",)
_UNIT = (180.0 / np.pi,) * 3 + (1.0,) * 7


@dataclass
class Calibration:
    """The result.

    Attributes:
        R_cw: World -> camera rotation at the solution.
        position: Camera centre in the world [m].
        offset: Marker offset in the tracked frame [m].
        time_offset: Stamp minus exposure [s].
        x: The parameter vector (:data:`~amsfe_sym.calibration.model.PARAMETERS`),
            rotation relative to ``R0``.
        R0: The rotation the fitted rotation vector applies to.
        std: 1-sigma of each parameter (NaN: held), same units as ``x``.
        free: Which parameters were fitted.
        held: Parameter group -> why it was held at its initial value.
        pixel_std: Pixel noise measured from the inliers' residuals [px] (RMS per axis).
        residual: Reprojection error vector per frame (m, 2) [px] (NaN: frame not used).
        used: Frames in the final fit.
        dropped: Frame index -> reason, for every frame not used.
        initial: The OpenCV initial guess.
        singular_values: Of the final jacobian with its columns scaled to unit norm.
        correlation: The parameters' correlation matrix (NP, NP) from the same linearisation
            as ``std`` (NaN rows and columns: held): which parameters the pixels tell apart
            least (docs/calibrate.md, "Accuracy").
        nfev: Model evaluations of the final fit.
    """

    R_cw: FloatArray
    position: FloatArray
    offset: FloatArray
    time_offset: float
    x: FloatArray
    R0: FloatArray
    std: FloatArray
    free: NDArray[np.bool_]
    held: dict[str, str]
    pixel_std: float
    residual: FloatArray
    used: NDArray[np.bool_]
    dropped: dict[int, str]
    initial: InitialGuess
    singular_values: FloatArray
    nfev: int = 0
    pixel: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    correlation: FloatArray = field(default_factory=lambda: np.full((NP, NP), np.nan))
    stamp: FloatArray = field(default_factory=lambda: np.zeros(0))

    def half_width95(self) -> FloatArray:
        """The 95 % linearised half-width of each parameter (NaN where held)."""
        return Z95 * self.std

    def frame_errors(self) -> FloatArray:
        """Reprojection error [px] of each used frame."""
        return np.linalg.norm(self.residual[self.used], axis=1)


def calibrate(
    robot: Robot,
    links: LinkAngles,
    obs: Observations,
    pixel_std: float = 1.0,
    max_offset: float = 0.2,
    fit_time_offset: bool = True,
    progress: Callable[[str], None] | None = None,
    limits: dict[str, float] | None = None,
) -> Calibration:
    """Calibrate the camera pose, the marker offset and the time offset (module docstring).

    Args:
        robot: The loaded robot: its intrinsics, tracked frame and (initial) marker offset.
        links: Link angles per encoder tick.
        obs: The camera frames.
        pixel_std: Expected pixel noise [px] (the robust loss's scale before it is measured).
        max_offset: Largest time offset the initial scan tries [s].
        fit_time_offset: False holds the time offset at 0.
        progress: Called with a line per step.
        limits: The 95 % half-widths above which a parameter group is not determined
            (default :data:`UNDETERMINED`; ``amsfe calibrate`` always uses the default).

    Raises:
        LogError: no usable frame; an arm at rest; a pose the log cannot determine; too few
            frames left after the drops to leave a residual (2m <= p).
    """
    say = progress or (lambda _s: None)
    offset0 = np.asarray(robot.tracked_offset, dtype=np.float64)
    if obs.m < 6:
        raise LogError(
            describe(
                "calibration",
                "at least 6 camera frames",
                f"{obs.m}",
                "record the camera (its topic is named in the topic spec: "
                "docs/reference/topics.md)",
            )
        )
    spread_check(robot, links, obs, offset0)
    init = initial_guess(robot, links, obs, offset0, max_offset if fit_time_offset else 0.0)
    if init.source == "spec":
        say(
            f"initial guess: the spec's camera pose (reprojection RMS {init.rms:.2f} px over "
            f"{init.frames} frames; solvePnP's best, time offset scanned in "
            f"+-{max_offset:g} s: {init.pnp_rms:.2f} px)"
        )
    else:
        say(
            f"initial guess (solvePnP over {init.frames} frames, time offset scanned in "
            f"+-{max_offset:g} s): reprojection RMS {init.rms:.2f} px at "
            f"{init.time_offset * 1e3:+.0f} ms"
        )
    model = ReprojectionModel(robot, links, obs.stamp, init.R_cw)
    x0 = np.concatenate([np.zeros(3), init.position, offset0, [init.time_offset]])
    free = np.ones(NP, dtype=bool)
    held: dict[str, str] = {}
    if not fit_time_offset:
        free[9] = False
        x0[9] = 0.0
        held["time_offset"] = "held at 0 (--no-time-offset)"
    dropped: dict[int, str] = {}
    inside = (
        (obs.pixel[:, 0] >= 0)
        & (obs.pixel[:, 0] < robot.camera.width)
        & (obs.pixel[:, 1] >= 0)
        & (obs.pixel[:, 1] < robot.camera.height)
        & np.isfinite(obs.pixel).all(axis=1)
    )
    for i in np.flatnonzero(~inside):
        dropped[int(i)] = "pixel outside the image"
    use = inside.copy()

    # 2. robust fit (after a squared-loss one from a far start), pixel noise, outliers
    if init.rms > FAR_START * HUBER_SCALE * pixel_std:
        x0, use, _ = _fit(model, obs, x0, free, use, dropped)
    x, use, nfev = _fit(model, obs, x0, free, use, dropped, "huber", HUBER_SCALE * pixel_std)
    res = _residual(model, obs, x)
    sigma = 1.4826 * float(np.median(np.abs(res[use])))
    err = np.linalg.norm(res, axis=1)
    for i in np.flatnonzero(use & (err > OUTLIER_SIGMAS * sigma)):
        dropped[int(i)] = (
            f"outlier of the robust loss ({err[i]:.1f} px > {OUTLIER_SIGMAS:g} x {sigma:.2f} px)"
        )
        use[i] = False
    say(f"robust fit (Huber, scale {HUBER_SCALE * pixel_std:.2f} px): pixel noise {sigma:.3f} px")

    # 3./4. plain least squares on the inliers; hold what the motion cannot determine
    while True:
        x, use, nfev = _fit(model, obs, x, free, use, dropped)  # the squared loss
        pr = model.project(x)
        r = (pr.y - obs.pixel)[use]
        Jf = pr.J[use][:, :, free].reshape(-1, int(free.sum()))
        if r.size <= int(free.sum()):
            raise LogError(
                describe(
                    "calibration",
                    f"more pixel residuals than the {int(free.sum())} parameters fitted",
                    f"{r.size} from {int(use.sum())} frames left of {obs.m} "
                    f"({len(dropped)} dropped)",
                    "record more frames",
                )
            )
        dof = r.size - int(free.sum())
        s2 = float(np.sum(r**2)) / dof
        sd, sv = _stds(Jf, s2)
        std = np.full(NP, np.nan)
        std[free] = sd
        newly = _undetermined(std, free, held, UNDETERMINED if limits is None else limits)
        if not newly:
            break
        for group, why in newly.items():
            for k in range(NP):
                if _GROUP[k] == group:
                    free[k] = False
                    x[k] = 0.0 if group == "time_offset" else offset0[k - 6]
            held[group] = why
    res = _residual(model, obs, x)
    R = model.rotation(x[0:3])
    return Calibration(
        R_cw=R,
        position=x[3:6].copy(),
        offset=x[6:9].copy(),
        time_offset=float(x[9]),
        x=x,
        R0=init.R_cw,
        std=std,
        free=free,
        held=held,
        pixel_std=float(np.sqrt(s2)),
        residual=res,
        used=use,
        dropped=dropped,
        initial=init,
        singular_values=sv,
        nfev=nfev,
        pixel=obs.pixel,
        stamp=obs.stamp,
        correlation=_correlation(Jf, free),
    )


#: A singular value of the column-scaled jacobian below this share of the largest: its
#: direction is not determined at all (the parameters in it get an infinite std).
RANK_TOLERANCE = 1e-9


def _stds(J: FloatArray, s2: float) -> tuple[FloatArray, FloatArray]:
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


def _correlation(J: FloatArray, free: NDArray[np.bool_]) -> FloatArray:
    """The correlation matrix (NP, NP) of the free parameters from ``(J^T J)^+`` (``J``: the
    jacobian over them), NaN in the rows and columns of the held ones."""
    out = np.full((NP, NP), np.nan)
    cols = np.linalg.norm(J, axis=0)
    cols[cols == 0] = 1.0
    C = np.linalg.pinv((J / cols).T @ (J / cols))
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    idx = np.flatnonzero(free)
    out[np.ix_(idx, idx)] = C / np.outer(d, d)
    return out


def _undetermined(
    std: FloatArray, free: NDArray[np.bool_], held: dict[str, str], limits: dict[str, float]
) -> dict[str, str]:
    """Parameter groups whose 95 % half-width is over ``limits`` (:data:`UNDETERMINED`;
    module docstring, step 4); a camera pose among them is refused."""
    out: dict[str, str] = {}
    for group, limit in limits.items():
        ks = [k for k in range(NP) if _GROUP[k] == group and free[k]]
        if not ks:
            continue
        hw = max(Z95 * std[k] * _UNIT[k] for k in ks)
        if np.isfinite(hw) and hw <= limit:
            continue
        unit = {"rotation": "deg", "time_offset": "s"}.get(group, "m")
        why = (
            f"its linearised 95 % interval is +-{hw:.3g} {unit} wide (limit {limit:g} {unit}): "
            + _WHY[group]
        )
        if group in ("rotation", "camera"):
            raise LogError(
                describe(
                    "calibration: the camera pose",
                    "a log whose motion determines it",
                    why,
                    "record the arm moving through more of the camera's view",
                )
            )
        out[group] = why
    return out


_WHY = {
    "rotation": "the tracked point covers too little of the view",
    "camera": "the tracked point covers too little of the view",
    "offset": "the tracked frame does not turn enough in the log (held at the spec's offset)",
    "time_offset": "the tracked point hardly moves at the exposures, so a shift in time "
    "changes no pixel (held at 0; move the arm faster)",
}


def _residual(model: ReprojectionModel, obs: Observations, x: FloatArray) -> FloatArray:
    """Residuals (m, 2) [px] of every frame with link angles (NaN elsewhere)."""
    pr = model.project(x)
    res = pr.y - obs.pixel
    res[~pr.valid] = np.nan
    return res


def _with(x: FloatArray, free: NDArray[np.bool_], p: FloatArray) -> FloatArray:
    """``x`` with its free entries set to ``p``."""
    out = x.copy()
    out[free] = p
    return out


def _fit(
    model: ReprojectionModel,
    obs: Observations,
    x0: FloatArray,
    free: NDArray[np.bool_],
    use: NDArray[np.bool_],
    dropped: dict[int, str],
    loss: str = "linear",
    f_scale: float = 1.0,
) -> tuple[FloatArray, NDArray[np.bool_], int]:
    """``least_squares`` over the free parameters and the frames in ``use``; frames that lose
    their encoder samples (the time offset moved them off the log) or fall behind the camera
    are dropped and the fit repeated."""
    x = x0.copy()
    nfev = 0
    for _ in range(5):
        pr = model.project(x)
        for i in np.flatnonzero(use & ~pr.valid):
            dropped[int(i)] = NO_ENCODER
        use = use & pr.valid
        idx, base = np.flatnonzero(use), x.copy()

        def fun(p: FloatArray, idx: NDArray[np.intp] = idx, base: FloatArray = base) -> FloatArray:
            """Residuals [px] of the frames ``idx`` at the free parameters ``p``."""
            pr = model.project(_with(base, free, p))
            return (pr.y[idx] - obs.pixel[idx]).reshape(-1)

        def jac(p: FloatArray, idx: NDArray[np.intp] = idx, base: FloatArray = base) -> FloatArray:
            """Their jacobian over the free parameters."""
            pr = model.project(_with(base, free, p))
            return pr.J[idx][:, :, free].reshape(-1, int(free.sum()))

        sol = least_squares(
            fun, x[free], jac=jac, method="trf", loss=loss, f_scale=f_scale, x_scale="jac"
        )
        nfev += int(sol.nfev)
        x[free] = sol.x
        pr = model.project(x)
        lost = use & ~pr.valid
        behind = use & pr.valid & (pr.depth <= 0)
        for i in np.flatnonzero(lost):
            dropped[int(i)] = NO_ENCODER
        for i in np.flatnonzero(behind):
            dropped[int(i)] = "behind the camera at the solution"
        if not (lost.any() or behind.any()):
            break
        use = use & ~lost & ~behind
    # frames never usable (no encoder at the initial time offset either)
    pr = model.project(x)
    for i in np.flatnonzero(~pr.valid):
        dropped.setdefault(int(i), NO_ENCODER)
    return x, use & pr.valid, nfev
