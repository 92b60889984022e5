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
   covariance is the sandwich ``(J^T J)^-1 M (J^T J)^-1`` of
   :func:`~amsfe_sym.calibration.intervals.error_model` (errors shared by a frame's points
   and by consecutive frames; ``M = s^2 J^T J`` for independent errors, ``s^2`` the
   residual variance RSS / (2m - p)): a linearised interval, ``+-1.96 sigma`` for 95 %.
   Inliers with no more residuals than parameters (2m <= p) are refused: their fit is exact
   and its interval zero, not known.
4. **What the motion determines** (its geometry at the measured pixel noise: the verdict
   takes ``s^2 (J^T J)^-1``, whatever the errors share).  A parameter whose 95 % half-width exceeds
   :data:`UNDETERMINED` is held at its initial value (the spec's marker offset, a zero time
   offset) and the fit repeated without it; the result names it and why.  The camera's pose is
   never held: a log that cannot determine it is refused (one line), once every other
   parameter the log cannot determine is held (a held parameter is not in the degrees of
   freedom of ``s^2``).

With the marker's 4 corners per frame (an image log, :attr:`Observations.corners`) the fit is
the same over 8 residuals a frame, with the marker's orientation on its link as 3 more
parameters (:mod:`amsfe_sym.calibration.model`), its start from
:mod:`amsfe_sym.calibration.corner_start`; a frame's corners are dropped together, its error
the RMS of its 4 corners' distances.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from amsfe_sym.calibration.corner_start import CornerStart, corner_start
from amsfe_sym.calibration.initial import SCAN_STEP_S, InitialGuess, initial_guess, spread_check
from amsfe_sym.calibration.intervals import (
    GROUP,
    UNDETERMINED,
    Z95,
    ErrorModel,
    correlation,
    error_model,
    stds,
    undetermined,
)
from amsfe_sym.calibration.model import NP, PARAMETERS, ReprojectionModel, marker_corners_local
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
    "describe_errors",
    "initial_guess",
]

FloatArray = NDArray[np.float64]

