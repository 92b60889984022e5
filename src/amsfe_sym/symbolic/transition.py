"""The discrete flexible-joint transition F(x, u) (eqs. 1a-1d, 3, 4), its inverse (eq. 22),
and the continuous-time plant used as the simulated truth.

State (eq. 2): ``x = [q, qd, qm, qmd, theta]``, ``N = 4n + p``.  Process noise enters as
impulses ``w = [w_l (n) [N m s], w_m (n) [N m s], w_theta (p)]``, so that the noise gain
``Gamma = dF/dw`` at ``w = 0`` matches eq. (4)'s Gamma for the paper's integrator.

Two integrators (PAPER-NOTES section 1):

``paper`` (eqs. 1a-1d read as Nicosia's momentum update, errata corrected)::

    q+      = q + T qd
    M(q+) qd+ = M(q) qd + T [Ks (qm - q) + f(q, qd)] + w_l,   f = d/dq(1/2 qd^T M qd) - g(q)
    qm+     = qm + T qmd
    Mm qmd+ = Mm qmd + T [u - Fm qmd - Ks (qm - q)] + w_m
    theta+  = theta + T w_theta

``semi_implicit`` (symplectic Euler; q advances with the new velocity, stable for stiff joints)::

    M(q) (qd+ - qd) = T [Ks (qm - q) - b(q, qd)] + w_l,       q+  = q + T qd+
    Mm (qmd+ - qmd) = T [u - Fm qmd - Ks (qm - q)] + w_m,    qm+ = qm + T qmd+
    theta+ = theta + T w_theta

``rk4`` (ours, beyond the paper): one classical Runge-Kutta step of the continuous model
over T with u held, the impulses w applied at the start of the step.  Both Euler forms
above move positions by T times the old (or new) velocity and so make a *systematic*
position error of T^2/2 times the acceleration every step; with a known, large motor
torque that bias is far above any white process noise and an EKF built on them lags its
own encoders (docs/explanation/estimation.md).  RK4 is 4th order, explicit, stable for w T < 2.8.

The inverse solves the same equations for x given x+ exactly in the motor and q parts and
by a fixed number of unrolled chord (simplified Newton) steps for qd, whose contraction
factor is O(T); the rk4 inverse by unrolled Newton steps.  A fixed number of steps can fail
to converge (stiff joints on light links), so every generated ``transition_inverse`` has a
second output ``residual`` = inf-norm of F(x, u) - x+ at the returned x (see
:func:`with_residual`), which the runtime checks; ``amsfe check`` tests the round trip.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from amsfe_sym.symbolic import rk4_step as _rk4_step
from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.linalg import ldl_solve, plus_identity
from amsfe_sym.symbolic.rk4_step import (
    plant_rhs_over_stage,
    stage_split_functions,
    step_function,
)
from amsfe_sym.symbolic.rnea_derivatives import rnea_derivatives

__all__ = [
    "EXPAND_MAX_JOINTS",
    "STAGE_DERIVATIVES",
    "StateLayout",
    "Transition",
    "rk4_steps",
    "with_residual",
]

#: How :meth:`Transition.rk4_stage_function` builds the stage's dynamics derivative
#: dRNEA/dz: ``"analytic"`` (one recursive pass, :mod:`.rnea_derivatives`; the default) or
#: ``"reverse_ad"`` (n reverse-mode sweeps of the RNEA expression, kept for comparison).
STAGE_DERIVATIVES = ("analytic", "reverse_ad")

#: Up to this many joints the rk4 ``transition_step`` is expanded into SX (straight-line C)
#: and the C estimators call it; beyond, it is an MX graph over the generated stage (the
#: contract's function, small) and the C estimators call the chain of
#: ``runtime/c/amsfe_model.c``.  Measured (tools/codegen_sizes.py, docs/explanation/codegen.md):
#: 2-link
#: expanded 0.78 us against 1.55 us chained; UR5 chained 20.5 us against 67 us as MX (and
#: 42 us expanded, in 60k lines).
EXPAND_MAX_JOINTS = 2


def rk4_steps(
    rhs: ca.Function,
    x: ca.MX,
    u: ca.MX,
    th: ca.MX,
    td: ca.MX,
    duration: float,
    steps: int,
    fold: bool = True,
) -> ca.MX:
    """``steps`` classical RK4 steps of h = duration / steps of ``rhs(x, u, th, td)``, u, th
    and td held: the rk4 model F (td = 0, ``model_substeps``) and the plant
    (``plant_substeps``).  With ``fold`` and more than one step, one step is a Function
    called in a loop (``Function.fold``: its code is emitted once), else the steps are
    unrolled in the graph."""
    h = duration / steps

    def one(x: ca.MX, u: ca.MX, th: ca.MX, td: ca.MX) -> ca.MX:
        k1 = rhs(x, u, th, td)
        k2 = rhs(x + 0.5 * h * k1, u, th, td)
        k3 = rhs(x + 0.5 * h * k2, u, th, td)
        k4 = rhs(x + h * k3, u, th, td)
        return x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)

    if fold and steps > 1:
        ins = [
            ca.MX.sym(name, *rhs.size_in(i)) for i, name in enumerate(("xp", "u", "theta", "tau_d"))
        ]
        body = ca.Function(
            "rk4_substep_" + rhs.name(),
            ins,
            [one(*ins)],
            ["xp", "u", "theta", "tau_d"],
            ["xp_next"],
        )
        return body.fold(steps)(x, u, th, td)
    for _ in range(steps):
        x = one(x, u, th, td)
    return x


def with_residual(inverse: ca.Function, forward: ca.Function) -> ca.Function:
    """``transition_inverse`` (x_next, u) -> (x, residual) from an inverse that returns x.

    ``residual = max_i |F(x, u) - x_next|_i`` is the inf-norm of the forward map at the
    returned x against its target [state units]: the unrolled iterations of eq. (22) report
    whether they converged, in the generated code itself (the runtime refuses a large one).
    Both are called, not inlined, so the forward map is emitted once in the C file.
    """
    N, n = inverse.size_in(0)[0], inverse.size_in(1)[0]
    xn, u = ca.MX.sym("x_next", N), ca.MX.sym("u", n)
    x = inverse(xn, u)
    res = ca.norm_inf(forward(x, u) - xn)
    return ca.Function("transition_inverse", [xn, u], [x, res], ["x_next", "u"], ["x", "residual"])


@dataclass(frozen=True)
class StateLayout:
    """Slices of the state vector x = [q, qd, qm, qmd, theta] (eq. 2)."""

    n: int
    p: int

    @property
    def N(self) -> int:
        return 4 * self.n + self.p

    @property
    def q(self) -> slice:
        return slice(0, self.n)

    @property
    def qd(self) -> slice:
        return slice(self.n, 2 * self.n)

    @property
    def qm(self) -> slice:
        return slice(2 * self.n, 3 * self.n)

    @property
    def qmd(self) -> slice:
        return slice(3 * self.n, 4 * self.n)

    @property
    def theta(self) -> slice:
        return slice(4 * self.n, 4 * self.n + self.p)

    def as_dict(self) -> dict[str, list[int]]:
        """Start and stop index of each block, for the manifest."""
        return {
            k: [getattr(self, k).start, getattr(self, k).stop]
            for k in ("q", "qd", "qm", "qmd", "theta")
        }


class Transition:
    """Builds F, its jacobians, its inverse and the plant for one robot.

    Args:
        tree: The SX rigid-body tree.
        integrator: ``"paper"`` or ``"semi_implicit"``.
        inverse_iterations: Unrolled chord steps in the inverse.
        stage_derivative: One of :data:`STAGE_DERIVATIVES`.
        fold_substeps: rk4 substeps as a loop over one substep function (``True``) or
            unrolled; ``None`` reads :data:`.rk4_step.FOLD_SUBSTEPS`.
    """

    def __init__(
        self,
        tree: RigidBodyTree,
        integrator: str,
        inverse_iterations: int,
        stage_derivative: str = "analytic",
        fold_substeps: bool | None = None,
    ) -> None:
        if stage_derivative not in STAGE_DERIVATIVES:
            raise ValueError(f"stage_derivative must be one of {STAGE_DERIVATIVES}")
        self.stage_derivative = stage_derivative
        self.tree = tree
        self.robot = tree.robot
        self.layout = StateLayout(tree.n, tree.p)
        self.integrator = integrator
        self.iterations = inverse_iterations
        self.T = float(self.robot.spec.model.T)
        self.substeps = int(self.robot.spec.model.model_substeps)  # rk4 steps per T
        #: rk4 substeps in a loop of one substep function (``Function.fold``) or unrolled
        self.fold = _rk4_step.FOLD_SUBSTEPS if fold_substeps is None else fold_substeps
        self._cache: dict[str, ca.Function] = {}

    # ------------------------------------------------------------------ pieces
    def stiffness(self, theta: ca.SX) -> ca.SX:
        """Ks as an n-vector, with joint-stiffness parameters bound to theta."""
        ks = [ca.SX(float(v)) for v in self.robot.Ks]
        for i, b in enumerate(self.robot.theta):
            if b.kind == "joint_stiffness":
                ks[b.q_index] = theta[i]
        return ca.vertcat(*ks)

    def f_link(self, q: ca.SX, qd: ca.SX, theta: ca.SX) -> ca.SX:
        """f(q, qd) = d/dq (1/2 qd^T M(q) qd) - g(q): the non-inertial link forces of (1b)."""
        qs = ca.SX.sym("q_f", self.tree.n)
        M = self.tree.mass_matrix(qs, theta)
        ke = 0.5 * ca.dot(qd, ca.mtimes(M, qd))
        dke = ca.substitute(ca.gradient(ke, qs), qs, q)
        return dke - self.tree.gravity_torque(q, theta)

    def split(self, x: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        L = self.layout
        return x[L.q], x[L.qd], x[L.qm], x[L.qmd], x[L.theta]

    # ------------------------------------------------------------------ forward
    def forward(self, x: ca.SX, u: ca.SX, w: ca.SX | None = None) -> ca.SX:
        """x+ = F(x, u) + noise (eq. 3); ``w`` = [w_l, w_m, w_theta] impulses, or None."""
        n, p, T = self.tree.n, self.tree.p, self.T
        q, qd, qm, qmd, th = self.split(x)
        if w is None:
            w = ca.SX.zeros(2 * n + p, 1)
        wl, wm, wt = w[0:n], w[n : 2 * n], w[2 * n :]
        Ks = self.stiffness(th)
        Mm = ca.DM(self.robot.Mm)
        Fm = ca.DM(self.robot.Fm)
        delta = qm - q  # eq. (1d)
        if self.integrator == "rk4":
            raise ValueError("rk4 transitions are built by rk4_functions() (MX graphs)")
        if self.integrator == "paper":
            q_next = q + T * qd  # (1a)
            mom = (
                ca.mtimes(self.tree.mass_matrix(q, th), qd)
                + T * (Ks * delta + self.f_link(q, qd, th))
                + wl
            )
            qd_next = ldl_solve(self.tree.mass_matrix(q_next, th), mom)  # (1b)
            qm_next = qm + T * qmd
            qmd_next = qmd + (T * (u - Fm * qmd - Ks * delta) + wm) / Mm  # (1c)
        else:
            rhs = T * (Ks * delta - self.tree.bias(q, qd, th)) + wl
            qd_next = qd + ldl_solve(self.tree.mass_matrix(q, th), rhs)
            q_next = q + T * qd_next
            qmd_next = qmd + (T * (u - Fm * qmd - Ks * delta) + wm) / Mm
            qm_next = qm + T * qmd_next
        th_next = th + T * wt
        return ca.vertcat(q_next, qd_next, qm_next, qmd_next, th_next)

    # ------------------------------------------------------------------ inverse
    def inverse(self, xn: ca.SX, u: ca.SX) -> ca.SX:
        """x = F^-1(x+, u): the backward transition F_{kappa,lk} of eq. (22)."""
        T, K = self.T, self.iterations
        qn, qdn, qmn, qmdn, th = self.split(xn)
        Ks = self.stiffness(th)
        Mm = ca.DM(self.robot.Mm)
        Fm = ca.DM(self.robot.Fm)
        if self.integrator == "rk4":
            raise ValueError("rk4 transitions are built by rk4_functions() (MX graphs)")
        if self.integrator == "paper":
            Mn = self.tree.mass_matrix(qn, th)
            target = ca.mtimes(Mn, qdn)  # M(q+) qd+

            def motor(q: ca.SX) -> tuple[ca.SX, ca.SX]:
                # (Mm - T Fm + T^2 Ks) qmd = Mm qmd+ - T u + T Ks (qm+ - q), qm = qm+ - T qmd
                qmd = (Mm * qmdn - T * u + T * Ks * (qmn - q)) / (Mm - T * Fm + T * T * Ks)
                return qmn - T * qmd, qmd

            # Chord (simplified Newton) matrix: d(resid)/d(qd) without the O(T qd) terms,
            # M(q+) + T^2 Ks (1 - c) with c = T^2 Ks / (Mm - T Fm + T^2 Ks) (q = q+ - T qd
            # moves qm - q).  With M(q+) alone the steps diverge where a link's inertia is
            # below ~T^2 Ks (a light wrist: Unitree Z1, tests/test_inverse_convergence.py).
            c = T * T * Ks / (Mm - T * Fm + T * T * Ks)
            chord = Mn + ca.diag(T * T * Ks * (1 - c))
            qd = qdn
            for _ in range(K):
                q = qn - T * qd
                qm, _qmd = motor(q)
                resid = (
                    ca.mtimes(self.tree.mass_matrix(q, th), qd)
                    + T * (Ks * (qm - q) + self.f_link(q, qd, th))
                    - target
                )
                qd = qd - ldl_solve(chord, resid)
            q = qn - T * qd
            qm, qmd = motor(q)
        else:
            q = qn - T * qdn
            qm = qmn - T * qmdn
            delta = qm - q
            qmd = (Mm * qmdn - T * (u - Ks * delta)) / (Mm - T * Fm)
            M = self.tree.mass_matrix(q, th)
            qd = qdn
            for _ in range(K):
                qd = qdn - ldl_solve(M, T * (Ks * delta - self.tree.bias(q, qd, th)))
        return ca.vertcat(q, qd, qm, qmd, th)

    def rk4_stage_function(self) -> ca.Function:
        """One RK4 stage and its jacobian: ``(xp[4n], u[n], theta[p]) -> (k, J)``, SX with
        common subexpressions eliminated, built once per robot, its solves with M unrolled:
        the expanded step (up to :data:`EXPAND_MAX_JOINTS` joints) inlines it; beyond, the MX
        step and the C chain of ``runtime/c/amsfe_model.c`` call the two functions of
        :meth:`rk4_stage_split_functions` and solve with M in loops.

        ``k = f(xp, u, theta)`` is the plant's right-hand side without disturbance and
        ``J = dk/d[xp; theta]`` (4n x N, sparse: the qd, qmd and qmdd rows are structurally
        linear).  The acceleration rows use the inverse-dynamics derivative instead of
        differentiating through the LDL^T solve: ``M(q) qdd + b(q, qd) = Ks (qm - q)``
        differentiated at fixed ``qdd`` gives ``dqdd/dz = M^-1 (d(Ks (qm - q))/dz -
        dRNEA(q, qd, a)/dz |_{a = qdd})`` (DESIGN: half the code of the direct jacobian),
        with dRNEA/dz from :mod:`.rnea_derivatives` (``stage_derivative="analytic"``) or by
        reverse-mode AD (``"reverse_ad"``).
        """
        if "rk4_stage" in self._cache:
            return self._cache["rk4_stage"]
        n, p = self.tree.n, self.tree.p
        xp, u, th = ca.SX.sym("xp", 4 * n), ca.SX.sym("u", n), ca.SX.sym("theta", p)
        f = self.plant_rhs(xp, u, th, ca.SX.zeros(2 * n, 1))
        z = ca.vertcat(xp, th)
        q, qd, qm = xp[0:n], xp[n : 2 * n], xp[2 * n : 3 * n]
        d_rnea = self._rnea_derivative(q, qd, f[n : 2 * n], th, z)
        dtau = ca.jacobian(self.stiffness(th) * (qm - q), z) - d_rnea
        dqdd = ldl_solve(self.tree.mass_matrix(q, th), ca.densify(dtau))
        rows = ca.vertcat(f[0:n], f[2 * n :])  # qd, qmd, qmdd: linear in z
        J_lin = ca.jacobian(rows, z)
        J = ca.vertcat(J_lin[0:n, :], dqdd, J_lin[n:, :])
        fn = ca.Function(
            "rk4_stage", [xp, u, th], [f, J], ["xp", "u", "theta"], ["k", "J"], {"cse": True}
        )
        self._cache["rk4_stage"] = fn
        return fn

    def _rnea_derivative(self, q: ca.SX, qd: ca.SX, qdd: ca.SX, th: ca.SX, z: ca.SX) -> ca.SX:
        """dRNEA(q, qd, qdd, theta)/dz (n x (4n + p)) at the given qdd, projected on the
        structural sparsity of RNEA (it depends on neither qm nor qmd)."""
        n = self.tree.n
        a = ca.SX.sym("a", n)
        rnea = self.tree.rnea(q, qd, a, th)
        pattern = ca.jacobian_sparsity(rnea, z)
        if self.stage_derivative == "reverse_ad":
            # n adjoint sweeps of the whole RNEA expression (fewer operations than forward
            # mode's one sweep per column of z: 10.1k vs 12.1k on the Panda)
            d = ca.jtimes(rnea, z, ca.SX.eye(n), True).T
            return ca.project(ca.substitute(d, a, qdd), pattern)
        # one recursive pass (Carpentier and Mansard, RSS 2018): chain of 12 joints 13.3k
        # instructions against 23.0k, Panda 6.4k against 10.1k (the stage 27.1k against 35.7k
        # and 10.8k against 13.8k)
        dq, dv, dth = rnea_derivatives(self.tree, q, qd, qdd, th)
        d = ca.horzcat(dq, dv, ca.SX(n, 2 * n), dth)
        return ca.project(d, pattern)

    def rk4_stage_split_functions(self) -> tuple[ca.Function, ca.Function]:
        """``rk4_stage_rhs`` and ``rk4_stage_jac``: the stage without its dense solves
        (:func:`.rk4_step.stage_split_functions`), built once per robot."""
        if "rk4_stage_rhs" not in self._cache:
            fr, fj = stage_split_functions(self)
            self._cache["rk4_stage_rhs"], self._cache["rk4_stage_jac"] = fr, fj
        return self._cache["rk4_stage_rhs"], self._cache["rk4_stage_jac"]

    def rk4_minv_function(self) -> ca.Function:
        """``(q[n], theta[p]) -> M(q, theta)^-1`` (SX, LDL^T of the CRBA mass matrix), the
        noise gain's link block (eq. 4) of the expanded step; built once per robot."""
        if "rk4_minv" not in self._cache:
            n, p = self.tree.n, self.tree.p
            qs, ths = ca.SX.sym("q", n), ca.SX.sym("theta", p)
            minv = ldl_solve(self.tree.mass_matrix(qs, ths), ca.SX.eye(n))
            self._cache["rk4_minv"] = ca.Function(
                "rk4_minv", [qs, ths], [minv], ["q", "theta"], ["Minv"], {"cse": True}
            )
        return self._cache["rk4_minv"]

    def rk4_step_function(self, expand: bool = True) -> ca.Function:
        """``transition_step (x, u) -> (x_next, A, Gamma)`` of the ``rk4`` model
        (:func:`.rk4_step.step_function`; with ``expand`` straight-line SX over the unrolled
        stage, else an MX graph over the split stage, its solves in loops)."""
        return step_function(self, expand)

    def rk4_functions(self) -> dict[str, ca.Function]:
        """The ``rk4`` transition functions.

        ``transition_step`` (x+, A, Gamma) is :meth:`rk4_step_function`; ``transition`` is an
        MX graph calling the SX right-hand side four times (inlining four dynamics
        evaluations in SX makes the code grow tenfold); the inverse is Newton on the forward
        map from the backward-RK4 guess.

        Returns:
            ``transition``, ``transition_jacobian``, ``noise_gain``, ``transition_step`` and
            ``transition_inverse`` with the contract's names and shapes.
        """
        n, T, K = self.tree.n, self.T, self.iterations
        N = 4 * n + self.tree.p
        rhs = self.plant_rhs_function()
        x, u = ca.MX.sym("x", N), ca.MX.sym("u", n)
        th = x[4 * n :]
        zero = ca.MX.zeros(2 * n, 1)

        def step(xp: ca.MX, duration: float) -> ca.MX:
            return rk4_steps(rhs, xp, u, th, zero, duration, self.substeps, self.fold)

        F = ca.vertcat(step(x[: 4 * n], T), th)
        step_fn = self.rk4_step_function(expand=n <= EXPAND_MAX_JOINTS)
        xn = ca.MX.sym("x_next", N)
        xpn = xn[: 4 * n]
        th_n = xn[4 * n :]
        back = ca.Function(
            "rk4_back", [x, u], [step(x[: 4 * n], -T)]
        )  # uses th = x[4n:] of its own argument
        # Chord (simplified Newton) on F(x) = x+ from the backward-RK4 guess, with the step's
        # own A at the guess, factored once: the plain fixed point x <- x - (F(x) - x+)
        # contracts only for T |df/dx| < 1, which stiff joints break; the guess is O(T^5)
        # close, so A at the guess contracts as fast as full Newton's A for a fraction of
        # the cost (one jacobian and one QR per inverse instead of one per iteration)
        xp = back(xn, u)
        _fx, jx, _G = step_fn(ca.vertcat(xp, th_n), u)
        jinv = ca.solve(jx[: 4 * n, : 4 * n], plus_identity(ca.MX.zeros(4 * n, 4 * n)), "qr")
        fwd = ca.Function("rk4_fwd", [x, u], [step(x[: 4 * n], T)])  # no jacobian
        for _ in range(K):
            xp = xp - ca.mtimes(jinv, fwd(ca.vertcat(xp, th_n), u) - xpn)
        xs, us = ca.MX.sym("x", N), ca.MX.sym("u", n)
        _, A_s, G_s = step_fn(xs, us)
        transition = ca.Function("transition", [x, u], [F], ["x", "u"], ["x_next"])
        return {
            "transition_jacobian": ca.Function(
                "transition_jacobian", [xs, us], [A_s], ["x", "u"], ["A"]
            ),
            "noise_gain": ca.Function("noise_gain", [xs, us], [G_s], ["x", "u"], ["Gamma"]),
            "transition_step": step_fn,
            "transition": transition,
            "transition_inverse": with_residual(
                ca.Function("rk4_inverse_x", [xn, u], [ca.vertcat(xp, th_n)]), transition
            ),
        }

    # ------------------------------------------------------------------ plant (truth)
    def plant_rhs(self, xp: ca.SX, u: ca.SX, theta: ca.SX, tau_d: ca.SX) -> ca.SX:
        """Continuous-time Spong model: d/dt [q, qd, qm, qmd].

        ``M qdd + b = Ks (qm - q) + tau_l``, ``Mm qmdd + Fm qmd + Ks (qm - q) = u + tau_m``,
        with disturbance torques ``tau_d = [tau_l, tau_m]`` [N m].
        """
        n = self.tree.n
        q, qd, qm, qmd = xp[0:n], xp[n : 2 * n], xp[2 * n : 3 * n], xp[3 * n : 4 * n]
        Ks = self.stiffness(theta)
        delta = qm - q
        qdd = ldl_solve(
            self.tree.mass_matrix(q, theta),
            Ks * delta - self.tree.bias(q, qd, theta) + tau_d[0:n],
        )
        qmdd = (u + tau_d[n:] - ca.DM(self.robot.Fm) * qmd - Ks * delta) / ca.DM(self.robot.Mm)
        return ca.vertcat(qd, qdd, qmd, qmdd)

    def plant_rhs_function(self) -> ca.Function:
        """The plant's right-hand side as a Function (xp, u, theta, tau_d) -> d/dt xp, built
        once per robot (the transition and the plant call the same one, so it is emitted once
        in the C file): SX, or with the split rk4 stage (rk4, more than
        :data:`EXPAND_MAX_JOINTS` joints) an MX graph over ``rk4_stage_rhs``
        (:func:`.rk4_step.plant_rhs_over_stage`), which holds the same dynamics."""
        if "plant_rhs" not in self._cache:
            n, p = self.tree.n, self.tree.p
            if self.integrator == "rk4" and n > EXPAND_MAX_JOINTS:
                self._cache["plant_rhs"] = plant_rhs_over_stage(self)
                return self._cache["plant_rhs"]
            xp, u = ca.SX.sym("xp", 4 * n), ca.SX.sym("u", n)
            th, td = ca.SX.sym("theta", p), ca.SX.sym("tau_d", 2 * n)
            self._cache["plant_rhs"] = ca.Function(
                "plant_rhs", [xp, u, th, td], [self.plant_rhs(xp, u, th, td)], {"cse": True}
            )
        return self._cache["plant_rhs"]

    def plant_step(self, substeps: int) -> ca.Function:
        """One sampling interval T of the plant: ``substeps`` RK4 steps, u held (zero-order hold).

        Built as an MX graph that calls the SX right-hand side 4 x ``substeps`` times, so the
        generated C holds one copy of the dynamics and a short loop of calls.
        """
        n, p = self.tree.n, self.tree.p
        rhs = self.plant_rhs_function()
        xp, u = ca.MX.sym("xp", 4 * n), ca.MX.sym("u", n)
        th, td = ca.MX.sym("theta", p), ca.MX.sym("tau_d", 2 * n)
        x = rk4_steps(rhs, xp, u, th, td, self.T, substeps, self.fold)
        return ca.Function(
            "plant_step", [xp, u, th, td], [x], ["xp", "u", "theta", "tau_d"], ["xp_next"]
        )
