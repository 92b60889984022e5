"""Where the links are at a log's first sample when only the motor angles are known.

A log of effort kind ``none`` (docs/explanation/effort.md) gives the motor angles ``qm`` and rates,
not
the link angles ``q``: on an elastic arm the springs deflect under gravity by
``qm - q = Ks^-1 g(q)`` (eq. 1b at rest), 1.45 rad on the paper's soft arm.  Started at
``q = qm`` the estimator is 3 sigma off, its camera frames are gated out, and the encoders
alone never see the link (docs/explanation/effort.md section 2).  This module finds the link angles
that
balance the springs at the first sample,

    tau(q) = Ks (qm - q),    tau(q) = g(q, theta) + C(q, qd) qd    (eq. 1a with qdd = 0),

and the 1-sigma of what that balance does not know (the arm may be accelerating: the
inertial torque ``M(q) qdd`` and the model's error, ``tau_std`` [N m]).

A balance can have several solutions: on the soft paper arm at its start (q = (0.5, 0.5)
rad) the spring is weaker than the gravity gradient, ``dtau/dq + Ks`` is indefinite, and the
closed loop holds the arm at an equilibrium that is unstable open loop, while Newton from
``q = qm`` lands on a stable one 1 rad away.  So every solution found from a few seeds is a
candidate, and a camera frame (when the log has one) chooses: the candidate whose predicted
pixel is the most likely (its normalized innovation, eq. 8's camera with the candidate's
covariance).  The camera also gives a seed: the link angles that put the tracked point on
the frame's pixel (Gauss-Newton, minimum-norm steps from ``qm``).

Pure numpy: the robot enters as callables (the generated library's ``bias`` and
``camera_measure`` in the applications layer).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import EstimatorError, describe

__all__ = ["FirstFrame", "LinkStart", "balance_candidates", "camera_seed", "static_link_start"]

#: q -> tau(q) [N m]: the torque the springs hold at the first sample (gravity and Coriolis).
Torque = Callable[[FloatArray], FloatArray]
#: q -> (pixel y [px], dy/dq [px/rad]).
Camera = Callable[[FloatArray], tuple[FloatArray, FloatArray]]

#: Newton stops when the balance residual is below this [N m] (per joint, max).
BALANCE_TOL = 1e-9
#: Largest Newton step per joint [rad]: keeps a step from jumping across branches.
MAX_STEP = 0.5
MAX_ITER = 60


@dataclass(frozen=True)
class FirstFrame:
    """A camera frame that chooses between balances.

    Attributes:
        y: The frame's pixel [px], (2,).
        R: Its pixel covariance [px^2], (2, 2).
        camera: The camera of eq. 8 at link angles q: (y [px], dy/dq [px/rad]).
        shift: Motor motion from the first sample to the frame's exposure,
            ``qm(kappa) - qm(0)`` [rad]: the candidate is moved by it before it is seen
            (the deflection held over that time).
    """

    y: FloatArray
    R: FloatArray
    camera: Camera
    shift: FloatArray


@dataclass(frozen=True)
class LinkStart:
    """The link angles of the first sample and their uncertainty.

    Attributes:
        q: Link angles [rad], (n,).
        cov: Their covariance [rad^2], (n, n): ``H^-1 tau_std^2 H^-T`` with
            ``H = dtau/dq + Ks`` (what the balance does not know) plus the motor angle's.
        candidates: Every balance found [rad] (the chosen one among them).
        frame_nis: Per candidate, the first frame's normalized innovation (empty without a
            frame).
        stable: Whether ``H`` of the chosen balance is positive definite (a rest the springs
            hold without a controller).
    """

    q: FloatArray
    cov: FloatArray
    candidates: tuple[FloatArray, ...]
    frame_nis: tuple[float, ...]
    stable: bool

    @property
    def std(self) -> FloatArray:
        """1-sigma of each link angle [rad]."""
        return np.sqrt(np.diag(self.cov))


def _jacobian(f: Torque, q: FloatArray, h: float = 1e-6) -> FloatArray:
    """Central differences of ``f`` at ``q``, (m, n)."""
    cols = []
    for j in range(q.size):
        e = np.zeros_like(q)
        e[j] = h
        cols.append((f(q + e) - f(q - e)) / (2 * h))
    return np.stack(cols, axis=1)


def _balance(torque: Torque, Ks: FloatArray, qm: FloatArray) -> Torque:
    def r(q: FloatArray) -> FloatArray:
        return np.asarray(torque(q), dtype=float).ravel() - Ks * (qm - q)

    return r


def _newton(r: Torque, q0: FloatArray, settle_shift: float | None = None) -> FloatArray | None:
    """A root of ``r`` from ``q0`` (steps clipped to :data:`MAX_STEP`), or None.

    ``settle_shift``: the modified Newton of a minimization instead: the symmetric part of
    the jacobian shifted until its smallest eigenvalue is ``settle_shift`` > 0, so every step
    goes down the arm's potential (``r`` is its gradient when the rates are zero) and the
    iteration settles on a stable balance, as a released link would."""
    q = np.array(q0, dtype=float)
    for _ in range(MAX_ITER):
        res = r(q)
        if not np.all(np.isfinite(res)):
            return None
        if np.max(np.abs(res)) < BALANCE_TOL:
            return q
        H = _jacobian(r, q)
        if settle_shift is not None:
            lam = float(np.min(np.linalg.eigvalsh(0.5 * (H + H.T))))
            H = H + max(0.0, settle_shift - lam) * np.eye(q.size)
        try:
            dq = np.linalg.solve(H, -res)
        except np.linalg.LinAlgError:
            return None
        q = q + dq * min(1.0, MAX_STEP / max(np.max(np.abs(dq)), 1e-300))
    return None


def balance_candidates(
    torque: Torque, Ks: FloatArray, qm: FloatArray, seeds: Sequence[FloatArray]
) -> list[FloatArray]:
    """The distinct solutions of ``tau(q) = Ks (qm - q)`` that Newton reaches from ``seeds``,
    then the stable one a settling iteration reaches from the first seed (:func:`_newton`),
    in that order.

    Args:
        torque: ``tau(q)`` [N m] (gravity, and Coriolis at the measured rates).
        Ks: Spring stiffness per joint [N m/rad].
        qm: Motor angles of the sample [rad].
        seeds: Where Newton starts [rad].
    """
    r = _balance(torque, Ks, qm)
    shift = 0.1 * float(np.min(Ks))
    tries = [_newton(r, s) for s in seeds]
    if seeds:
        tries.append(_newton(r, seeds[0], settle_shift=shift))
    found: list[FloatArray] = []
    for q in tries:
        if q is not None and not any(np.max(np.abs(q - c)) < 1e-6 for c in found):
            found.append(q)
    return found


def camera_seed(camera: Camera, y: FloatArray, q0: FloatArray, iters: int = 30) -> FloatArray:
    """Link angles near ``q0`` that put the tracked point on pixel ``y`` [rad]: Gauss-Newton
    with minimum-norm steps (the camera sees 2 of the n angles), clipped to
    :data:`MAX_STEP`."""
    q = np.array(q0, dtype=float)
    for _ in range(iters):
        yq, J = camera(q)
        dq = np.linalg.lstsq(np.atleast_2d(J), np.asarray(y) - yq, rcond=None)[0]
        q = q + dq * min(1.0, MAX_STEP / max(np.max(np.abs(dq)), 1e-300))
        if np.max(np.abs(dq)) < 1e-10:
            break
    return q


def static_link_start(
    torque: Torque,
    Ks: FloatArray,
    qm: FloatArray,
    tau_std: float,
    qm_std: float,
    frame: FirstFrame | None = None,
) -> LinkStart:
    """The link angles balancing the springs at the first sample, chosen by the first camera
    frame when there is one (module docstring).

    Args:
        torque: ``tau(q)`` [N m], the torque the springs hold (gravity and Coriolis).
        Ks: Spring stiffness per joint [N m/rad].
        qm: The first sample's motor angles [rad].
        tau_std: 1-sigma of the torque the balance misses [N m] (inertia, model error).
        qm_std: 1-sigma of the motor angles [rad] (moves the balance with it).
        frame: A camera frame near the start, or None.

    Raises:
        EstimatorError: no balance found (the torque is not finite near the motor angles).
    """
    qm = np.asarray(qm, dtype=float)
    seeds = [qm]
    if frame is not None:
        seeds.append(camera_seed(frame.camera, frame.y, qm + frame.shift) - frame.shift)
    cands = balance_candidates(torque, Ks, qm, seeds)
    if not cands:
        raise EstimatorError(
            describe(
                "the link angles at the log's first sample",
                "a solution of g(q) + C(q, qd) qd = Ks (qm - q) (the springs' balance)",
                f"none by Newton from the motor angles {np.round(qm, 4).tolist()}",
                "give the start yourself: --scenario with [estimate0] q (docs/how-to/logs.md)",
            )
        )
    r = _balance(torque, Ks, qm)
    covs = []
    for c in cands:
        H = _jacobian(r, c)
        Hi = np.linalg.inv(H)
        G = Hi * Ks  # dq/dqm = H^-1 Ks
        covs.append(tau_std**2 * Hi @ Hi.T + qm_std**2 * G @ G.T)
    nis: list[float] = []
    if frame is not None:
        for c, P in zip(cands, covs, strict=True):
            yq, J = frame.camera(c + frame.shift)
            S = J @ P @ J.T + frame.R
            nu = frame.y - yq
            nis.append(float(nu @ np.linalg.solve(S, nu)))
    best = int(np.argmin(nis)) if nis else 0
    H = _jacobian(r, cands[best])
    stable = bool(np.all(np.linalg.eigvalsh(0.5 * (H + H.T)) > 0))
    return LinkStart(cands[best], covs[best], tuple(cands), tuple(nis), stable)
