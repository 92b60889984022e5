"""The shipped Franka Emika Panda (robots/panda), checked without compiling its library.

- its URDF carries Gaz et al. 2019's identified inertial parameters (robots/panda/gaz2019.toml),
  and the one difference (link 1's centre-of-mass z) changes neither M nor the bias;
- the spec: 7 revolute joints, the fingers locked, the elastic joints' modes resolved at T;
- the symbolic model (CasADi VM) against Pinocchio: the rk4 transition and the truth plant
  against numpy RK4 on ``pin.aba`` (M, the bias and the camera are in test_dynamics.py);
- ``panda-control`` resolves against the spec (shapes, camera timing) without generating.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import tomllib

from amsfe_sym.apps.check import random_states, rel_err
from amsfe_sym.apps.reference import PinocchioOracle
from amsfe_sym.codegen.preflight import check_scenario_shapes
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import load_spec, robots_dir
from amsfe_sym.scenario import camera_timing, load_scenario
from amsfe_sym.symbolic.model import build_functions

PANDA = robots_dir() / "panda"


def test_urdf_carries_the_identified_parameters() -> None:
    with (PANDA / "gaz2019.toml").open("rb") as fh:
        gaz = tomllib.load(fh)
    links = {ln.get("name"): ln for ln in ET.parse(PANDA / "panda.urdf").getroot().iter("link")}
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    for i in range(7):
        inertial = links[f"panda_link{i + 1}"].find("inertial")
        assert inertial is not None
        mass, origin, tensor = (inertial.find(t) for t in ("mass", "origin", "inertia"))
        assert mass is not None and origin is not None and tensor is not None
        assert float(mass.get("value", "nan")) == gaz["mass"][i]
        assert [float(tensor.get(k, "nan")) for k in keys] == gaz["inertia"][i]
        com = [float(v) for v in origin.get("xyz", "").split()]
        # link 1 (vertical axis): its centre-of-mass z is not identifiable; the URDF's differs
        assert com[: 2 if i == 0 else 3] == gaz["com"][i][: 2 if i == 0 else 3], i
    # ... and it enters neither M nor the bias (fingers at their locked 0)
    urdf = pin.buildModelFromUrdf(str(PANDA / "panda.urdf"))
    ident = urdf.copy()
    lever = ident.inertias[1].lever.copy()
    lever[2] = gaz["com"][0][2]
    ident.inertias[1] = pin.Inertia(ident.inertias[1].mass, lever, ident.inertias[1].inertia)
    d1, d2 = urdf.createData(), ident.createData()
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = np.r_[rng.uniform(urdf.lowerPositionLimit[:7], urdf.upperPositionLimit[:7]), 0, 0]
        v = np.r_[rng.uniform(-2.0, 2.0, 7), 0, 0]
        np.testing.assert_allclose(pin.crba(urdf, d1, q), pin.crba(ident, d2, q), atol=1e-14)
        np.testing.assert_allclose(pin.nle(urdf, d1, q, v), pin.nle(ident, d2, q, v), atol=1e-13)


def test_spec_locks_the_fingers_and_resolves_every_joint_mode() -> None:
    robot = load_robot("panda")
    spec = load_spec("panda")
    assert robot.n == 7 and robot.p == 1 and robot.N == 29
    assert [j.name for j in robot.joints] == [f"panda_joint{i}" for i in range(1, 8)]
    assert set(spec.model.locked) == {"panda_finger_joint1", "panda_finger_joint2"}
    assert spec.model.integrator == "rk4"
    # the joints' link-against-rotor modes stay well inside what T resolves (robot.toml: the
    # largest w T is 0.79), and M is positive definite, over random q within the limits
    Ks, Mm, T = np.array(spec.actuators.Ks), np.array(spec.actuators.Mm), spec.model.T
    model = robot.model
    data = model.createData()
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(100):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert np.linalg.eigvalsh(M)[0] > 1e-3
        J = 1.0 / np.diag(np.linalg.inv(M))
        worst = max(worst, float(np.max(np.sqrt(Ks * (1.0 / J + 1.0 / Mm)) * T)))
    assert 0.5 < worst <= 0.8


def test_rk4_transition_and_plant_match_pinocchio() -> None:
    """The Panda's symbolic rk4 transition and truth plant (CasADi VM) vs numpy RK4 on
    ``pin.aba``, at random states within the joint limits."""
    robot = load_robot("panda")
    fns = build_functions(robot, parts=("model",)).functions
    oracle = PinocchioOracle(robot)
    rng = np.random.default_rng(2)
    n = robot.n
    for x in random_states(robot, 4, rng):
        u = rng.uniform(-5.0, 5.0, n)
        tau = rng.normal(0.0, 0.1, 2 * n)
        xn = np.array(fns["transition"](x, u)).ravel()
        assert rel_err(xn, oracle.transition(x, u)) <= 1e-10
        th = x[4 * n :]
        xp = np.array(fns["plant_step"](x[: 4 * n], u, th, tau)).ravel()
        assert rel_err(xp, oracle.plant_step(x[: 4 * n], u, th, tau)) <= 1e-10


def test_panda_control_fits_the_spec() -> None:
    sc = load_scenario("panda-control")
    spec = load_spec(sc.robot)
    check_scenario_shapes(sc, spec)
    timing = camera_timing(sc, spec.camera.period, spec.camera.delay, needs_history=True)
    assert (timing.period, timing.delay) == (33, 33)
    assert sc.compare == ("amsfe", "dtsmc", "truth")
    # the plant starts on the reference (no start transient)
    t = sc.trajectory
    amp, om, ph, off = (np.array(t[k]) for k in ("amplitude", "omega", "phase", "offset"))
    np.testing.assert_allclose(sc.plant.q0, off + amp * np.sin(ph), atol=1e-4)
    np.testing.assert_allclose(sc.plant.qd0, amp * om * np.cos(ph), atol=1e-4)
