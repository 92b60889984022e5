"""Analytic RNEA derivatives (symbolic/rnea_derivatives.py, issue 18) against Pinocchio's
computeRNEADerivatives, CasADi's AD of the SX RNEA, and the rk4 stage built either way."""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amsfe_sym.apps.check import rel_err
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.load.spec import default_spec
from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.rnea_derivatives import rnea_derivatives
from amsfe_sym.symbolic.rnea_taylor import rnea_jet
from amsfe_sym.symbolic.transition import Transition

from .conftest import SHIPPED, erd_urdf, ur5_three_thetas
from .test_random_chains import _chain_urdf


def _functions(robot: Robot) -> tuple[ca.Function, ca.Function]:
    """(analytic (dq, dv, dth), AD jacobian of RNEA w.r.t. [q, qd, theta])."""
    tree = RigidBodyTree(robot)
    n, p = tree.n, tree.p
    q, qd, qdd, th = (ca.SX.sym(s, k) for s, k in (("q", n), ("qd", n), ("qdd", n), ("th", p)))
    analytic = ca.Function(
        "d", [q, qd, qdd, th], list(rnea_derivatives(tree, q, qd, qdd, th)), {"cse": True}
    )
    tau = tree.rnea(q, qd, qdd, th)
    ad = ca.Function("ad", [q, qd, qdd, th], [ca.jacobian(tau, ca.vertcat(q, qd, th))])
    return analytic, ad


def _check(robot: Robot, samples: int, seed: int) -> None:
    analytic, ad = _functions(robot)
    n, p = robot.n, robot.p
    rng = np.random.default_rng(seed)
    for _ in range(samples):
        q, qd, qdd = rng.uniform(-2.0, 2.0, (3, n))
        th = (robot.theta_true + 1.0) * rng.uniform(0.5, 1.5, p)
        model = robot.pin_model_at(th)
        data = model.createData()  # the results are views of data: keep it alive
        dq_ref, dv_ref, _ = (
            np.array(m) for m in pin.computeRNEADerivatives(model, data, robot.to_pin_q(q), qd, qdd)
        )
        dq, dv, dth = (np.array(m) for m in analytic(q, qd, qdd, th))
        assert rel_err(dq, dq_ref, floor=1.0) <= 1e-10  # relative, absolute below 1
        assert rel_err(dv, dv_ref, floor=1.0) <= 1e-10
        J = np.array(ad(q, qd, qdd, th))
        assert rel_err(np.hstack([dq, dv, dth]), J, floor=1.0) <= 1e-10


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_robots_vs_pinocchio_and_ad(name: str) -> None:
    _check(load_robot(name), samples=20, seed=3)


@pytest.mark.parametrize(
    ("rel", "lock"),
    [
        ("ur_description/urdf/ur5_robot.urdf", None),
        ("double_pendulum_description/urdf/double_pendulum_continuous.urdf", None),
        ("panda_description/urdf/panda.urdf", {"panda_finger_joint2": 0.02}),  # + prismatic
        ("so_arm_description/urdf/so101.urdf", None),
        ("z1_description/urdf/z1.urdf", None),
    ],
    ids=["ur5", "double_pendulum_continuous", "panda_prismatic", "so101", "z1"],
)
def test_example_robot_data_arms(rel: str, lock: dict[str, float] | None) -> None:
    spec = default_spec(erd_urdf(rel))
    _check(load_robot(spec.with_locked(lock or {})), samples=10, seed=5)


def test_theta_kinds_vs_ad(tmp_path: Path) -> None:
    """payload_mass and link_mass enter dtau/dtheta; joint_stiffness does not."""
    robot = load_robot(ur5_three_thetas(tmp_path))
    _check(robot, samples=10, seed=7)
    tree = RigidBodyTree(robot)
    q, qd, qdd, th = (ca.SX.sym(s, k) for s, k in (("q", 6), ("qd", 6), ("qdd", 6), ("th", 3)))
    dth = rnea_derivatives(tree, q, qd, qdd, th)[2]
    assert dth[:, 2].nnz() == 0  # the stiffness is not in the inverse dynamics


