"""Joint modes, integrator limits, and libraries at another sampling interval (issue 26,
item 5): codegen/modes.py and runtime/stability.py.

- the stability limits (closed forms, and rk4's ray search) are the edge of the 2x2 modal
  maps built as matrices, and the vectorised growth equals those maps' spectral radius;
- the modes against a closed form (one joint: w^2 = Ks (1/Ml + 1/Mm)) and against numpy's
  general eigensolver on the 2-link arm;
- the Panda's warning at T = 1/30 s (every joint) and none at its own T = 1 ms;
- a Panda library generated at 1/30 s with the substeps the modes choose: its
  transition_jacobian at rest equals R(h A_c)^m built from Pinocchio's ABA derivatives, and its
  spectral radius is the physical one (gravity's), where one rk4 step would give 2e4; a second
  call reuses it;
- a covariance failure on a model that cannot integrate its joints names them and the fix.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import generate, library_at_period
from amsfe_sym.codegen.modes import (
    joint_modes,
    modes_at,
    modes_document,
    period_fix,
    robot_source,
    spec_at_period,
    warn_stiff,
)
from amsfe_sym.errors import EstimatorError
from amsfe_sym.estimation.base import FilterConfig
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.load.spec import load_spec, robots_dir
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)
from amsfe_sym.runtime.stability import (
    DEFAULT_MARGIN,
    STABILITY_MARGIN,
    covariance_hint,
    growth_per_step,
    modal_spectral_radius,
    stable_wh,
    stiff_joints,
    stiffness_fix,
    substeps_for,
)

INTEGRATORS = ("rk4", "semi_implicit", "paper")
ZETAS = (0.0, 0.01, 0.2, 0.7, 0.999, 1.0, 1.5, 3.0)
T_LOG = 1.0 / 30.0  # a 30 Hz JointState log


@pytest.fixture(scope="module")
def panda() -> Robot:
    return load_robot("panda")


# ------------------------------------------------------------------------------ limits


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_stable_wh_is_the_edge_of_the_modal_map(integrator: str) -> None:
    for zeta in ZETAS:
        y = float(stable_wh(integrator, zeta))
        assert modal_spectral_radius(integrator, zeta, y * (1 - 1e-7)) <= 1 + 1e-9, zeta
        past = max(y * (1 + 1e-4), 1e-3)
        assert modal_spectral_radius(integrator, zeta, past) > 1 + 1e-9, zeta


def test_undamped_limits() -> None:
    assert float(stable_wh("rk4", 0.0)) == pytest.approx(2 * math.sqrt(2), abs=1e-9)
    assert float(stable_wh("semi_implicit", 0.0)) == pytest.approx(2.0, abs=1e-12)
    assert float(stable_wh("paper", 0.0)) == 0.0
    with pytest.raises(ValueError):
        stable_wh("euler", 0.1)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_growth_per_step_is_the_modal_maps_spectral_radius(integrator: str) -> None:
    rng = np.random.default_rng(3)
    zeta, y = rng.uniform(0, 2.5, 60), rng.uniform(0, 5, 60)
    got = growth_per_step(integrator, zeta, y)
    want = [modal_spectral_radius(integrator, z, v) for z, v in zip(zeta, y, strict=True)]
    np.testing.assert_allclose(got, want, rtol=1e-10)


# ------------------------------------------------------------------------------ modes


def test_one_link_mode_is_the_two_mass_closed_form() -> None:
    robot = load_robot("paper_1link")
    (jm,) = joint_modes(robot)
    data = robot.model.createData()
    Ml = float(pin.crba(robot.model, data, robot.to_pin_q(np.zeros(1)))[0, 0])
    Ks, Mm, Fm = (float(v[0]) for v in (robot.Ks, robot.Mm, robot.Fm))
    w = math.sqrt(Ks * (1 / Ml + 1 / Mm))
    assert jm.highest.w == pytest.approx(w, rel=1e-12)
    # mass-normalised shape (1, -Ml/Mm) a: zeta = Fm phi_m^2 / (2 w)
    assert jm.highest.zeta == pytest.approx(Fm * Ml / (2 * w * Mm * (Mm + Ml)), rel=1e-10)


def test_two_link_modes_match_numpy_eig() -> None:
    robot = load_robot("paper_2link")
    n = robot.n
    rng = np.random.default_rng(7)
    qs = rng.uniform(-math.pi, math.pi, (5, n))
    ms = modes_at(robot, qs, robot.theta_true)
    model = robot.pin_model_at(robot.theta_true)
    data = model.createData()
    Ks = np.diag(robot.Ks)
    K = np.block([[Ks, -Ks], [-Ks, Ks]])
    for s, q in enumerate(qs):
        B = scipy.linalg.block_diag(pin.crba(model, data, robot.to_pin_q(q)), np.diag(robot.Mm))
        B = np.triu(B) + np.triu(B, 1).T
        lam = np.sort(np.linalg.eigvals(np.linalg.solve(B, K)).real)[n:]  # general, not eigh
        np.testing.assert_allclose(ms.w[s], np.sqrt(lam), rtol=1e-10)
        assert sorted(ms.joint[s]) == [0, 1]  # one mode per spring here


def test_panda_warns_at_30_hz_and_not_at_its_own_T(panda: Robot, capsys) -> None:
    modes = joint_modes(panda)
    T = panda.spec.model.T
    assert stiff_joints(modes, T, "rk4", panda.spec.model.model_substeps) == ()
    stiff = stiff_joints(modes, T_LOG, "rk4", 1)
    assert {s.joint for s in stiff} == {j.name for j in panda.joints}
    assert all(s.wT > s.limit > 2.8 for s in stiff)
    wmax = max(m.highest.w for m in modes)
    for margin in (DEFAULT_MARGIN, STABILITY_MARGIN):
        m = substeps_for(modes, T_LOG, margin)
        assert wmax * T_LOG / m <= margin < wmax * T_LOG / (m - 1)  # the smallest such m
        assert stiff_joints(modes, T_LOG, "rk4", m) == ()
    k = substeps_for(modes, T_LOG)
    warn_stiff(stiff, robot_source(panda.spec), modes)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == len(panda.joints)
    for line, s in zip(lines, stiff, strict=True):
        assert f"joint {s.joint}: w = " in line and f"w T = {s.wT:.3g} > 2.83 (rk4" in line
        assert f"model_substeps = {k} in robots/panda/robot.toml" in line
        assert "--period" in line


def test_covariance_hint_names_the_joints_and_the_fix(panda: Robot) -> None:
    modes = joint_modes(panda)
    raw = {"T": T_LOG, "integrator": "rk4", "model_substeps": 1, "name": "panda"}
    raw["joint_modes"] = modes_document(panda, modes)
    hint = covariance_hint(raw)
    assert hint is not None
    k = substeps_for(modes, T_LOG)
    assert "joint panda_joint3: w = " in hint and "> 2.83 (rk4" in hint
    assert f"model_substeps = {k} in robots/panda/robot.toml or generate" in hint
    assert f"(amsfe generate panda --period 0.0333333 --substeps {k})" in hint
    assert covariance_hint({**raw, "model_substeps": k}) is None
    assert covariance_hint({**raw, "joint_modes": None}) is None  # an older library


def test_spec_at_period_is_derived_in_memory(panda: Robot) -> None:
    toml = robots_dir() / "panda" / "robot.toml"
    before = toml.read_bytes()
    spec = spec_at_period("panda", T_LOG, loaded=panda)
    k = substeps_for(joint_modes(panda), T_LOG)
    assert spec.name == f"panda_T33333p333us_rk4x{k}"
    assert (spec.model.T, spec.model.model_substeps, spec.model.integrator) == (T_LOG, k, "rk4")
    assert (spec.camera.period, spec.camera.delay) == (1, 1)  # 33 ms at 1 kHz: one step
    assert spec.model.plant_substeps == 16  # stable, w h <= 2.0 (the robot's own 2 are not)
    assert toml.read_bytes() == before and spec.spec_path == toml.resolve()
    assert period_fix("panda", T_LOG, loaded=panda).startswith(
        f"amsfe generate panda --period {T_LOG:.12g} (its own library, model_substeps = {k} "
    )
    # a paper-integrator robot its Euler form cannot integrate at T becomes rk4
    one = spec_at_period("paper_1link", 0.2)
    assert one.model.integrator == "rk4" and one.name.endswith("_rk4x7")  # w T 3.02 / 0.5


def test_the_fix_names_what_the_user_edits(tmp_path) -> None:
    """A shipped robot by name, a robot folder of one's own by its path, a bare URDF with no
    robot.toml to edit."""
    shipped = robot_source(load_spec("panda"))
    assert (shipped.robot, shipped.spec_file) == ("panda", "robots/panda/robot.toml")
    mine = tmp_path / "my_arm"
    mine.mkdir()
    urdf = robots_dir() / "paper_2link" / "paper_2link.urdf"
    (mine / "robot.toml").write_text(f'urdf = "{urdf}"\n[model]\nT = 0.0333\n')
    own = robot_source(load_spec(mine))
    assert (own.robot, own.spec_file) == (str(mine), str(mine / "robot.toml"))
    bare = robot_source(load_spec(urdf))
    assert (bare.robot, bare.spec_file) == (str(urdf), None)
    modes = joint_modes(load_robot(mine))
    stiff = stiff_joints(modes, 0.0333, "semi_implicit")
    assert stiffness_fix(own, 0.0333, "semi_implicit", 1).startswith(
        f'set [model] integrator = "rk4" and model_substeps = 1 in {mine / "robot.toml"}'
    )
    assert stiff == ()  # the 2-link arm's modes (w <= 19.4 rad/s) at 30 Hz, symplectic Euler


def test_bad_period_is_one_line_and_writes_nothing(tmp_path, capsys) -> None:
    for bad in (["--period", "-0.1"], ["--period", "nan"], ["--substeps", "0"]):
        out = tmp_path / "gen"
        assert main(["generate", "paper_2link", "--out", str(out), *bad]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "expected" in err, err
        assert not out.exists()


# ------------------------------------------------------------------------------ compiled


def _continuous_jacobian(
    robot: Robot, q: np.ndarray, theta: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State x at rest at q (the springs hold gravity, u = g(q)), u, and the continuous-time
    jacobian A_c (4n x 4n) of eqs. (1a)-(1d) there from Pinocchio's ABA derivatives."""
    n = robot.n
    model = robot.pin_model_at(theta)
    data = model.createData()
    pq = robot.to_pin_q(q)
    g = pin.computeGeneralizedGravity(model, data, pq)
    Ks = robot.stiffness_at(theta)
    x = np.concatenate([q, np.zeros(n), q + g / Ks, np.zeros(n), theta])
    pin.computeABADerivatives(model, data, pq, np.zeros(n), g)
    Minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
    Ac = np.zeros((4 * n, 4 * n))
    eye = np.eye(n)
    Ac[:n, n : 2 * n] = eye
    Ac[n : 2 * n, :n] = data.ddq_dq - Minv * Ks
    Ac[n : 2 * n, n : 2 * n] = data.ddq_dv
    Ac[n : 2 * n, 2 * n : 3 * n] = Minv * Ks
    Ac[2 * n : 3 * n, 3 * n :] = eye
    Ac[3 * n :, :n] = np.diag(Ks / robot.Mm)
    Ac[3 * n :, 2 * n : 3 * n] = -np.diag(Ks / robot.Mm)
    Ac[3 * n :, 3 * n :] = -np.diag(robot.Fm / robot.Mm)
    return x, g, Ac


