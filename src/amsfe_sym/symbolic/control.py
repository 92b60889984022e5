"""The paper's control laws as CasADi functions, built from the same model as the transition.

Notation (PAPER-NOTES section 4; the extracted paper lost its bars and tildes):

- tracking error ``e = q - q_d`` (30); estimation error ``e_e = q - qhat``.  Only
  ``e - e_e = qhat - q_d`` is computable; the laws use the estimate (certainty equivalence:
  ``e ~ qhat - q_d``, ``e_e`` enters only through (31), where it is exact);
- reference velocity ``v_t = qd_d - Lt (qhat - q_d)`` (31);
- filtered error ``sigma = qdhat - v_t`` (32);
- terminal surface ``s = sigma + lam e^p`` (33) with the sign-preserving power
  ``x^p := sign(x) |x|^p``, ``p = p1/p2 = 3/5``;
- reaching law ``s(k+1) = (I - T h) s(k) - T eps sgn(s(k))`` (34).  ``sgn`` is replaced by
  the saturation ``sat(s/phi)`` with boundary-layer width ``phi``; ``phi = 0`` is ``sgn``.

The one-step prediction of the error used by (37), ``e(k+1) = e + T (sigma - Lt e + Lt e_e)``
(40), is ``qhat - q_d + T (qdhat - qd_d)`` on the estimate.

Functions (every gain is an input, so changing a gain never recompiles):

``control_amsfe_paper``
    Law (37) as printed: ``u = (Mhat/T) [Fhat + v_t(k) - v_t(k-1) + lam e^p - lam e(k+1)^p
    - T (h s + eps sat(s/phi))]`` with ``Mhat = M(qbar, thetahat)``, ``qbar = qhat + T qdhat``
    (29a), and ``Fhat`` the F of (29b) at the estimates:
    ``F = qd - M(qbar)^-1 (M(q) qd + T f(q, qd)) + M(qbar)^-1 [Mm (qmd(k+1) - qmd(k))
    + T Fm qmd(k)]``, where ``f = d/dq (1/2 qd^T M qd) - g`` is the link force of (1b).
    The caller chooses how ``qmd(k+1)`` is estimated (an input): substituting the true
    ``qmd(k+1)`` of (1c) cancels u out of (29b) exactly (PAPER-NOTES section 4).
``control_dtsmc_paper``
    The baseline (54): the same law with the surface ``s = e_dot + lam e^p``, i.e. (37) with
    ``Lt = 0`` (then ``v_t = qd_d`` and ``sigma = e_dot``); applied to sensor values.
``control_amsfe``
    The working variant (docs/control.md): the terminal sliding law of (31)-(37) designed on the
    rigid-link part of the model with the spring torque as the virtual input,
    ``qd(k+1) = qd + T M^-1 (tau - b)``, which gives
    ``tau_d = b + (M/T) [v_t(k+1) - v_t(k) + lam e^p - lam e(k+1)^p - T (h s + eps sat(s/phi))]``
    (``v_t(k+1)`` from the trajectory and the predicted error: exact on its design model),
    clipped to ``|tau_d| <= tau_max``; then the motor angle that produces it,
    ``qm_d = qhat + Ks^-1 tau_d``, is realized by a motor loop with smooth feedforward
    (Spong's cascade for flexible joints):
    ``u = Ks (qmhat - qhat) + Fm qmdhat
    + Mm (qmdd_r + wm^2 (qm_d - qmhat) + 2 wm (qmd_r - qmdhat))``,
    where ``qm_r = q_d + Ks^-1 (M(q_d) qdd_d + b(q_d, qd_d))`` is the motor angle of the desired
    motion and ``qmd_r``, ``qmdd_r`` its exact time derivatives (forward-mode AD along the
    trajectory's jerk and snap).
``control_dtsmc``
    ``control_amsfe`` with ``Lt = 0`` (the baseline surface of (54)) on sensor values.

Outputs of every law: ``u`` [N m], ``s`` (33), ``e_next`` (the predicted error (40)) and
``bound`` = ``|dv - lam e(k+1)^p + lam e^p|`` per joint, the norm inside the gain condition (38)
(``dv`` the reference-velocity increment the law used).
"""

