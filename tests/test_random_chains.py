"""Property-based: random serial chains of 1-8 revolute/prismatic joints with random axes,
placements and inertias; the SX dynamics must equal Pinocchio's."""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amsfe_sym.apps.check import rel_err
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import default_spec
from amsfe_sym.symbolic.dynamics import RigidBodyTree


def _chain_urdf(seed: int, n: int, prismatic_mask: int) -> str:
    rng = np.random.default_rng(seed)
    parts = ['<robot name="chain">', '<link name="l0"/>']
    for i in range(1, n + 1):
        m = rng.uniform(0.1, 5.0)
        dims = rng.uniform(0.02, 0.4, 3)  # a box: principal moments satisfy the triangle law
        moments = (
            m
            / 12.0
            * np.array(
                [
                    dims[1] ** 2 + dims[2] ** 2,
                    dims[0] ** 2 + dims[2] ** 2,
                    dims[0] ** 2 + dims[1] ** 2,
                ]
            )
        )
        R = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        inertia = R @ np.diag(moments) @ R.T
        com = rng.uniform(-0.2, 0.2, 3)
        parts.append(
            f'<link name="l{i}"><inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/>'
            f'<mass value="{m}"/><inertia ixx="{inertia[0, 0]}" ixy="{inertia[0, 1]}" '
            f'ixz="{inertia[0, 2]}" iyy="{inertia[1, 1]}" iyz="{inertia[1, 2]}" '
            f'izz="{inertia[2, 2]}"/></inertial></link>'
        )
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        xyz = rng.uniform(-0.3, 0.3, 3)
        rpy = rng.uniform(-np.pi, np.pi, 3)
        kind = "prismatic" if (prismatic_mask >> i) & 1 else "revolute"
        parts.append(
            f'<joint name="j{i}" type="{kind}"><parent link="l{i - 1}"/><child link="l{i}"/>'
            f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
            f'<axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
            '<limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 8),
    prismatic_mask=st.integers(0, 2**9 - 1),
)
def test_random_chain_matches_pinocchio(seed: int, n: int, prismatic_mask: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "chain.urdf"
        path.write_text(_chain_urdf(seed, n, prismatic_mask))
        robot = load_robot(default_spec(path))
    tree = RigidBodyTree(robot)
    qs, qds, th = ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("theta", 0)
    fns = {
        "mass_matrix": ca.Function("M", [qs, th], [tree.mass_matrix(qs, th)]),
        "bias": ca.Function("b", [qs, qds, th], [tree.bias(qs, qds, th)]),
        "tracked_point": ca.Function(
            "r", [qs, th], [tree.frame_point(qs, robot.tracked_frame_id, robot.tracked_offset)]
        ),
    }
    assert robot.n == n
    assert [j.kind for j in robot.joints] == [
        "prismatic" if (prismatic_mask >> i) & 1 else "revolute" for i in range(1, n + 1)
    ]
    model = robot.pin_model_at([])
    data = model.createData()
    rng = np.random.default_rng(seed)
    for _ in range(3):
        q = rng.uniform(-1, 1, n)
        qd = rng.uniform(-2, 2, n)
        M = np.array(fns["mass_matrix"](q, []))
        M_ref = pin.crba(model, data, q)
        M_ref = np.triu(M_ref) + np.triu(M_ref, 1).T
        assert rel_err(M, M_ref) <= 1e-10
        b = np.array(fns["bias"](q, qd, [])).ravel()
        assert rel_err(b, pin.nle(model, data, q, qd)) <= 1e-10
        pin.framesForwardKinematics(model, data, q)
        r = np.array(fns["tracked_point"](q, [])).ravel()
        assert np.max(np.abs(r - data.oMf[robot.tracked_frame_id].translation)) <= 1e-12
