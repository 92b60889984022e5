"""The rk4 substeps folded (one substep function called in a loop, ``Function.fold``) against
the same substeps unrolled in the graph, in CasADi's VM (no compile): every transition
function equal to rounding, A of the folded step against central differences of the
folded transition, and the folded C not growing with the substeps.  The compiled folded
step is checked by ``tests/test_generated.py::test_chained_rk4_step_equals_the_generated_one``
(3 substeps: the C chain and ``amsfe check``'s rows)."""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from amsfe_sym.apps.check import random_states, rel_err
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.load.spec import load_spec
from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.transition import EXPAND_MAX_JOINTS, Transition


def _robot(name: str, substeps: int) -> Robot:
    spec = load_spec(name)
    return load_robot(
        replace(spec, model=replace(spec.model, integrator="rk4", model_substeps=substeps))
    )


def _functions(robot: Robot, fold: bool) -> dict[str, ca.Function]:
    tr = Transition(RigidBodyTree(robot), "rk4", 3, fold_substeps=fold)
    fns = tr.rk4_functions()
    fns["plant_step"] = tr.plant_step(4)
    return fns


def _c_lines(fn: ca.Function) -> int:
    cg = ca.CodeGenerator("f.c")
    cg.add(fn)
    return int(cg.dump().count("\n"))


#: paper_2link: the expanded step (SX stage, <= EXPAND_MAX_JOINTS joints); ur5: the MX step
#: over the split stage (CasADi's ldl).
@pytest.mark.parametrize("name", ["paper_2link", "ur5"])
def test_folded_substeps_equal_unrolled(name: str) -> None:
    """transition_step (x+, A, Gamma), transition, transition_inverse and plant_step with
    3 substeps folded equal the unrolled ones to 1e-14 (the same operations)."""
    robot = _robot(name, 3)
    assert (robot.n <= EXPAND_MAX_JOINTS) == (name == "paper_2link")
    folded, unrolled = _functions(robot, True), _functions(robot, False)
    rng = np.random.default_rng(5)
    n = robot.n
    for x in random_states(robot, 4, rng):
        u = rng.uniform(-3.0, 3.0, n)
        for fn in ("transition_step", "transition", "transition_inverse", "plant_step"):
            args = [x, u] if fn != "plant_step" else [x[: 4 * n], u, x[4 * n :], np.zeros(2 * n)]
            want = unrolled[fn](*args)
            got = folded[fn](*args)
            for a, b in zip(
                got if isinstance(got, tuple) else [got],
                want if isinstance(want, tuple) else [want],
                strict=True,
            ):
                assert rel_err(np.array(a), np.array(b), floor=1.0) <= 1e-14, fn


def test_folded_jacobian_equals_central_differences() -> None:
    """A = dF/dx of the folded expanded step (5 substeps, the 2-link arm) against central
    differences of the folded ``transition`` (<= 1e-7 relative, step 1e-6)."""
    robot = _robot("paper_2link", 5)
    fns = _functions(robot, True)
    step, F = fns["transition_step"], fns["transition"]
    rng = np.random.default_rng(11)
    eps = 1e-6
    for x in random_states(robot, 3, rng):
        u = rng.uniform(-3.0, 3.0, robot.n)
        A = np.array(step(x, u)[1])
        fd = np.column_stack(
            [
                (np.array(F(x + eps * e, u)) - np.array(F(x - eps * e, u))).ravel() / (2 * eps)
                for e in np.eye(x.size)
            ]
        )
        assert rel_err(A, fd) <= 1e-7


@pytest.mark.parametrize("name", ["paper_2link", "ur5"])
def test_folded_code_does_not_grow_with_substeps(name: str) -> None:
    """The substep's code is emitted once: from 2 to 8 substeps the folded step's C grows by
    the 6 more calls (at most 20 lines each), the unrolled step's by 6 copies of the
    substep (more than 10 times as much)."""
    lines = {
        (fold, m): _c_lines(_functions(_robot(name, m), fold)["transition_step"])
        for fold in (True, False)
        for m in (2, 8)
    }
    grown = lines[True, 8] - lines[True, 2]
    assert 0 <= grown <= 6 * 20, lines
    assert lines[False, 8] - lines[False, 2] > 10 * grown, lines
