"""``oosm``: the paper's Sec. 3.2 update = Bar-Shalom's algorithm A1 applied over the whole lag.

Bar-Shalom, "Update with out-of-sequence measurements in tracking: exact solution", IEEE
TAES 38(3), 2002, eqs. (30)-(39) ("A1"); the paper's eqs. (19)-(27) with the corrections of
``shared/PAPER-NOTES.md`` section 3. For a frame taken at ``kappa`` and delivered at ``k``
(lag ``L = k - kappa``), with the last encoder update at ``k`` (innovation ``nu``, its
covariance ``S``, jacobian ``H``, prior ``P(k|k-1)``):

- ``Phi = A_{k-1} ... A_kappa`` (stored forward jacobians), ``Fb = Phi^-1`` (jacobian of the
  backward map ``F_{kappa,k}``, eq. (22));
- ``Q = Q(k, kappa) = sum_j Phi(k, j+1) Qd_j Phi(k, j+1)^T`` (eq. (23));
- ``v_hat = Q H^T S^-1 nu`` (eq. (25), corrected: the innovation, not ``z(k) - z(k-1)``);
- ``x(kappa|k) = F_{kappa,k}(x(k|k) - v_hat)`` (eq. (24)), the backward map linearised about
  the filter's own trajectory (:func:`backward_map`): from the stored posteriors
  ``x(j|j)``, priors ``x(j+1|j) = F(x(j|j))`` and jacobians ``A_j``, one linear solve with
  ``Phi`` per frame instead of ``L`` Newton inverses of the transition (exact for a linear
  model; for a nonlinear one the error is second order in the corrections the updates made
  over the lag, see ``docs/explanation/estimation-algorithms.md``); with
  ``FilterConfig.backward_map = "inverse"`` it is the paper's form instead
  (:func:`backward_inverse`): ``L`` applications of the model's inverse transition
  (eq. (22)) from ``x(k|k) - v_hat``, and ``Fb`` below the jacobian of that map at the points
  it passes through (``Phi_b^-1``, ``Phi_b`` the product of the forward jacobians at the
  retrodicted states), not at the stored trajectory;
- ``Pvv = Q - Q H^T S^-1 H Q``, ``Pxv = Q - P(k|k-1) H^T S^-1 H Q``,
  ``P(kappa|k) = Fb (P(k|k) + Pvv - Pxv - Pxv^T) Fb^T`` (eq. (27), corrected);
- ``Pxz = (P(k|k) - Pxv) Fb^T Hc^T``, ``Szz = Hc P(kappa|k) Hc^T + Rc`` (eq. (26));
- ``x(k|kappa+) = x(k|k) + Pxz Szz^-1 (zc - hc(x(kappa|k)))``,
  ``P(k|kappa+) = P(k|k) - Pxz Szz^-1 Pxz^T`` (eqs. (19)-(20)).

Exact (linear-Gaussian) for a one-step lag; an approximation for longer lags, because the
encoder updates at ``kappa+1 .. k-1`` also depend on the process noise of the lag and only the
last one is accounted for. With no encoder update at ``k`` the ``nu`` terms are zero
(``v_hat = 0``, ``Pvv = Pxv = Q``). ``Fb`` is never formed: ``Hc Fb`` is one linear solve with
``Phi^T``. See ``docs/explanation/estimation-algorithms.md``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConvergenceError, EstimatorError, describe
from amsfe_sym.estimation.base import Estimator, StepInputs, StepReport
from amsfe_sym.estimation.ekf import (
    UpdateResult,
    cholesky_lower,
    cholesky_solve,
    measure,
    symmetrize,
)
from amsfe_sym.estimation.models import CameraFrame, TransitionModel

__all__ = [
    "A1Correction",
    "A1Retrodiction",
    "BackwardPass",
    "OosmAl1Estimator",
    "OosmEstimator",
    "a1_correct",
    "a1_retrodict",
    "al1_retrodict",
    "backward_inverse",
    "backward_map",
]

logger = logging.getLogger(__name__)


@dataclass(slots=True)
class A1Retrodiction:
    """Retrodiction terms of A1, still at time ``k`` (before the backward map).

    Attributes:
        x_shift: ``x(k|k) - v_hat(k, kappa|k)``; ``x(kappa|k) = F_{kappa,k}(x_shift)`` (eq. (24)).
        M: ``P(k|k) + Pvv - Pxv - Pxv^T``; ``P(kappa|k) = Fb M Fb^T`` (eq. (27), corrected).
        C: ``P(k|k) - Pxv``; ``Pxz = C Fb^T Hc^T`` (eq. (26)).
        v_hat: Retrodicted process noise ``Q H^T S^-1 nu`` (eq. (25), corrected).
    """

    x_shift: FloatArray
    M: FloatArray
    C: FloatArray
    v_hat: FloatArray


@dataclass(slots=True)
class A1Correction:
    """Result of :func:`a1_correct`.

    Attributes:
        accepted: The update was applied.
        reason: ``"ok"``, ``"gated"`` or ``"indefinite"`` (``Szz`` or the new ``P`` not
            positive definite: the multi-step approximation broke down).
        nis: NIS of the camera innovation with ``Szz`` (``nan`` if ``Szz`` is indefinite).
        x: ``x(k|kappa+)`` (the input ``x(k|k)`` when not accepted).
        P: ``P(k|kappa+)`` (the input ``P(k|k)`` when not accepted).
        W: Gain ``Pxz Szz^-1`` (``None`` when not computed).
        Szz: Retrodicted-measurement covariance ``Hc P(kappa|k) Hc^T + Rc``.
    """

    accepted: bool
    reason: str
    nis: float
    x: FloatArray
    P: FloatArray
    W: FloatArray | None
    Szz: FloatArray


def a1_retrodict(
    x_post: FloatArray, P_post: FloatArray, Q: FloatArray, last: UpdateResult | None
) -> A1Retrodiction:
    """A1 retrodiction terms (Bar-Shalom 2002 eqs. (30)-(32); paper eqs. (24)-(27) corrected).

    Args:
        x_post: ``x(k|k)``.
        P_post: ``P(k|k)``.
        Q: ``Q(k, kappa)``, process noise accumulated over the lag, symmetric.
        last: The encoder update at ``k`` (innovation, ``S`` factor, ``H``, ``P(k|k-1)``);
            ``None`` when there was none: the innovation terms are then zero.

    Returns:
        The :class:`A1Retrodiction`.
    """
    if last is None:
        D = P_post - Q
        return A1Retrodiction(x_post, D, D, np.zeros_like(x_post))
    H = last.H
    S_inv_HQ = cholesky_solve(last.S_chol, H @ Q)  # S^-1 H Q
    v_hat = S_inv_HQ.T @ last.nu  # Q H^T S^-1 nu (Q, S symmetric)
    Pvv = Q - (H @ Q).T @ S_inv_HQ
    Pxv = Q - (last.P_prior @ H.T) @ S_inv_HQ
    return _retrodiction(x_post, P_post, v_hat, Pvv, Pxv)


def _retrodiction(
    x_post: FloatArray, P_post: FloatArray, v_hat: FloatArray, Pvv: FloatArray, Pxv: FloatArray
) -> A1Retrodiction:
    """The common tail of A1 and Al1: ``M = P + Pvv - Pxv - Pxv^T`` (eq. (27) corrected),
    ``C = P - Pxv`` and ``x_shift = x - v_hat`` (eq. (24))."""
    M = symmetrize(P_post + Pvv - Pxv - Pxv.T)
    return A1Retrodiction(x_post - v_hat, M, P_post - Pxv, v_hat)


def al1_retrodict(
    x_post: FloatArray,
    P_post: FloatArray,
    Q: FloatArray,
    x_pred: FloatArray,
    P_pred: FloatArray,
) -> A1Retrodiction:
    """Retrodiction terms with an equivalent measurement over the lag (Al1, as reconstructed).

    Every update in ``(kappa, k]`` is replaced by one equivalent measurement of ``x(k)``
    (``H* = I``) that takes the prediction ``x(k|kappa), P(k|kappa)`` (from the posterior at
    ``kappa``, no updates) to the posterior ``x(k|k), P(k|k)``:
    ``S*^-1 = P(k|kappa)^-1 - P(k|kappa)^-1 P(k|k) P(k|kappa)^-1`` and
    ``S*^-1 nu* = P(k|kappa)^-1 (x(k|k) - x(k|kappa))``; then A1 is applied with
    ``P(k|kappa)`` in place of ``P(k|k-1)``. With ``T = P(k|kappa)^-1 Q``:
    ``v_hat = T^T (x(k|k) - x(k|kappa))``, ``Pxv = P(k|k) T``, ``Pvv = Q - T^T Q + T^T P(k|k) T``.
    This equals one Rauch-Tung-Striebel step over the whole lag taken as a single transition.

    Args:
        x_post: ``x(k|k)``.
        P_post: ``P(k|k)``.
        Q: ``Q(k, kappa)``.
        x_pred: ``x(k|kappa)``, the posterior at kappa predicted to k without updates.
        P_pred: ``P(k|kappa) = Phi P(kappa|kappa) Phi^T + Q(k, kappa)``.

    Returns:
        The :class:`A1Retrodiction` (used with :func:`a1_correct` exactly as A1's).
    """
    L = cholesky_lower(P_pred)
    if L is None:
        raise EstimatorError(
            describe(
                "P(k|kappa)",
                "positive definite",
                "a matrix Cholesky cannot factorise",
                "check the stored covariances and process noise",
            )
        )
    T = cholesky_solve(L, Q)  # P(k|kappa)^-1 Q
    v_hat = T.T @ (x_post - x_pred)
    Pxv = P_post @ T
    Pvv = Q - T.T @ Q + T.T @ P_post @ T
    return _retrodiction(x_post, P_post, v_hat, Pvv, Pxv)


def a1_correct(
    x_post: FloatArray,
    P_post: FloatArray,
    retro: A1Retrodiction,
    G: FloatArray,
    nu_c: FloatArray,
    R_c: FloatArray,
    gate: float,
) -> A1Correction:
    """A1 update of the current estimate with the late frame (paper eqs. (19)-(20), (26)).

    Args:
        x_post: ``x(k|k)``.
        P_post: ``P(k|k)``.
        retro: Output of :func:`a1_retrodict`.
        G: ``Hc Fb``: the camera jacobian at ``x(kappa|k)`` times the backward jacobian.
        nu_c: Camera innovation ``zc - hc(x(kappa|k))``.
        R_c: Camera noise covariance.
        gate: NIS threshold.

    Returns:
        The :class:`A1Correction`.
    """
    Szz = symmetrize(G @ retro.M @ G.T + R_c)
    L = cholesky_lower(Szz)
    if L is None:
        return A1Correction(False, "indefinite", float("nan"), x_post, P_post, None, Szz)
    nis = float(nu_c @ cholesky_solve(L, nu_c))
    if not nis <= gate:
        return A1Correction(False, "gated", nis, x_post, P_post, None, Szz)
    Pxz = retro.C @ G.T
    W = cholesky_solve(L, Pxz.T).T
    P_new = symmetrize(P_post - W @ Pxz.T)
    if cholesky_lower(P_new) is None:
        return A1Correction(False, "indefinite", nis, x_post, P_post, W, Szz)
    return A1Correction(True, "ok", nis, x_post + W @ nu_c, P_new, W, Szz)


def _singular_phi() -> EstimatorError:
    return EstimatorError(
        describe(
            "product of transition jacobians over the lag",
            "an invertible matrix",
            "a singular one",
            "the backward map of eq. (22) needs an invertible transition",
        )
    )


def backward_map(
    Phi: FloatArray, x_post_kappa: FloatArray, corrections: FloatArray, target: FloatArray
) -> FloatArray:
    """``x(kappa|k) = F_{kappa,k}(target)`` (eq. (24)) to first order about the filter's
    trajectory: ``x(kappa|kappa) + Phi^-1 r``.

    One backward step linearised at the stored posterior ``x(j|j)``, whose image
    ``F(x(j|j)) = x(j+1|j)`` and jacobian ``A_j`` the forward pass computed, is
    ``F^-1(y) = x(j|j) + A_j^-1 (y - x(j+1|j))``; chained over the lag it gives
    ``r = sum_{i=kappa+1}^{k-1} Phi(k, i) c_i + target - x(k|k-1)`` with the updates'
    corrections ``c_i = x(i|i) - x(i|i-1)``.  Exact for a linear model; otherwise the error
    is ``O(|F''| |x(j) - x(j|j)|^2)`` per step.

    Args:
        Phi: ``A_{k-1} ... A_kappa``.
        x_post_kappa: ``x(kappa|kappa)``, the posterior the prediction from kappa started at.
        corrections: ``sum_{i=kappa+1}^{k-1} Phi(k, i) c_i``, accumulated with the stored
            jacobians (``s <- A_j s + c_{j+1}`` for ``j = kappa .. k-2``, then
            ``s <- A_{k-1} s``).
        target: The state at ``k`` to map back (``x(k|k) - v_hat``) minus ``x(k|k-1)``.

    Returns:
        ``x(kappa|k)``.

    Raises:
        EstimatorError: If ``Phi`` is singular.
    """
    try:
        step = np.linalg.solve(Phi, corrections + target)
    except (np.linalg.LinAlgError, ValueError):
        raise _singular_phi() from None
    return np.asarray(x_post_kappa + step, dtype=np.float64)


@dataclass(slots=True)
class BackwardPass:
    """The paper's backward map over a lag (eqs. (22), (24)), from :func:`backward_inverse`.

    Attributes:
        x: ``x(kappa|k) = F^-1(... F^-1(x_shift, u_{k-1}) ..., u_kappa)``.
        Phi: ``A(x_{k-1}) ... A(x_kappa)``: the forward jacobians at the retrodicted states
            ``x_j``; the backward map's jacobian is ``Phi^-1`` (the inverse of the forward
            one at the matching point, ``shared/PAPER-NOTES.md`` section 1).
    """

    x: FloatArray
    Phi: FloatArray


def backward_inverse(
    model: TransitionModel, x_end: FloatArray, inputs: list[FloatArray]
) -> BackwardPass:
    """``x(kappa|k) = F_{kappa,k}(x_end)`` through the model's inverse transition (eq. (22)).

    For ``j = k-1 .. kappa``: ``x_j = F^-1(x_{j+1}, u_j)`` (``model.inverse``), then
    ``A_j = dF/dx(x_j, u_j)`` (``model.step``); ``Phi = A_{k-1} ... A_kappa``.

    Args:
        model: The transition (its ``inverse`` and ``step``).
        x_end: The state at ``k`` to map back (``x(k|k) - v_hat``, eq. (24)).
        inputs: ``u_kappa .. u_{k-1}`` in time order (``L`` entries).

    Returns:
        The :class:`BackwardPass`.

    Raises:
        ConvergenceError: An inverse step did not converge (the caller refuses the frame).
    """
    x = np.asarray(x_end, dtype=np.float64)
    Phi = np.eye(x.shape[0])
    for u_j in reversed(inputs):
        x = model.inverse(x, u_j)
        Phi = Phi @ model.step(x, u_j)[1]
    return BackwardPass(x, Phi)


class OosmEstimator(Estimator):
    """EKF + the paper's out-of-sequence camera update (A1 over the whole lag).

    Keeps, for the last ``buffer_steps`` steps, the inputs, the forward jacobians, the process
    noise and the start and end states of each prediction, and the last encoder update (a late
    frame costs ``L`` N^3 products and no model evaluation with the default
    ``backward_map = "linearised"``; ``"inverse"`` adds ``L`` inverse transitions and ``L``
    jacobians of the model, and refuses the frame when an inverse does not converge).
    A frame with lag 0 gets a standard update; an older one the A1 update above. When A1
    yields an indefinite covariance (a long lag with many encoder updates in between), the
    frame is rejected with a warning rather than corrupting ``P``.
    """

    name: ClassVar[str] = "oosm"
    needs_history: ClassVar[bool] = True

    def _setup(self) -> None:
        n, B = self.nx, self.config.buffer_steps
        self._A = np.empty((B, n, n))
        self._Q = np.empty((B, n, n))
        self._x_post = np.empty((B, n))  # x(j|j) the prediction from j started at
        self._x_prior = np.empty((B, n))  # x(j+1|j) = F(x(j|j), u_j)
        self._u: list[FloatArray | None] = [None] * B
        self._last: UpdateResult | None = None  # accepted encoder update at self.k, if any

    def _step(self, step: StepInputs, report: StepReport) -> None:
        u, z_encoder, frames = step.u, step.z_encoder, step.frames
        k_new = self.k + 1
        slot = self.k % self.config.buffer_steps
        self._x_post[slot] = self.x
        pred = self._predict(u)
        self._A[slot] = pred.A
        self._Q[slot] = pred.Q
        self._x_prior[slot] = pred.x
        self._u[slot] = u
        result = self._encoder_update(z_encoder, report)
        self._last = result if result is not None and result.accepted else None
        for frame in frames:
            if frame.exposure_step == k_new:
                upd = self._frame_update_now(frame.z)
                report.frame_result(frame.exposure_step, upd.accepted, upd.nis, self._gate_camera)
            else:
                self._late_frame(frame, k_new, report)

    def _retrodict(self, kappa: int, k: int, Phi: FloatArray, Q: FloatArray) -> A1Retrodiction:
        """A1 with the last encoder update (none at k: the innovation terms vanish)."""
        return a1_retrodict(self.x, self.P, Q, self._last)

    def _inputs(self, kappa: int, k: int) -> list[FloatArray]:
        """The stored inputs ``u_kappa .. u_{k-1}``."""
        B = self.config.buffer_steps
        inputs = []
        for j in range(kappa, k):
            u_j = self._u[j % B]
            if u_j is None:  # cannot happen: the base class refuses frames older than the buffer
                raise EstimatorError(f"oosm: no stored input for step {j}")
            inputs.append(u_j)
        return inputs

    def _late_frame(self, frame: CameraFrame, k: int, report: StepReport) -> None:
        kappa = frame.exposure_step
        B = self.config.buffer_steps
        n = self.nx
        Phi = np.eye(n)
        Q = np.zeros((n, n))
        s = np.zeros(n)
        for j in range(kappa, k):  # eq. (23): Q(k, kappa) = sum_j Phi(k, j+1) Qd_j Phi(k, j+1)^T
            A_j = self._A[j % B]
            Phi = A_j @ Phi
            Q = A_j @ Q @ A_j.T + self._Q[j % B]
            s = A_j @ s  # the updates' corrections, carried to k (backward_map)
            if j + 1 < k:
                s += self._x_post[(j + 1) % B] - self._x_prior[j % B]
        Q = symmetrize(Q)
        retro = self._retrodict(kappa, k, Phi, Q)
        if self.config.backward_map == "inverse":  # eqs. (22), (24): the paper's form
            try:
                back = backward_inverse(self.model, retro.x_shift, self._inputs(kappa, k))
            except ConvergenceError as exc:
                report.reject(f"camera frame kappa={kappa} (lag {k - kappa}): {exc}")
                return
            x_r, Phi = back.x, back.Phi
        else:  # eq. (24) linearised about the stored trajectory
            target = retro.x_shift - self._x_prior[(k - 1) % B]
            x_r = backward_map(Phi, self._x_post[kappa % B], s, target)
        if not np.isfinite(x_r).all():
            raise EstimatorError(
                describe(
                    "retrodicted state x(kappa|k)",
                    "finite",
                    "NaN or inf",
                    "check the transition's jacobians on the current trajectory",
                )
            )
        z_hat, Hc = measure(self.camera, x_r)
        try:
            # Hc Fb = Hc Phi^-1.  np.linalg.solve, not scipy.linalg.solve: on these small
            # systems scipy's wrapper with multithreaded OpenBLAS cost 0.9-1.9 ms a call
            # (measured in the study), numpy's ~5 us.
            G = np.asarray(np.linalg.solve(Phi.T, Hc.T).T, dtype=np.float64)
        except (np.linalg.LinAlgError, ValueError):
            raise _singular_phi() from None
        if not np.isfinite(G).all():
            raise EstimatorError(
                describe("Hc Fb", "finite", "NaN or inf", "check the camera jacobian")
            )
        corr = a1_correct(
            self.x, self.P, retro, G, frame.z - z_hat, self.R_camera, self._gate_camera
        )
        if corr.reason == "indefinite":
            report.reject(
                f"camera frame kappa={kappa} (lag {k - kappa}): the A1 update gives an "
                "indefinite covariance (the one-step retrodiction does not hold over this lag; "
                "use 'replay' or 'cloning')"
            )
            return
        report.frame_result(kappa, corr.accepted, corr.nis, self._gate_camera)
        if corr.accepted:
            self.x, self.P = corr.x, corr.P


class OosmAl1Estimator(OosmEstimator):
    """``oosm`` with Al1's equivalent measurement instead of the last encoder innovation.

    Not in :data:`~amsfe_sym.estimation.registry.ESTIMATORS` (the paper's method is
    ``oosm``); offered because the paper's A1-over-the-lag breaks down (indefinite
    retrodicted covariance) when several encoder updates fall inside the lag, which Al1 does
    not. Exact for a one-step lag, or when no update falls strictly inside the lag; an
    approximation otherwise (see ``docs/explanation/estimation-algorithms.md``). Also stores the
    posterior of each step of the buffer window (``(buffer_steps + 1) nx^2`` floats).
    """

    name: ClassVar[str] = "oosm-al1"

    def _setup(self) -> None:
        super()._setup()
        size = self.config.buffer_steps + 1
        self._post_x = np.empty((size, self.nx))
        self._post_P = np.empty((size, self.nx, self.nx))
        self._store_posterior(self.k)

    def _store_posterior(self, j: int) -> None:
        s = j % (self.config.buffer_steps + 1)
        self._post_x[s] = self.x
        self._post_P[s] = self.P

    def _step(self, step: StepInputs, report: StepReport) -> None:
        super()._step(step, report)
        self._store_posterior(self.k + 1)

    def _retrodict(self, kappa: int, k: int, Phi: FloatArray, Q: FloatArray) -> A1Retrodiction:
        size = self.config.buffer_steps + 1
        x_pred = self._post_x[kappa % size].copy()
        for u_j in self._inputs(kappa, k):  # x(k|kappa): the posterior at kappa, no updates
            x_pred = self.model.step(x_pred, u_j)[0]
        P_pred = symmetrize(Phi @ self._post_P[kappa % size] @ Phi.T + Q)
        return al1_retrodict(self.x, self.P, Q, x_pred, P_pred)
