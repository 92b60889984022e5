"""Symbolic terms (CasADi VM, before code generation) vs Pinocchio and the paper's closed form."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from amsfe_sym.apps.check import random_states, rel_err
from amsfe_sym.load import load_robot
from amsfe_sym.symbolic.dynamics import RigidBodyTree
from amsfe_sym.symbolic.model import build_functions

from .conftest import SHIPPED, erd_urdf, ur5_three_thetas


def _pin_M(robot, q, th):
    m = robot.pin_model_at(th)
    M = pin.crba(m, m.createData(), robot.to_pin_q(q))
    return np.triu(M) + np.triu(M, 1).T


@pytest.mark.parametrize("name", SHIPPED)
def test_mass_matrix_and_bias_vs_pinocchio(name: str) -> None:
    robot = load_robot(name)
    fns = build_functions(robot, parts=("model",)).functions
    rng = np.random.default_rng(42)
    worst_M = worst_b = 0.0
    for x in random_states(robot, 60, rng):
        n = robot.n
        q, qd, th = x[:n], x[n : 2 * n], x[4 * n :]
        m = robot.pin_model_at(th)
        d = m.createData()
        M = np.array(fns["mass_matrix"](q, th))
        b = np.array(fns["bias"](q, qd, th)).ravel()
        worst_M = max(worst_M, rel_err(M, _pin_M(robot, q, th)))
        worst_b = max(worst_b, rel_err(b, pin.nle(m, d, robot.to_pin_q(q), qd)))
    assert worst_M <= 1e-10
    assert worst_b <= 1e-10


def _eq53(q, qd, m1, m2, l1, l2, g=9.81):
    """The paper's eq. (53) for the 2-link arm (PAPER-NOTES section 1 on what C means)."""
    c2, s2 = np.cos(q[1]), np.sin(q[1])
    M11 = (m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2
    M12 = m2 * l2**2 + m2 * l1 * l2 * c2
    M = np.array([[M11, M12], [M12, m2 * l2**2]])
    g1 = -(m1 + m2) * g * l1 * np.sin(q[0]) - m2 * g * l2 * np.sin(q[0] + q[1])
    gv = np.array([g1, -m2 * g * l2 * np.sin(q[0] + q[1])])
    C = np.array(
        [
            -m2 * l1 * l2 * s2 * (2 * qd[0] * qd[1] + qd[1] ** 2),
            -m2 * l1 * l2 * s2 * qd[0] * qd[1],
        ]
    )
    return M, gv, C


@pytest.mark.parametrize("payload", [0.0, 0.15])
def test_paper_2link_matches_eq53(payload: float) -> None:
    """M(q) and g(q) equal eq. (53); (53)'s C equals Mdot(q) qd.  The tip payload theta
    [kg] sits at the tip of link 2, so it adds to m2."""
    robot = load_robot("paper_2link")
    tree = RigidBodyTree(robot)
    q, qd, th = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("th", 1)
    M_sx = tree.mass_matrix(q, th)
    Mdot_qd = ca.jtimes(ca.mtimes(M_sx, ca.DM([[0.0], [0.0]]) + qd), q, qd)  # (dM/dq . qd) qd
    f = ca.Function("f", [q, qd, th], [M_sx, tree.gravity_torque(q, th), Mdot_qd])
    rng = np.random.default_rng(7)
    for _ in range(50):
        qq = rng.uniform(-np.pi, np.pi, 2)
        vv = rng.uniform(-3, 3, 2)
        M, g, Mdq = (np.array(v).squeeze() for v in f(qq, vv, payload))
        M53, g53, C53 = _eq53(qq, vv, 2.5, 3.0 + payload, 0.35, 0.20)
        assert np.max(np.abs(M - M53)) <= 1e-12
        assert np.max(np.abs(g - g53)) <= 1e-12
        assert np.max(np.abs(Mdq - C53)) <= 1e-12


@pytest.mark.parametrize("name", SHIPPED)
def test_tracked_point_and_camera(name: str) -> None:
    robot = load_robot(name)
    fns = build_functions(robot, parts=("model",)).functions
    rng = np.random.default_rng(3)
    for x in random_states(robot, 30, rng):
        q, th = x[: robot.n], x[4 * robot.n :]
        m = robot.pin_model_at(th)
        d = m.createData()
        pin.framesForwardKinematics(m, d, robot.to_pin_q(q))
        r_ref = d.oMf[robot.tracked_frame_id].act(robot.tracked_offset)
        r = np.array(fns["tracked_point"](q, th)).ravel()
        assert np.max(np.abs(r - r_ref)) <= 1e-12
        # independent pinhole: camera frame from the spec's position / look_at / up
        cam = robot.camera
        pc = cam.R_cw @ (r_ref - cam.position)
        y_ref = [
            cam.K[0, 0] * pc[0] / pc[2] + cam.K[0, 2],
            cam.K[1, 1] * pc[1] / pc[2] + cam.K[1, 2],
        ]
        y = np.array(fns["camera"](q, th)).ravel()
        assert np.max(np.abs(y - y_ref)) <= 1e-9


def test_camera_rotation_is_proper_and_looks_at_target() -> None:
    robot = load_robot("paper_2link")
    cam = robot.camera
    assert np.allclose(cam.R_cw @ cam.R_cw.T, np.eye(3), atol=1e-14)
    assert np.isclose(np.linalg.det(cam.R_cw), 1.0)
    # the look_at point (the shoulder, origin) projects to the principal point
    y = cam.project(np.zeros(3))
    assert np.allclose(y, cam.K[:2, 2], atol=1e-9)
    # world up appears up in the image (smaller v)
    assert cam.project(np.array([0.0, 0.0, 0.3]))[1] < cam.K[1, 2]


def test_theta_kinds_vs_pinocchio(tmp_path) -> None:
    """payload_mass, link_mass and joint_stiffness bindings on the UR5 from example-robot-data."""
    robot = load_robot(ur5_three_thetas(tmp_path))
    urdf = erd_urdf("ur_description/urdf/ur5_robot.urdf")
    fns = build_functions(robot).functions
    full = pin.buildModelFromUrdf(str(urdf))
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = rng.uniform(-np.pi, np.pi, 6)
        th = np.array([rng.uniform(0, 4), rng.uniform(0.5, 5), 500.0])
        # reference: the full URDF model with the forearm mass scaled and a point payload
        ref = full.copy()
        jid = ref.getJointId("elbow_joint")
        fid = ref.getFrameId("forearm_link")
        nominal = ref.frames[fid].placement.act(_urdf_link_inertia(urdf, "forearm_link"))
        params = ref.inertias[jid].toDynamicParameters() + (th[1] / nominal.mass - 1.0) * (
            nominal.toDynamicParameters()
        )
        ref.inertias[jid] = pin.Inertia.FromDynamicParameters(params)
        tool = ref.frames[ref.getFrameId("tool0")]
        c = tool.placement.act(np.array([0.0, 0.0, 0.1]))
        ref.inertias[tool.parentJoint] += pin.Inertia(th[0], c, np.zeros((3, 3)))
        M_ref = pin.crba(ref, ref.createData(), q)
        M_ref = np.triu(M_ref) + np.triu(M_ref, 1).T
        assert rel_err(np.array(fns["mass_matrix"](q, th)), M_ref) <= 1e-10
    # the stiffness parameter replaces Ks of the elbow in the transition (semi-implicit):
    # d qd+/d k3 = T M^-1 e3 (qm3 - q3), d q+ = T d qd+, d qmd+ = -T (qm3 - q3)/Mm3 e3,
    # d qm+ = T d qmd+; checked in closed form and by central differences
    n, T = 6, robot.spec.model.T
    q = rng.uniform(-1, 1, n)
    x = np.concatenate([q, rng.uniform(-1, 1, n), q + rng.uniform(-0.05, 0.05, n)])
    x = np.concatenate([x, rng.uniform(-1, 1, n), [1.0, 2.275, 123.0]])
    u = rng.uniform(-5, 5, n)
    col = np.array(fns["transition_jacobian"](x, u))[:, 4 * n + 2]
    M = np.array(fns["mass_matrix"](q, x[4 * n :]))
    defl = x[2 * n + 2] - x[2]
    d_qd = T * np.linalg.solve(M, np.eye(n)[2]) * defl
    d_qmd = -T * defl / robot.Mm[2] * np.eye(n)[2]
    closed = np.concatenate([T * d_qd, d_qd, T * d_qmd, d_qmd, np.eye(3)[2]])  # theta+ = theta
    assert rel_err(col, closed) <= 1e-10
    h = 1e-3 * 123.0
    e = np.zeros(4 * n + 3)
    e[4 * n + 2] = h
    fd = (np.array(fns["transition"](x + e, u)) - np.array(fns["transition"](x - e, u))) / (2 * h)
    assert rel_err(col, fd.ravel()) <= 1e-8  # F is affine in k3 (central differences exact)


def _urdf_link_inertia(urdf, link):
    import xml.etree.ElementTree as ET

    for ln in ET.parse(urdf).getroot().findall("link"):
        if ln.get("name") == link:
            i = ln.find("inertial")
            mass = float(i.find("mass").get("value"))
            o = i.find("origin")
            xyz = (
                np.array([float(v) for v in o.get("xyz", "0 0 0").split()])
                if o is not None
                else np.zeros(3)
            )
            rpy = [float(v) for v in o.get("rpy", "0 0 0").split()] if o is not None else [0, 0, 0]
            R = pin.rpy.rpyToMatrix(*rpy)
            e = i.find("inertia")
            v = {k: float(e.get(k)) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
            inertia = np.array(
                [
                    [v["ixx"], v["ixy"], v["ixz"]],
                    [v["ixy"], v["iyy"], v["iyz"]],
                    [v["ixz"], v["iyz"], v["izz"]],
                ]
            )
            return pin.Inertia(mass, xyz, R @ inertia @ R.T)
    raise KeyError(link)