#: Huber loss scale, in pixel noise standard deviations.
HUBER_SCALE = 3.0
#: A frame whose reprojection error exceeds this many pixel-noise sigmas is an outlier.
OUTLIER_SIGMAS = 5.0
#: A start whose reprojection RMS exceeds this many Huber scales gets a squared-loss fit
#: before the robust one (module docstring, step 2).
FAR_START = 10.0


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
        std: 1-sigma of each parameter (NaN: held), same units as ``x``: the sandwich of the
            error model ``errors`` (docs/calibrate.md, "Intervals").
        std_white: The same with the pixel errors taken as independent, ``s^2 (J^T J)^-1``:
            what the motion's geometry determines at the measured pixel noise (step 4's
            verdict).
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
        pixel: What was fitted per frame (m, 2P) [px] (P = 1: the tracked point; 4: the
            marker's corners, u, v of each in turn); ``residual`` has its shape.
        names: The parameters' names (:data:`~amsfe_sym.calibration.model.PARAMETERS`,
            or ``CORNER_PARAMETERS`` in the corner fit).
        fit: ``"centres"`` (one point a frame) or ``"corners"`` (the marker's 4 corners).
        marker_R: The marker's orientation in the tracked frame (marker -> tracked frame)
            at the solution (corner fit), else None.
        corner_start: The corner fit's start (its candidates' RMS), else None.
        errors: The error model the intervals come from (docs/calibrate.md, "Intervals").
    """

    R_cw: FloatArray
    position: FloatArray
    offset: FloatArray
    time_offset: float
    x: FloatArray
    R0: FloatArray
    std: FloatArray
    std_white: FloatArray
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
    names: tuple[str, ...] = PARAMETERS
    fit: str = "centres"
    marker_R: FloatArray | None = None
    corner_start: CornerStart | None = None
    errors: ErrorModel | None = None

    def half_width95(self) -> FloatArray:
        """The 95 % linearised half-width of each parameter (NaN where held)."""
        return Z95 * self.std

    def frame_errors(self) -> FloatArray:
        """Reprojection error [px] of each used frame (the RMS of its points' distances)."""
        return _frame_rms(self.residual[self.used])


def describe_errors(errors: ErrorModel) -> str:
    """One line: what the intervals take the pixel errors to be."""
    if errors.kind == "sandwich":
        return (
            "intervals: a sandwich over the frames (a frame's points one cluster, "
            f"correlation over {errors.bandwidth} consecutive frames)"
        )
    if errors.tau2 > 0:
        return (
            f"intervals: a frame's points share a common shift of {np.sqrt(errors.tau2):.3f} px "
            f"per axis besides {np.sqrt(errors.sigma2):.3f} px each (few frames: a block model)"
        )
    return f"intervals: independent pixel errors of {np.sqrt(errors.sigma2):.3f} px per axis"


def _frame_rms(res: FloatArray) -> FloatArray:
    """Per frame, the RMS of its points' distances [px], from residuals (m, 2P) [px]."""
    d2 = np.sum(res.reshape(res.shape[0], -1, 2) ** 2, axis=2)
    return np.sqrt(np.mean(d2, axis=1))


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
    model, x0, cs = _start(robot, links, obs, init, offset0, say)
    start_rms = init.rms if cs is None else cs.rms
    npar = model.np
    free = np.ones(npar, dtype=bool)
    held: dict[str, str] = {}
    if not fit_time_offset:
        free[9] = False
        x0[9] = 0.0
        held["time_offset"] = "held at 0 (--no-time-offset)"
    dropped: dict[int, str] = {}
    pts = obs.target.reshape(obs.m, -1, 2)
    box = (
        (pts[:, :, 0] >= 0)
        & (pts[:, :, 0] < robot.camera.width)
        & (pts[:, :, 1] >= 0)
        & (pts[:, :, 1] < robot.camera.height)
        & np.isfinite(pts).all(axis=2)
    )
    inside: NDArray[np.bool_] = np.asarray(box.all(axis=1), dtype=bool)
    for i in np.flatnonzero(~inside):
        dropped[int(i)] = "pixel outside the image"
    use = inside.copy()

    # 2. robust fit (after a squared-loss one from a far start), pixel noise, outliers
    if start_rms > FAR_START * HUBER_SCALE * pixel_std:
        x0, use, _ = _fit(model, obs, x0, free, use, dropped)
    x, use, nfev = _fit(model, obs, x0, free, use, dropped, "huber", HUBER_SCALE * pixel_std)
    res = _residual(model, obs, x)
    sigma = 1.4826 * float(np.median(np.abs(res[use])))
    err = _frame_rms(res)
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
        r = (pr.y - obs.target)[use]
        J3 = pr.J[use][:, :, free]
        Jf = J3.reshape(-1, int(free.sum()))
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
        errors = error_model(J3, r)
        sd, sv = stds(Jf, errors.middle)
        std = np.full(npar, np.nan)
        std[free] = sd
        # what the motion determines: its geometry at the measured pixel noise (step 4)
        std_white = np.full(npar, np.nan)
        std_white[free] = stds(Jf, s2 * (Jf.T @ Jf))[0]
        newly = undetermined(std_white, free, UNDETERMINED if limits is None else limits)
        if not newly:
            break
        for group, why in newly.items():
            for k in range(npar):
                if GROUP[k] == group:
                    free[k] = False
                    x[k] = offset0[k - 6] if group == "offset" else 0.0
            held[group] = why
    res = _residual(model, obs, x)
    R = model.rotation(x[0:3])
    say(describe_errors(errors))
    if cs is not None:
        say(f"corner fit: 4 corners a frame, {int(use.sum())} frames, {npar} parameters")
    return Calibration(
        R_cw=R,
        position=x[3:6].copy(),
        offset=x[6:9].copy(),
        time_offset=float(x[9]),
        x=x,
        R0=init.R_cw,
        std=std,
        std_white=std_white,
        free=free,
        held=held,
        pixel_std=float(np.sqrt(s2)),
        residual=res,
        used=use,
        dropped=dropped,
        initial=init,
        singular_values=sv,
        nfev=nfev,
        pixel=obs.target,
        stamp=obs.stamp,
        correlation=correlation(Jf, free, errors.middle),
        errors=errors,
        names=model.names,
        fit="centres" if cs is None else "corners",
        marker_R=None if cs is None else model.marker_rotation(x),
        corner_start=cs,
    )


def _start(
    robot: Robot,
    links: LinkAngles,
    obs: Observations,
    init: InitialGuess,
    offset0: FloatArray,
    say: Callable[[str], None],
) -> tuple[ReprojectionModel, FloatArray, CornerStart | None]:
    """The model and the start's parameters: the centre scan's (one point a frame), or with
    the marker's corners the corner start (:mod:`amsfe_sym.calibration.corner_start`)."""
    if obs.corners is None:
        model = ReprojectionModel(robot, links, obs.stamp, init.R_cw)
        return (
            model,
            np.concatenate([np.zeros(3), init.position, offset0, [init.time_offset]]),
            None,
        )
    from amsfe_sym.load.rotation import quaternion_to_matrix

    q = robot.spec.tracked.orientation
    Rm_spec = None if q is None else np.asarray(quaternion_to_matrix(q), dtype=np.float64)
    cs = corner_start(robot, links, obs, init, offset0, Rm_spec)
    tried = ", ".join(f"{k} {v:.2f} px" for k, v in cs.tried.items())
    say(f"corner start: {cs.source} (corners' reprojection RMS: {tried})")
    local = marker_corners_local(obs.marker_size)
    model = ReprojectionModel(robot, links, obs.stamp, cs.R_cw, local, cs.Rm)
    x0 = np.concatenate([np.zeros(3), cs.position, cs.offset, [cs.time_offset], np.zeros(3)])
    return model, x0, cs


def _residual(model: ReprojectionModel, obs: Observations, x: FloatArray) -> FloatArray:
    """Residuals (m, 2) [px] of every frame with link angles (NaN elsewhere)."""
    pr = model.project(x)
    res = pr.y - obs.target
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
            return (pr.y[idx] - obs.target[idx]).reshape(-1)

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
