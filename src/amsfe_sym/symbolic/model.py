"""Assemble every symbolic function of one robot (the generated-function contract).

:func:`build_functions` returns CasADi Functions named and shaped as
docs/explanation/architecture.md's
contract table says; :mod:`amsfe_sym.codegen` turns them into one C library.  All outputs
are dense so the C buffers are plain column-major arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from amsfe_sym.core.interrupts import checkpoint
from amsfe_sym.load import Robot
from amsfe_sym.symbolic.camera import depth, pinhole
from amsfe_sym.symbolic.control import build_control_functions
from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.estimator import estimator_functions
from amsfe_sym.symbolic.functions import sx_function
from amsfe_sym.symbolic.rk4_step import dynamics_jacobian_function
from amsfe_sym.symbolic.transition import (
    EXPAND_MAX_JOINTS,
    StateLayout,
    Transition,
    with_residual,
)

__all__ = ["MATRIX_OUTPUTS", "PARTS", "SymbolicModel", "build_functions"]

#: Outputs that are matrices even when they have one column (e.g. dy/dq of a 1-joint arm).
MATRIX_OUTPUTS = frozenset({"M", "dy_dq", "A", "Gamma"})


@dataclass
class SymbolicModel:
    """The functions of one robot plus what the manifest needs to describe them."""

    robot: Robot
    layout: StateLayout
    functions: dict[str, ca.Function] = field(default_factory=dict)
    camera_depends_on_theta: bool = False
    #: Functions compiled into the library for its hand-written C (``runtime/c``), not part
    #: of the contract: the rk4 stage and M^-1 that ``amsfe_model.c`` chains.
    internal: dict[str, ca.Function] = field(default_factory=dict)
    #: Functions of the contract implemented in hand-written C, by the generated function
    #: whose names and shapes they share: ``transition_step_chain`` (``amsfe_model.c``).
    chained: dict[str, str] = field(default_factory=dict)


def _transition_functions(
    tr: Transition, x: ca.SX, u: ca.SX, xn: ca.SX, w: ca.SX
) -> list[ca.Function]:
    """transition, its inverse, and the fused step (x+, A, Gamma) in SX; the jacobian and
    the noise gain are the bulk of the generated code, so they are emitted once, in the fused
    ``transition_step``, and the single-output functions call it (measured on the UR5: 52k ->
    35k lines of C, -O1 compile 5.1 -> 4.1 s)."""
    N, n = x.shape[0], u.shape[0]
    F = tr.forward(x, u)
    Fw = tr.forward(x, u, w)
    A = ca.jacobian(F, x)
    G = ca.substitute(ca.jacobian(Fw, w), w, ca.SX.zeros(w.shape[0], 1))
    step = sx_function(
        "transition_step", [("x", x), ("u", u)], [("x_next", F), ("A", A), ("Gamma", G)]
    )
    xm, um = ca.MX.sym("x", N), ca.MX.sym("u", n)
    _, A_m, G_m = step(xm, um)
    fwd = sx_function("transition", [("x", x), ("u", u)], [("x_next", F)])
    inv = sx_function(
        "transition_inverse_x", [("x_next", xn), ("u", u)], [("x", tr.inverse(xn, u))]
    )
    return [
        fwd,
        with_residual(inv, fwd),
        step,
        ca.Function("transition_jacobian", [xm, um], [A_m], ["x", "u"], ["A"]),
        ca.Function("noise_gain", [xm, um], [G_m], ["x", "u"], ["Gamma"]),
    ]


def _camera_wrappers(measure: ca.Function, n: int, p: int) -> list[ca.Function]:
    """``camera`` and ``camera_jacobian`` as MX graphs returning one output of
    ``camera_measure`` (the same SX expressions, emitted once: the Panda's library 1.3k
    lines shorter); a call costs what ``camera_measure`` costs."""
    qm, thm = ca.MX.sym("q", n), ca.MX.sym("theta", p)
    y_m, dy_m, _depth = measure(qm, thm)
    return [
        ca.Function("camera", [qm, thm], [y_m], ["q", "theta"], ["y"]),
        ca.Function("camera_jacobian", [qm, thm], [dy_m], ["q", "theta"], ["dy_dq"]),
    ]


#: The groups of generated functions: the model (dynamics, camera, transition, plant), the
#: control laws (``control_*``) and the compiled estimators (``est_*``, with the C glue).
PARTS = ("model", "control", "estimator")


def build_functions(robot: Robot, parts: tuple[str, ...] = PARTS) -> SymbolicModel:
    """Build the model functions of ``robot`` (eqs. 1-8, 22) as CasADi Functions, plus the
    control laws and the compiled estimators when ``parts`` names them."""
    tree = RigidBodyTree(robot)
    spec = robot.spec.model
    tr = Transition(tree, spec.integrator, spec.inverse_iterations)
    n, p = robot.n, robot.p
    L = tr.layout
    N = L.N
    q, qd = ca.SX.sym("q", n), ca.SX.sym("qd", n)
    th = ca.SX.sym("theta", p)
    x, u = ca.SX.sym("x", N), ca.SX.sym("u", n)
    xn = ca.SX.sym("x_next", N)
    w = ca.SX.sym("w", 2 * n + p)

    M = tree.mass_matrix(q, th)
    r = tree.frame_point(q, robot.tracked_frame_id, robot.tracked_offset)
    y = pinhole(robot.camera, r)
    dy = ca.jacobian(y, q)

    measure = sx_function(
        "camera_measure",
        [("q", q), ("theta", th)],
        [("y", y), ("dy_dq", dy), ("depth", depth(robot.camera, r))],
    )
    bias = sx_function("bias", [("q", q), ("qd", qd), ("theta", th)], [("b", tree.bias(q, qd, th))])
    qm_, thm_ = ca.MX.sym("q", n), ca.MX.sym("theta", p)
    fns = [
        sx_function("mass_matrix", [("q", q), ("theta", th)], [("M", M)]),
        bias,
        # g(q) = b(q, 0): the same RNEA at zero velocity (a call costs what bias costs; it is
        # called once per simulation and by amsfe check)
        ca.Function(
            "gravity",
            [qm_, thm_],
            [ca.densify(bias(qm_, ca.MX.zeros(n, 1), thm_))],
            ["q", "theta"],
            ["g"],
        ),
        sx_function("tracked_point", [("q", q), ("theta", th)], [("r", r)]),
        *_camera_wrappers(measure, n, p),
        measure,
    ]
    fns += (
        _transition_functions(tr, x, u, xn, w)
        if spec.integrator != "rk4"
        else [
            # compact MX graphs calling the SX right-hand side instead of inlined SX
            *tr.rk4_functions().values()
        ]
    )
    model = SymbolicModel(robot=robot, layout=L)
    if spec.integrator == "rk4" and n > EXPAND_MAX_JOINTS:
        # the C chain over the generated stage (runtime/c/amsfe_model.c); up to
        # EXPAND_MAX_JOINTS the expanded step is faster (2-link: 0.78 against 1.55 us a call,
        # docs/explanation/codegen.md) and small, and the C estimators call it directly
        stage_rhs, stage_jac = tr.rk4_stage_split_functions()
        model.internal = {"rk4_stage_rhs": stage_rhs, "rk4_stage_jac": stage_jac}
        model.chained = {"transition_step_chain": "transition_step"}
    if model.chained:  # what the chain computes per stage, on its own (amsfe bench times it)
        fns.append(dynamics_jacobian_function(tr))
    model.functions = {f.name(): f for f in fns}
    checkpoint()  # a held Ctrl-C is raised here, between the stages (core.interrupts)
    model.functions["plant_step"] = tr.plant_step(spec.plant_substeps)
    if "control" in parts:
        for f in build_control_functions(tree, tr):  # eqs. (29)-(37), (54) and the cascade
            model.functions[f.name()] = f
    checkpoint()
    if "estimator" in parts:
        slots = robot.camera.delay // robot.camera.period + 1  # clones in flight (cloning)
        blocks = {k: getattr(L, k) for k in ("q", "qd", "qm", "qmd", "theta")}
        for f in estimator_functions(model.functions, n, p, blocks, slots):
            model.functions[f.name()] = f
    model.camera_depends_on_theta = bool(ca.depends_on(y, th)) if p else False
    return model