def test_branching_tree(tmp_path: Path) -> None:
    """Two branches off one joint: joints on different branches have structural zeros."""
    link = (
        '<link name="{0}"><inertial><origin xyz="0.05 0.02 0.1"/><mass value="{1}"/>'
        '<inertia ixx="0.02" ixy="0.001" ixz="0.002" iyy="0.03" iyz="0.001" izz="0.015"/>'
        "</inertial></link>"
    )
    joint = (
        '<joint name="{0}" type="{4}"><parent link="{1}"/><child link="{2}"/>'
        '<origin xyz="0.1 0.05 0.3" rpy="0.3 -0.2 0.5"/><axis xyz="{3}"/>'
        '<limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
    )
    parts = ['<robot name="tree">', '<link name="base"/>']
    for i, (name, parent, axis, kind) in enumerate(
        [
            ("a", "base", "0 0 1", "revolute"),
            ("b", "a", "0 1 0", "revolute"),
            ("c", "b", "1 0 0", "prismatic"),
            ("d", "a", "0.6 0 0.8", "revolute"),
            ("e", "d", "0 0 1", "revolute"),
        ]
    ):
        parts.append(link.format(name, 1.0 + 0.3 * i))
        parts.append(joint.format(f"j{name}", parent, name, axis, kind))
    parts.append("</robot>")
    (tmp_path / "tree.urdf").write_text("\n".join(parts))
    spec = default_spec(tmp_path / "tree.urdf")
    robot = load_robot(spec)
    _check(robot, samples=10, seed=9)
    tree = RigidBodyTree(robot)
    parents = [b.parent for b in tree.bodies]
    assert sorted(parents) != list(range(-1, robot.n - 1))  # really a tree, not a chain
    n = robot.n
    q, qd, qdd = (ca.SX.sym(s, n) for s in ("q", "qd", "qdd"))
    dq = rnea_derivatives(tree, q, qd, qdd, ca.SX.sym("th", 0))[0]
    on_branch = {(i, j) for i in range(n) for j in range(n) if _related(parents, i, j)}
    assert {(int(r), int(c)) for r, c in zip(*dq.sparsity().get_triplet(), strict=True)} <= (
        on_branch
    )


