"""The link angles ``amsfe estimate LOG --robot ROBOT`` starts from (docs/how-to/logs.md, "Where
the estimate starts"), by what the log's effort says of the springs at its first sample:

- ``joint_torque``: the spring torque is measured, so ``q = qm - tau_J / Ks`` is exact
  (positions said to be the link's: ``q`` is the position itself);
- ``none`` (motor angles only): the springs' balance at the first sample,
  ``g(q) + C(q, qd) qd = Ks (qm - q)``, solved by Newton on the generated library's ``bias``
  and chosen among its solutions by the first camera frame
  (:func:`~amsfe_sym.estimation.static_start.static_link_start`), with the 1-sigma of what
  a balance does not know (the arm's acceleration, the model's error: ``tau_std``);
- ``applied``: the measured positions (the motor equation sees the deflection from the
  first encoder update on).

The gravity comes from the robot's own library (its ``bias`` function at the measured
rates), not from Pinocchio: the same model the estimator predicts with, and nothing more
to load.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.estimation.static_start import FirstFrame, static_link_start

if TYPE_CHECKING:
    from amsfe_sym.estimation.effort import EffortSpec
    from amsfe_sym.logs.read import RobotLog
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import Scenario

__all__ = ["LogLinkStart", "log_link_start", "scenario_start"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LogLinkStart:
    """The link angles of the log's first sample.

    Attributes:
        q: Link angles [rad], (n,).
        std: Their 1-sigma [rad] (one value: the largest joint's, as ``[estimate0] std``
            takes one per block), or None to keep the scenario's.
        how: What they come from, for the printout.
    """

    q: FloatArray
    std: float | None
    how: str


def log_link_start(
    log: RobotLog,
    lib: ModelLibrary,
    theta: FloatArray,
    *,
    positions: str = "motor",
    scale: float = 1.0,
    tau_std: float,
    qm_std: float,
    pixel_var: float,
) -> LogLinkStart:
    """The link angles the estimate of ``log`` starts from (module docstring).

    Args:
        log: The log read on its ticks (its first encoder sample, effort and frames).
        lib: The robot's library (``bias``, ``camera_measure``, Ks).
        theta: The estimator's initial theta.
        positions: What the log's positions are (``"motor"`` or ``"link"``).
        scale: [N m per logged unit] of the effort.
        tau_std: 1-sigma of the torque a balance misses [N m].
        qm_std: 1-sigma of the motor angles at the start [rad].
        pixel_var: The camera's pixel variance [px^2].
    """
    n = lib.n
    z0 = np.asarray(log.z[0], dtype=float)
    pos, qd0 = z0[:n].copy(), z0[n:].copy()
    Ks = lib.stiffness(theta)
    if log.effort_kind == "joint_torque" and log.effort is not None:
        if positions == "link":
            return LogLinkStart(pos, None, "the logged positions (link angles)")
        tau_j = np.asarray(log.effort[0], dtype=float) * scale
        return LogLinkStart(pos - tau_j / Ks, None, "qm - tau_J / Ks of the first sample")
    if log.effort_kind != "none":
        return LogLinkStart(pos, None, "the logged positions")
    bias = lib.function("bias")

    def torque(q: FloatArray) -> FloatArray:
        return np.asarray(bias(q, qd0, theta)[0], dtype=float).ravel()

    frame = _first_frame(log, lib, theta, pixel_var)
    start = static_link_start(torque, Ks, pos, tau_std, qm_std, frame)
    how = f"the springs' balance at the first sample ({len(start.candidates)} found"
    how += ", chosen by the first camera frame)" if start.frame_nis else ")"
    return LogLinkStart(start.q, float(np.max(start.std)), how)


def scenario_start(
    sc: Scenario, log: RobotLog, lib: ModelLibrary, effort: EffortSpec, tau_std: float
) -> LogLinkStart:
    """:func:`log_link_start` with the scenario's numbers: theta ``[estimate0] theta`` (or
    the robot's initial), the motor angles' 1-sigma ``[estimate0] std qm``, the pixel
    variance of the filter's camera R (``[filter] camera_pixel_std``, else ``[camera]
    pixel_std`` with the rounding's 1/12 px^2), the effort's ``positions`` and ``scale``;
    ``tau_std`` [N m] the torque a balance misses."""
    e0, cam = sc.estimate0, sc.camera
    theta = np.array(e0.theta, dtype=float) if e0.theta else lib.theta_initial
    rounding = 1 / 12 if cam.round_to_pixel else 0.0  # as the filter's R (signals.camera)
    px = sc.filter.camera_pixel_std
    return log_link_start(
        log,
        lib,
        theta,
        positions=effort.positions,
        scale=effort.scale,
        tau_std=tau_std,
        qm_std=float(dict(e0.std).get("qm", 0.01)),
        pixel_var=px**2 if px else cam.pixel_std**2 + rounding,
    )


def _first_frame(
    log: RobotLog, lib: ModelLibrary, theta: FloatArray, pixel_var: float
) -> FirstFrame | None:
    """The log's earliest camera frame exposed within the robot's first camera period (l
    steps: later, the deflection held since the start would be a guess) with an encoder
    sample at its exposure, or None."""
    n, K = lib.n, log.z.shape[0]
    last = min(K - 1, max(lib.manifest.camera.period, 1))
    usable = [
        f
        for f in log.frames
        if 0 <= f.exposure_step <= last and np.isfinite(log.z[f.exposure_step]).all()
    ]
    if not usable:
        return None
    f = min(usable, key=lambda fr: fr.exposure_step)
    measure = lib.function("camera_measure")

    def camera(q: FloatArray) -> tuple[FloatArray, FloatArray]:
        y, J, _depth = measure(q, theta)
        return np.asarray(y, dtype=float).ravel(), np.asarray(J, dtype=float).reshape(2, n)

    shift = np.asarray(log.z[f.exposure_step, :n] - log.z[0, :n], dtype=float)
    return FirstFrame(np.asarray(f.z, dtype=float), pixel_var * np.eye(2), camera, shift)