from __future__ import annotations

import casadi as ca

from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.linalg import ldl_solve
from amsfe_sym.symbolic.transition import Transition

__all__ = ["CONTROL_GAINS", "build_control_functions", "fpow", "sat"]

#: Gain inputs of every law, in order (each an n-vector except ``p``, a scalar).
CONTROL_GAINS = ("h", "lam", "Lt", "eps", "p", "phi")
#: Extra inputs of the cascaded laws: motor-loop bandwidth [rad/s], spring-torque limit [N m].
CASCADE_GAINS = ("wm", "tau_max")


def fpow(x: ca.SX, p: ca.SX) -> ca.SX:
    """Sign-preserving fractional power ``x^p := sign(x) |x|^p`` (eq. 33)."""
    return ca.sign(x) * ca.fabs(x) ** p


def sat(s: ca.SX, phi: ca.SX) -> ca.SX:
    """``sat(s/phi)`` in [-1, 1]; ``phi = 0`` gives ``sgn(s)`` (``s/tiny`` saturates)."""
    return ca.fmin(ca.fmax(s / ca.fmax(phi, 1e-300), -1.0), 1.0)


class _Surface:
    """The surface quantities (30)-(33) and the predicted error (40) at one tick."""

    def __init__(
        self,
        q: ca.SX,
        qd: ca.SX,
        q_d: ca.SX,
        qd_d: ca.SX,
        lam: ca.SX,
        Lt: ca.SX,
        p: ca.SX,
        T: float,
    ) -> None:
        self.e = q - q_d  # (30), on the estimate
        self.vt = qd_d - Lt * self.e  # (31)
        self.sigma = qd - self.vt  # (32)
        self.s = self.sigma + lam * fpow(self.e, p)  # (33)
        self.e_next = self.e + T * (qd - qd_d)  # (40) with e_e -> 0 (certainty equivalence)
        self.lam_terms = lam * fpow(self.e, p) - lam * fpow(self.e_next, p)


