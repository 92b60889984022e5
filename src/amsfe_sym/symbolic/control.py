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
    ``Lt = 0`` (then ``v_t = qd_d`` and ``sigma = e_dot``), on the raw motor encoders
    ``z = [qm, qmd]`` read as the link (q = qm, qd = qmd) and the given theta.
``control_amsfe``
    The working variant (docs/explanation/control.md): the terminal sliding law of (31)-(37)
    designed on the
    rigid-link part of the model with the spring torque as the virtual input,
    ``qd(k+1) = qd + T M^-1 (tau - b)``, which gives
    ``tau_d = b + (M/T) [v_t(k+1) - v_t(k) + lam e^p - lam e(k+1)^p - T (h s + eps sat(s/phi))]``
    (``v_t(k+1)`` from the trajectory and the predicted error: exact on its design model),
    clipped to ``|tau_d| <= tau_max``; then the motor angle that produces it,
    ``qm_d = qhat + Ks^-1 tau_d``, is realized by a motor loop with smooth feedforward
    (Spong's cascade for flexible joints):
    ``u = Ks (qmhat - qhat) + Fm qmdhat
    + Mm (qmdd_r + cdd + wm^2 (qm_d - qmhat) + 2 wm (qmd_r + cd - qmdhat))``,
    where ``qm_r = q_d + Ks^-1 (M(q_d) qdd_d + b(q_d, qd_d))`` is the motor angle of the desired
    motion, ``qmd_r``, ``qmdd_r`` its exact time derivatives (RNEA on second-order Taylor
    polynomials along the trajectory's jerk and snap, :mod:`.rnea_taylor`), and ``cd``,
    ``cdd`` the rate and acceleration of the feedback part ``qm_d - qm_r`` from a critically
    damped command filter of bandwidth ``wf`` (its state ``cf`` is an input, its next state
    ``cf_next`` an output: no memory in the law).
``control_dtsmc``
    ``control_amsfe`` with ``Lt = 0`` (the baseline surface of (54)) on the motor encoders
    ``z = [qm, qmd]`` with the planned spring deflection removed:
    ``q = qm - (qm_r - q_d)``, ``qd = qmd - (qmd_r - qd_d)``.
``control_motor_reference``
    ``(ref, theta) -> (qm_r, qmd_r, qmdd_r)``, the motor angle of the desired motion and its
    exact derivatives (used by the cascades; exported for plots and tests).

Outputs of every law: ``u`` [N m], ``s`` (33), ``e_next`` (the predicted error (40)) and
``bound`` = ``|dv - lam e(k+1)^p + lam e^p|`` per joint, the norm inside the gain condition (38)
(``dv`` the reference-velocity increment the law used).
"""

from __future__ import annotations

import casadi as ca

from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.estimator import EXPAND_MAX_STATES
from amsfe_sym.symbolic.functions import sx_function
from amsfe_sym.symbolic.rnea_taylor import rnea_jet
from amsfe_sym.symbolic.transition import Transition

__all__ = ["CONTROL_GAINS", "build_control_functions", "fpow", "sat"]

#: Gain inputs of every law, in order (each an n-vector except ``p``, a scalar).
CONTROL_GAINS = ("h", "lam", "Lt", "eps", "p", "phi")
#: Extra inputs of the cascaded laws: motor-loop bandwidth [rad/s], spring-torque limit [N m],
#: command-filter bandwidth [rad/s], motor rate bound [rad/s]; then ``hold`` (per joint, 0 or
#: 1): 1 holds the command filter (no rate, no acceleration feedforward: the start-up).
CASCADE_GAINS = ("wm", "tau_max", "wf", "vmax", "hold")


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
    """The generated control laws of the module docstring, for one robot.

    Code size: every product ``M(q) w`` is one RNEA pass (``rnea(q, 0, w)`` without gravity)
    and ``b + M a`` is ``rnea(q, qd, a)``, never an assembled M (n passes); the baselines and
    the cascade's motor reference are MX calls of one emitted function each, so nothing is
    generated twice (the 6-DOF UR5: see docs/explanation/codegen.md).
    """
    robot = tree.robot
    n, p_, T = tree.n, tree.p, float(robot.spec.model.T)
    N = 4 * n + p_
    Mm, Fm = ca.DM(robot.Mm), ca.DM(robot.Fm)
    x = ca.SX.sym("x", N)
    q, qd, qm, qmd, th = tr.split(x)
    g = {k: ca.SX.sym(k, 1 if k == "p" else n) for k in (*CONTROL_GAINS, *CASCADE_GAINS)}
    gin = [(k, g[k]) for k in CONTROL_GAINS]
    q_d, qd_d = ca.SX.sym("q_d", n), ca.SX.sym("qd_d", n)
    Ks = tr.stiffness(th)
    zero_n = ca.SX.zeros(n, 1)

    def m_times(qq: ca.SX, w: ca.SX) -> ca.SX:  # M(qq) w in one RNEA pass
        return tree.rnea(qq, zero_n, w, th, with_gravity=False)

    # ---------------------------------------------------------------- (37) and (54) as printed
    qmd_next, vt_prev = ca.SX.sym("qmd_next", n), ca.SX.sym("vt_prev", n)
    qbar = q + T * qd  # (29a)
    # the link force of (1b), f = d/dq (1/2 qd^T M(q) qd) - g(q), by reverse AD of one pass
    qs = ca.SX.sym("q_f", n)
    ke = 0.5 * ca.dot(qd, tree.rnea(qs, zero_n, qd, th, with_gravity=False))
    f_link = ca.substitute(ca.gradient(ke, qs), qs, q) - tree.gravity_torque(q, th)
    sf = _Surface(q, qd, q_d, qd_d, g["lam"], g["Lt"], g["p"], T)
    dv = sf.vt - vt_prev
    reach = T * (g["h"] * sf.s + g["eps"] * sat(sf.s, g["phi"]))
    # u = Mbar/T [Fhat + dv + ...] with Mbar Fhat = Mbar qd - M(q) qd - T f + Mm (qmd+ - qmd)
    # + T Fm qmd written out, so no solve is needed (F of (29b) at the estimates); Mbar is
    # linear in its vector, so Mbar qd + Mbar w is one RNEA pass, Mbar (qd + w)
    rest = -m_times(q, qd) - T * f_link + Mm * (qmd_next - qmd) + T * Fm * qmd
    u = (m_times(qbar, qd + dv + sf.lam_terms - reach) + rest) / T
    law37 = sx_function(
        "control_amsfe_paper",
        [
            ("x", x),
            ("qmd_next", qmd_next),
            ("q_d", q_d),
            ("qd_d", qd_d),
            ("vt_prev", vt_prev),
            *gin,
        ],
        [
            ("u", u),
            ("s", sf.s),
            ("vt", sf.vt),
            ("e_next", sf.e_next),
            ("bound", ca.fabs(dv + sf.lam_terms)),
        ],
    )

    # ---------------------------------------------------------------- the cascade (ours)
    ref = ca.SX.sym("ref", 5 * n)  # q_d, qd_d, qdd_d, qddd_d, qdddd_d
    cf = ca.SX.sym("cf", 2 * n)  # command-filter state
    mr = [ca.SX.sym(k, n) for k in ("qm_r", "qmd_r", "qmdd_r")]
    qm_r, qmd_r, qmdd_r = mr
    rq, rqd, rqdd = ref[:n], ref[n : 2 * n], ref[2 * n : 3 * n]
    sf = _Surface(q, qd, rq, rqd, g["lam"], g["Lt"], g["p"], T)
    vt_next = rqd + T * rqdd - g["Lt"] * sf.e_next
    dv = vt_next - sf.vt
    reach = T * (g["h"] * sf.s + g["eps"] * sat(sf.s, g["phi"]))
    tau = tree.rnea(q, qd, (dv + sf.lam_terms - reach) / T, th)  # b + M a_d
    tau = ca.fmin(ca.fmax(tau, -g["tau_max"]), g["tau_max"])
    qm_d = q + tau / Ks
    # command filter on the feedback part dq = qm_d - qm_r (critically damped, bandwidth wf):
    # its states give the smooth angle, rate and acceleration the motor loop tracks; held
    # (hold = 1: its state is the caller's, no acceleration) while the start-up waits
    dq = qm_d - qm_r
    wf = g["wf"]
    c, cd = cf[:n], cf[n:]
    cdd = (1.0 - g["hold"]) * (wf * wf * (dq - c) - 2.0 * wf * cd)
    cd_next = cd + T * cdd
    cf_next = ca.vertcat(c + T * cd_next, cd_next)
    wm, vmax = g["wm"], g["vmax"]
    # nested loops: a bounded rate correction from the angle error, then the rate loop (linear
    # gains wm^2 and 2 wm: a critically damped PD; the bound keeps a saturated motor from
    # overshooting)
    v_cmd = qmd_r + cd + ca.fmin(ca.fmax(0.5 * wm * (qm_r + c - qm), -vmax), vmax)
    u = Ks * (qm - q) + Fm * qmd + Mm * (qmdd_r + cdd + 2.0 * wm * (v_cmd - qmd))
    out_names = ["u", "s", "tau_d", "qm_d", "e_next", "bound", "cf_next", "dq"]
    core = ca.Function(
        "control_cascade_core",
        [x, ref, cf, *g.values(), *mr],
        [
            ca.densify(e)
            for e in (u, sf.s, tau, qm_d, sf.e_next, ca.fabs(dv + sf.lam_terms), cf_next, dq)
        ],
        {"cse": True},
    )
    mref = _motor_reference(tree, tr, n, p_)

    # MX wrappers: the law and its baselines call ``core`` / ``mref`` / ``law37`` (emitted once)
    gm = {k: ca.MX.sym(k, 1 if k == "p" else n) for k in g}
    xm, refm, cfm = ca.MX.sym("x", N), ca.MX.sym("ref", 5 * n), ca.MX.sym("cf", 2 * n)
    zm, thm = ca.MX.sym("z", 2 * n), ca.MX.sym("theta", p_)
    gain_names = [*CONTROL_GAINS, *CASCADE_GAINS]

    def gains_with(lt: ca.MX) -> list[ca.MX]:
        return [lt if k == "Lt" else gm[k] for k in g]

    no_lt = [k for k in gain_names if k != "Lt"]
    m_r = mref.call([refm, xm[4 * n :]])
    cascade = ca.Function(
        "control_amsfe",
        [xm, refm, cfm, *(gm[k] for k in gain_names)],
        core.call([xm, refm, cfm, *gains_with(gm["Lt"]), *m_r]),
        ["x", "ref", "cf", *gain_names],
        out_names,
    )
    # dtsmc: the planned spring deflection removed from the encoders, the surface of (54)
    m_z = mref.call([refm, thm])
    x_plan = ca.vertcat(zm[:n] - (m_z[0] - refm[:n]), zm[n:] - (m_z[1] - refm[n : 2 * n]), zm, thm)
    base = ca.Function(
        "control_dtsmc",
        [zm, thm, refm, cfm, *(gm[k] for k in no_lt)],
        core.call([x_plan, refm, cfm, *gains_with(ca.MX.zeros(n, 1)), *m_z]),
        ["z", "theta", "ref", "cf", *no_lt],
        out_names,
    )
    # (54): the raw encoders stand for the link (q = qm, qd = qmd), Lt = 0
    pm = [ca.MX.sym(k, n) for k in ("qmd_next", "q_d", "qd_d", "vt_prev")]
    law_gains = [k for k in CONTROL_GAINS if k != "Lt"]
    x_raw = ca.vertcat(zm[:n], zm[n:], zm, thm)
    law54 = ca.Function(
        "control_dtsmc_paper",
        [zm, thm, *pm, *(gm[k] for k in law_gains)],
        law37.call(
            [x_raw, *pm, *[ca.MX.zeros(n, 1) if k == "Lt" else gm[k] for k in CONTROL_GAINS]]
        ),
        ["z", "theta", "qmd_next", "q_d", "qd_d", "vt_prev", *law_gains],
        ["u", "s", "vt", "e_next", "bound"],
    )
    if N <= EXPAND_MAX_STATES:  # the tick's law as straight-line SX (small arms only)
        cascade = cascade.expand()
    return [law37, law54, cascade, base, mref]


def _motor_reference(tree: RigidBodyTree, tr: Transition, n: int, p: int) -> ca.Function:
    """``control_motor_reference``: ``(ref, theta) -> (qm_r, qmd_r, qmdd_r)``, the motor angle
    of the desired motion, ``qm_r = q_d + Ks^-1 RNEA(q_d, qd_d, qdd_d)``, and its exact first
    and second time derivatives along the trajectory's jerk and snap, by one pass of RNEA on
    second-order Taylor polynomials (:mod:`.rnea_taylor`; nested forward-mode AD emitted
    about 1.5x the code)."""
    ref, th = ca.SX.sym("ref", 5 * n), ca.SX.sym("theta", p)
    rq, rqd, rqdd, rj, rs = (ref[i * n : (i + 1) * n] for i in range(5))
    Ks = tr.stiffness(th)  # constant in time
    tau = rnea_jet(tree, [rq, rqd, rqdd], [rqd, rqdd, rj], [rqdd, rj, rs], th)
    qm_r, qmd_r, qmdd_r = rq + tau[0] / Ks, rqd + tau[1] / Ks, rqdd + tau[2] / Ks
    return ca.Function(
        "control_motor_reference",
        [ref, th],
        [ca.densify(qm_r), ca.densify(qmd_r), ca.densify(qmdd_r)],
        ["ref", "theta"],
        ["qm_r", "qmd_r", "qmdd_r"],
        {"cse": True},
    )
