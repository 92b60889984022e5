"""Loading: every refused input gives the documented error naming file, element and fix, and
nothing is written; valid edge cases load with the right joints."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from amsfe_sym import errors
from amsfe_sym.apps.check import random_states, rel_err
from amsfe_sym.codegen import generate
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import default_spec
from amsfe_sym.symbolic.model import build_functions

from .conftest import DATA

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

BAD = tomllib.loads((DATA / "bad_urdfs" / "cases.toml").read_text())["case"]
GOOD = tomllib.loads((DATA / "good_urdfs" / "cases.toml").read_text())["case"]


@pytest.mark.parametrize("case", BAD, ids=[c["file"] for c in BAD])
def test_bad_urdf_refused_and_nothing_written(case: dict, tmp_path: Path) -> None:
    path = DATA / "bad_urdfs" / case["file"]
    cls = getattr(errors, case["error"])
    with pytest.raises(cls) as info:
        load_robot(default_spec(path))
    msg = str(info.value)
    assert (case["element"] or case["file"]) in msg
    assert case.get("value", "") in msg
    assert case["file"] in msg
    assert "expected" in msg and "Fix:" in msg
    # builtin compatibility: every loader error is also a ValueError
    assert isinstance(info.value, ValueError)
    out = tmp_path / "gen"
    with pytest.raises(cls):
        generate(path, out=out)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("case", GOOD, ids=[c["file"] for c in GOOD])
def test_good_edge_cases(case: dict, tmp_path: Path) -> None:
    path = DATA / "good_urdfs" / case["file"]
    (tmp_path / "robot.toml").write_text(
        f'urdf = "{path}"\n[tracked]\nframe = "{case["tracked"]}"\n'
    )
    robot = load_robot(tmp_path / "robot.toml")
    assert [j.name for j in robot.joints] == case["joints"]
    assert [j.kind for j in robot.joints] == case["types"]
    assert robot.n == case["n"] and robot.model.nq == case["pin_nq"]
    fns = build_functions(robot).functions
    model = robot.pin_model_at([])
    data = model.createData()
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-1.5, 1.5, robot.n)
        qd = rng.uniform(-2, 2, robot.n)
        qp = robot.to_pin_q(q)
        M_ref = pin.crba(model, data, qp)
        M_ref = np.triu(M_ref) + np.triu(M_ref, 1).T
        assert rel_err(np.array(fns["mass_matrix"](q, [])), M_ref) <= 1e-10
        assert (
            rel_err(np.array(fns["bias"](q, qd, [])).ravel(), pin.nle(model, data, qp, qd)) <= 1e-10
        )
        pin.framesForwardKinematics(model, data, qp)
        r = np.array(fns["tracked_point"](q, [])).ravel()
        assert np.max(np.abs(r - data.oMf[robot.tracked_frame_id].translation)) <= 1e-12


def test_locking_joints_reduces_the_model(tmp_path: Path) -> None:
    path = DATA / "good_urdfs" / "tree.urdf"
    robot = load_robot(default_spec(path), lock={"right_joint1": 0.3})
    assert [j.name for j in robot.joints] == ["torso_joint", "left_joint1", "left_joint2"]
    full = pin.buildModelFromUrdf(str(path))
    fns = build_functions(robot).functions
    q = np.array([0.1, -0.4, 0.7])
    qf = np.zeros(full.nq)
    for name, v in zip(["torso_joint", "left_joint1", "left_joint2"], q, strict=True):
        qf[full.joints[full.getJointId(name)].idx_q] = v
    qf[full.joints[full.getJointId("right_joint1")].idx_q] = 0.3
    M_full = pin.crba(full, full.createData(), qf)
    M_full = np.triu(M_full) + np.triu(M_full, 1).T
    keep = [
        full.joints[full.getJointId(n)].idx_v for n in ["torso_joint", "left_joint1", "left_joint2"]
    ]
    assert rel_err(np.array(fns["mass_matrix"](q, [])), M_full[np.ix_(keep, keep)]) <= 1e-12


def _spec(tmp_path: Path, body: str) -> Path:
    urdf = Path(__file__).parent.parent / "robots" / "paper_2link" / "paper_2link.urdf"
    p = tmp_path / "robot.toml"
    p.write_text(f'urdf = "{urdf}"\n{body}')
    return p


@pytest.mark.parametrize(
    ("body", "needle"),
    [
        ('[model]\njoints = ["joint1", "nope"]\n', "'nope'"),
        ('[model]\njoints = ["joint2", "joint1"]\n', "tree order"),
        ("[model]\nlocked = {ghost = 0.1}\n", "'ghost'"),
        ('[tracked]\nframe = "nowhere"\n', "'nowhere'"),
        ("[actuators]\nKs = [1.0]\n", "2 values"),
        ("[actuators]\nKs = [1.0, -2.0]\n", "positive"),
        ("[model]\nT = 0\n", "[1e-06, 10]"),
        ('[model]\nintegrator = "rk45"\n', "integrator"),
        ("[camera]\nfocal = 3\n", "focal"),
        ("colour = 1\n", "colour"),
        ("[[theta]]\nname='a'\nkind='wing_span'\ntarget='tip'\ntrue=1\ninitial=0\n", "wing_span"),
        ("[[theta]]\nname='a'\nkind='payload_mass'\ntarget='x'\ntrue=1\ninitial=0\n", "'x'"),
        ("[[theta]]\nname='a'\nkind='payload_mass'\ntarget='base'\ntrue=1\ninitial=0\n", "fixed"),
        ("[[theta]]\nname='a'\nkind='joint_stiffness'\ntarget='tip'\ntrue=1\ninitial=0\n", "'tip'"),
        ("[[theta]]\nname='a'\nkind='link_mass'\ntarget='tip'\ntrue=1\ninitial=0\n", "positive"),
        ("[[theta]]\nname='a'\nkind='payload_mass'\ntarget='tip'\ntrue=1\n", "initial"),
        ("[camera]\nposition = [0, 0, 1]\nlook_at = [0, 0, 0]\nup = [0, 0, 1]\n", "parallel"),
        ("[model\n", "TOML"),
        # typed values (issue 20): no float() of a boolean or a string, finiteness, integers
        ("[actuators]\nKs = [true, 10.0]\n", "(bool)"),
        ('[actuators]\nKs = ["10", 10]\n', "(a string)"),
        ("[camera]\ncx = nan\n", "finite"),
        ("[model]\ninverse_iterations = 0.4\n", "an integer"),
        ("[model]\nplant_substeps = 0.5\n", "an integer"),
        ("[model]\nmodel_substeps = 0\n", "in [1, "),
        ("[model]\nmodel_substeps = 2.5\n", "an integer"),
        ("[camera]\nperiod = 0.5\n", "an integer"),
        ("[camera]\nperiod = 4294967346\n", "2147483647"),
        ("[model]\nlocked = {joint2 = nan}\n", "finite"),
    ],
)
def test_spec_errors(tmp_path: Path, body: str, needle: str) -> None:
    with pytest.raises(errors.SpecError) as info:
        load_robot(_spec(tmp_path, body))
    assert needle in str(info.value)
    assert "Fix:" in str(info.value)


def test_bare_urdf_defaults() -> None:
    """A bare URDF: all movable joints, tip of the chain tracked, a camera that sees the
    workspace (the tracked point in the image at random q), p = 0."""
    robot = load_robot(DATA / "good_urdfs" / "prismatic_chain.urdf")
    assert robot.p == 0 and robot.n == 2
    assert robot.tracked_frame == "tip"
    fns = build_functions(robot).functions
    rng = np.random.default_rng(1)
    for x in random_states(robot, 50, rng):  # within the joint limits
        y = np.array(fns["camera"](x[:2], [])).ravel()
        assert 0 <= y[0] < robot.camera.width and 0 <= y[1] < robot.camera.height