def build_control_functions(tree: RigidBodyTree, tr: Transition) -> list[ca.Function]:
    """The four generated control laws of the module docstring, for one robot."""
    robot = tree.robot
    n, p_, T = tree.n, tree.p, float(robot.spec.model.T)
    N = 4 * n + p_
    Mm, Fm = ca.DM(robot.Mm), ca.DM(robot.Fm)
    x = ca.SX.sym("x", N)
    q, qd, qm, qmd, th = tr.split(x)
    g = {k: ca.SX.sym(k, 1 if k == "p" else n) for k in (*CONTROL_GAINS, *CASCADE_GAINS)}
    gin = [(k, g[k]) for k in CONTROL_GAINS]
    cin = [(k, g[k]) for k in CASCADE_GAINS]
    q_d, qd_d = ca.SX.sym("q_d", n), ca.SX.sym("qd_d", n)
    Ks = tr.stiffness(th)

    # ---------------------------------------------------------------- (37) and (54) as printed
    qmd_next, vt_prev = ca.SX.sym("qmd_next", n), ca.SX.sym("vt_prev", n)
    qbar = q + T * qd  # (29a)
    Mbar = tree.mass_matrix(qbar, th)
    Fhat = (
        qd
        - ldl_solve(Mbar, ca.mtimes(tree.mass_matrix(q, th), qd) + T * tr.f_link(q, qd, th))
        + ldl_solve(Mbar, Mm * (qmd_next - qmd) + T * Fm * qmd)
    )

    def printed(name: str, Lt: ca.SX) -> ca.Function:
        sf = _Surface(q, qd, q_d, qd_d, g["lam"], Lt, g["p"], T)
        dv = sf.vt - vt_prev
        reach = T * (g["h"] * sf.s + g["eps"] * sat(sf.s, g["phi"]))
        u = ca.mtimes(Mbar, Fhat + dv + sf.lam_terms - reach) / T
        ins = [("x", x), ("qmd_next", qmd_next), ("q_d", q_d), ("qd_d", qd_d)]
        ins += [("vt_prev", vt_prev), *gin]
        if name == "control_dtsmc_paper":  # Lt is fixed to 0: keep the input for one signature
            ins = [(k, v if k != "Lt" else ca.SX.sym("Lt_unused", n)) for k, v in ins]
        outs = [("u", u), ("s", sf.s), ("vt", sf.vt), ("e_next", sf.e_next)]
        outs += [("bound", ca.fabs(dv + sf.lam_terms))]
        return _fn(name, ins, outs)

    fns = [printed("control_amsfe_paper", g["Lt"]), printed("control_dtsmc_paper", ca.SX.zeros(n))]

    # ---------------------------------------------------------------- the cascade (ours)
    ref = ca.SX.sym("ref", 5 * n)  # q_d, qd_d, qdd_d, qddd_d, qdddd_d
    rq, rqd, rqdd, rj, rs = (ref[i * n : (i + 1) * n] for i in range(5))
    # motor angle of the desired motion and its exact time derivatives
    y = ca.SX.sym("y", 3 * n)
    tau_ff = ca.mtimes(tree.mass_matrix(y[:n], th), y[2 * n :]) + tree.bias(y[:n], y[n : 2 * n], th)
    qm_r_fn = ca.Function("qm_r", [y, th], [y[:n] + tau_ff / Ks])
    ydot, yddot = ca.vertcat(rqd, rqdd, rj), ca.vertcat(rqdd, rj, rs)
    yy = ca.vertcat(rq, rqd, rqdd)
    qm_r = qm_r_fn(yy, th)
    d1 = ca.jtimes(qm_r_fn(y, th), y, ydot)  # d/dt at fixed direction ydot(t)
    qmd_r = ca.substitute(d1, y, yy)
    # d2/dt2 = d/dy (J ydot) ydot + J yddot, with ydot itself moving along yddot
    yd_s = ca.SX.sym("yd", 3 * n)
    d1s = ca.jtimes(qm_r_fn(y, th), y, yd_s)
    d2 = ca.jtimes(d1s, y, yd_s) + ca.jtimes(d1s, yd_s, yddot)
    qmdd_r = ca.substitute(ca.substitute(d2, yd_s, ydot), y, yy)

    def cascade(name: str, Lt: ca.SX) -> ca.Function:
        sf = _Surface(q, qd, rq, rqd, g["lam"], Lt, g["p"], T)
        vt_next = rqd + T * rqdd - Lt * sf.e_next
        dv = vt_next - sf.vt
        reach = T * (g["h"] * sf.s + g["eps"] * sat(sf.s, g["phi"]))
        M = tree.mass_matrix(q, th)
        tau = tree.bias(q, qd, th) + ca.mtimes(M, dv + sf.lam_terms - reach) / T
        tau = ca.fmin(ca.fmax(tau, -g["tau_max"]), g["tau_max"])
        qm_d = q + tau / Ks
        wm = g["wm"]
        u = (
            Ks * (qm - q)
            + Fm * qmd
            + Mm * (qmdd_r + wm * wm * (qm_d - qm) + 2.0 * wm * (qmd_r - qmd))
        )
        ins = [("x", x), ("ref", ref), *gin, *cin]
        if name == "control_dtsmc":
            ins = [(k, v if k != "Lt" else ca.SX.sym("Lt_unused", n)) for k, v in ins]
        outs = [("u", u), ("s", sf.s), ("tau_d", tau), ("qm_d", qm_d), ("e_next", sf.e_next)]
        outs += [("qm_r", qm_r), ("bound", ca.fabs(dv + sf.lam_terms))]
        return _fn(name, ins, outs)

    fns += [cascade("control_amsfe", g["Lt"]), cascade("control_dtsmc", ca.SX.zeros(n))]
    return fns


def _fn(name: str, ins: list[tuple[str, ca.SX]], outs: list[tuple[str, ca.SX]]) -> ca.Function:
    return ca.Function(
        name,
        [s for _, s in ins],
        [ca.densify(e) for _, e in outs],
        [k for k, _ in ins],
        [k for k, _ in outs],
    )