def _related(parents: list[int], i: int, j: int) -> bool:
    def chain(k: int) -> set[int]:
        out = {k}
        while parents[k] >= 0:
            k = parents[k]
            out.add(k)
        return out

    return i in chain(j) or j in chain(i)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 8),
    prismatic_mask=st.integers(0, 2**9 - 1),
)
def test_random_chains(seed: int, n: int, prismatic_mask: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "chain.urdf"
        path.write_text(_chain_urdf(seed, n, prismatic_mask))
        robot = load_robot(default_spec(path))
    _check(robot, samples=3, seed=seed)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_stage_analytic_equals_reverse_ad(name: str) -> None:
    """The rk4 stage's (k, J) with the analytic derivative equals the reverse-mode one: the
    same sparsity of J (the C chain's compressed columns) and values to 1e-12."""
    robot = load_robot(name)
    tree = RigidBodyTree(robot)
    stages = [
        Transition(tree, "rk4", 3, stage_derivative=mode).rk4_stage_function()
        for mode in ("analytic", "reverse_ad")
    ]
    n, p = robot.n, robot.p
    rng = np.random.default_rng(13)
    for _ in range(10):
        xp, u = rng.uniform(-1.0, 1.0, 4 * n), rng.uniform(-5.0, 5.0, n)
        th = (robot.theta_true + 1.0) * rng.uniform(0.5, 1.5, p)
        (k1, J1), (k2, J2) = (s(xp, u, th) for s in stages)
        assert J1.sparsity() == J2.sparsity()
        assert rel_err(np.array(k1), np.array(k2)) <= 1e-12
        assert rel_err(np.array(J1), np.array(J2)) <= 1e-12
    with pytest.raises(ValueError, match="stage_derivative"):
        Transition(tree, "rk4", 3, stage_derivative="forward")


@pytest.mark.parametrize("name", ["ur5", "panda"])
@pytest.mark.parametrize("mode", ["analytic", "reverse_ad"])
def test_split_stage_equals_the_stage(name: str, mode: str) -> None:
    """The stage without its solves (``rk4_stage_rhs``: k with rhs rows, M;
    ``rk4_stage_jac``: J with dtau rows at a = qdd), solved with M here, equals the stage
    with its unrolled LDL^T to 1e-12; the MX step over it (CasADi's ldl linsol, Gamma from
    the first stage's M) equals the expanded step over the unrolled stage."""
    robot = load_robot(name)
    tr = Transition(RigidBodyTree(robot), "rk4", 3, stage_derivative=mode)
    stage = tr.rk4_stage_function()
    stage_rhs, stage_jac = tr.rk4_stage_split_functions()
    n, p = robot.n, robot.p
    rng = np.random.default_rng(17)
    for _ in range(5):
        xp, u = rng.uniform(-1.0, 1.0, 4 * n), rng.uniform(-5.0, 5.0, n)
        th = (robot.theta_true + 1.0) * rng.uniform(0.5, 1.5, p)
        k, J = (np.array(v) for v in stage(xp, u, th))
        kr, M = (np.array(v) for v in stage_rhs(xp, u, th))
        assert rel_err(M, M.T) == 0.0
        qdd = np.linalg.solve(M, kr[n : 2 * n])
        kr[n : 2 * n] = qdd
        Jr = np.array(ca.densify(stage_jac(xp, u, th, qdd)))
        Jr[n : 2 * n] = np.linalg.solve(M, Jr[n : 2 * n])
        assert rel_err(kr, k) <= 1e-12
        assert rel_err(Jr, J) <= 1e-12
    steps = [tr.rk4_step_function(expand=e) for e in (True, False)]
    for _ in range(3):
        x = np.r_[
            rng.uniform(-1.0, 1.0, 4 * n), (robot.theta_true + 1.0) * rng.uniform(0.5, 1.5, p)
        ]
        u = rng.uniform(-5.0, 5.0, n)
        for a, b in zip(*(f(x, u) for f in steps), strict=True):
            assert rel_err(np.array(b), np.array(a)) <= 1e-12


@pytest.mark.parametrize("name", SHIPPED)
def test_rnea_jet_equals_ad_time_derivatives(name: str) -> None:
    """RNEA on Taylor polynomials (the motor reference's derivatives) equals nested
    forward-mode AD of RNEA along the trajectory (the former implementation)."""
    robot = load_robot(name)
    tree = RigidBodyTree(robot)
    n, p = robot.n, robot.p
    ref, th = ca.SX.sym("ref", 5 * n), ca.SX.sym("theta", p)
    rq, rqd, rqdd, rj, rs = (ref[i * n : (i + 1) * n] for i in range(5))
    jet = ca.Function(
        "jet", [ref, th], rnea_jet(tree, [rq, rqd, rqdd], [rqd, rqdd, rj], [rqdd, rj, rs], th)
    )
    y, yd = ca.SX.sym("y", 3 * n), ca.SX.sym("yd", 3 * n)
    tau = tree.rnea(y[:n], y[n : 2 * n], y[2 * n :], th)
    d1 = ca.jtimes(tau, y, yd)
    d2 = ca.jtimes(d1, y, yd) + ca.jtimes(d1, yd, ca.vertcat(rqdd, rj, rs))
    at = [ca.vertcat(rq, rqd, rqdd), ca.vertcat(rqd, rqdd, rj)]
    ad = ca.Function("ad", [ref, th], ca.substitute([tau, d1, d2], [y, yd], at))
    rng = np.random.default_rng(17)
    for _ in range(10):
        r = rng.uniform(-2.0, 2.0, 5 * n)
        t = (robot.theta_true + 1.0) * rng.uniform(0.5, 1.5, p)
        for a, b in zip(jet(r, t), ad(r, t), strict=True):
            assert rel_err(np.array(a), np.array(b), floor=1.0) <= 1e-12