def _rk4_map(Z: np.ndarray) -> np.ndarray:
    eye = np.eye(len(Z))
    return eye + Z @ (eye + Z @ (eye / 2 + Z @ (eye / 6 + Z / 24)))


def _rho(M: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M))))


#: The period of docs/tutorials/real-recording.md's ``amsfe generate panda --period 0.03333``
#: (what the refusal of its 10 s, 30 Hz Franka log prints): the test below builds the same
#: library, so a run of the suite compiles it once (the content-hash cache).
T_TUTORIAL = 0.03333


@pytest.mark.slow
def test_panda_at_30_hz_is_stable_and_cached(panda: Robot, capsys) -> None:
    """One 7-DOF compile, the library of docs/tutorials/real-recording.md's ``amsfe generate
    panda --period 0.03333`` (shared with that page's test: the suite compiles it once; a
    second call must not compile).  Its default substeps (w h <= 0.5: 62) are more than the
    fewest stable ones (w h <= 2.0: 16), so it is stable (rk4 is stable for every w h <=
    2.83); the exact rk4 map of the continuous jacobian, to 1e-9."""
    T = T_TUTORIAL
    modes = joint_modes(panda)
    k = substeps_for(modes, T)
    assert k == 62 and substeps_for(modes, T, STABILITY_MARGIN) == 16
    lib = library_at_period("panda", T)
    raw = lib.manifest.raw
    m, n = raw["model_substeps"], panda.n
    assert m == k
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = rng.uniform(-1.0, 1.0, n)
        x, u, Ac = _continuous_jacobian(panda, q, panda.theta_initial)
        (A,) = lib.function("transition_jacobian")(x, u)
        want = np.linalg.matrix_power(_rk4_map(T / m * Ac), m)
        np.testing.assert_allclose(
            A[: 4 * n, : 4 * n], want, rtol=0, atol=1e-9 * np.abs(want).max()
        )
        # gravity tips the arm over: the physical map exp(A_c T) grows (|lambda| ~ 1.14); the
        # model adds nothing to it, where one rk4 step per T would amplify by ~2e4
        physical = _rho(scipy.linalg.expm(Ac * T))
        assert _rho(A[: 4 * n, : 4 * n]) <= physical * (1 + 1e-9)
        assert _rho(_rk4_map(T * Ac)) > 100 * physical
    again = generate(spec_at_period("panda", T, substeps=k, loaded=panda))
    assert again.reused and again.out_dir == lib.dir and again.stiff() == ()
    assert main(["generate", "panda", "--period", "0.03333"]) == 0  # the tutorial's command
    out, err = capsys.readouterr()
    assert "panda_T33330us_rk4x62: up to date (cached)" in out
    assert "integrator rk4, model_substeps 62, camera period 1 / delay 1 steps" in out
    assert "warning" not in err


@pytest.mark.slow
def test_covariance_failure_names_the_stiff_joint() -> None:
    """The 2-link arm's rk4 model at T = 0.5 s with one step (w T = 9.7 and 3.3 > 2.83): the
    compiled estimator loses its covariance and says which joints and what to do."""
    base = load_spec("paper_2link")
    base = replace(base, model=replace(base.model, integrator="rk4"))
    spec = spec_at_period(base, 0.5, substeps=1)
    res = generate(spec)
    assert [s.joint for s in res.stiff()] == ["joint2", "joint1"]  # worst first
    lib = ModelLibrary(res.out_dir)
    n = lib.n
    x0 = np.concatenate([[0.3, -0.4], np.zeros(n), [0.3, -0.4], np.zeros(n), lib.theta_initial])
    est = make_compiled_estimator(
        "encoders",
        model=CompiledTransition(lib, noise_covariance(lib, 0.1, 0.1, 0.01)),
        encoder=EncoderMeasurement(lib, np.full(n, 1e-6), np.full(n, 1e-4)),
        camera=CameraMeasurement(lib, 1.0),
        x0=x0,
        P0=np.eye(lib.N) * 1e-4,
        config=FilterConfig(),
    )
    z = np.concatenate([x0[2 * n : 3 * n], x0[3 * n : 4 * n]])
    with pytest.raises(EstimatorError) as err:
        for _ in range(200):
            est.step(np.zeros(n), z)
    msg = str(err.value)
    assert "lost positive definiteness" in msg
    assert "joint joint2: w = " in msg and "(rk4, T = 0.5 s)" in msg
    # NaN from the model and a non-PD innovation covariance say the same; bad input does not
    for status, named in ((-3, True), (-4, True), (-1, False)):
        assert ("joint joint2: w = " in str(est._error("tick", status))) is named
    k = substeps_for(res.modes, 0.5)
    assert k == 20 and f"(amsfe generate paper_2link --period 0.5 --substeps {k})" in msg
