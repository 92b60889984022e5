"""The compiled libraries: contract, equality with the CasADi functions they came from,
every function against its reference (finite differences, Pinocchio), and the cache."""

from __future__ import annotations

import json
import shutil

import casadi as ca
import numpy as np
import pytest

from amsfe_sym.apps.check import random_states, run_checks
from amsfe_sym.codegen import generate
from amsfe_sym.symbolic.model import build_functions

from .conftest import COMPILED, erd_urdf

CONTRACT = {
    "mass_matrix": (["q", "theta"], ["M"]),
    "bias": (["q", "qd", "theta"], ["b"]),
    "tracked_point": (["q", "theta"], ["r"]),
    "camera": (["q", "theta"], ["y"]),
    "camera_jacobian": (["q", "theta"], ["dy_dq"]),
    "transition": (["x", "u"], ["x_next"]),
    "transition_jacobian": (["x", "u"], ["A"]),
    "transition_inverse": (["x_next", "u"], ["x", "residual"]),
}


@pytest.mark.parametrize("name", COMPILED)
def test_manifest_contract(name: str, libraries) -> None:
    robot, lib = libraries.get(name)
    m = lib.manifest.raw
    n, p = robot.n, robot.p
    N = 4 * n + p
    assert (m["n"], m["p"], m["N"]) == (n, p, N)
    assert m["joints"] == [j.name for j in robot.joints]
    assert m["tracked_frame"] == robot.tracked_frame
    assert len(m["theta"]) == p and all("kind" in t and "target" in t for t in m["theta"])
    assert m["T"] == robot.spec.model.T
    assert m["state_layout"] == {
        "q": [0, n],
        "qd": [n, 2 * n],
        "qm": [2 * n, 3 * n],
        "qmd": [3 * n, 4 * n],
        "theta": [4 * n, N],
    }
    assert len(m["content_hash"]) == 64
    shapes = {
        "q": [n, 1],
        "qd": [n, 1],
        "theta": [p, 1],
        "x": [N, 1],
        "u": [n, 1],
        "x_next": [N, 1],
        "M": [n, n],
        "b": [n, 1],
        "r": [3, 1],
        "y": [2, 1],
        "dy_dq": [2, n],
        "A": [N, N],
        "residual": [1, 1],
    }
    for fname, (ins, outs) in CONTRACT.items():
        sig = m["functions"][fname]
        assert [i["name"] for i in sig["inputs"]] == ins
        assert [o["name"] for o in sig["outputs"]] == outs
        for io in sig["inputs"] + sig["outputs"]:
            assert io["shape"] == shapes[io["name"]], (fname, io)
    # anyone can load a function with plain CasADi and no other part of the toolkit
    ext = ca.external("mass_matrix", str(lib.dir / m["library"]))
    assert ext.size_out(0) == (n, n)


def estimator_args(
    fns: dict[str, ca.Function], x: np.ndarray, u: np.ndarray, rng: np.random.Generator
) -> dict[str, tuple[object, ...]]:
    """Valid inputs of the estimator functions (symbolic/estimator.py) at state x."""
    N, n = x.shape[0], u.shape[0]
    nw, S = N - 2 * n, fns["est_clone_camera"].size_in(3)[0]
    Na = (1 + S) * N

    def spd(k: int) -> np.ndarray:
        L = 0.1 * rng.normal(size=(k, k))
        return L @ L.T + 0.01 * np.eye(k)

    P, Q, Phi = spd(N), spd(N), np.eye(N) + 0.01 * rng.normal(size=(N, N))
    xa = np.tile(x, 1 + S)
    zc, rc = rng.normal(size=2), np.ones(2)
    sel = np.eye(S)[0]
    return {
        "est_predict": (x, P, u, np.full(nw, 1e-4)),
        "est_camera_update": (x, P, x + 0.01, zc, rc),
        "est_oosm_accumulate": (Phi, Q, Phi.T, P),
        "est_oosm_correct": (x, P, x, P, 0.5 * P, Phi, zc, rc),
        "est_clone_predict": (xa, spd(Na), u, np.full(nw, 1e-4)),
        "est_clone_camera": (xa, spd(Na), x, sel, zc, rc),
    }


@pytest.mark.parametrize("name", COMPILED)
def test_compiled_equals_casadi_function(name: str, libraries) -> None:
    """Compiled C (through the ctypes binding) vs the CasADi VM: equal to rounding."""
    robot, lib = libraries.get(name)
    fns = build_functions(robot).functions
    rng = np.random.default_rng(5)
    for x in random_states(robot, 10, rng):
        n = robot.n
        u = rng.uniform(-3, 3, n)
        q, qd, th = x[:n], x[n : 2 * n], x[4 * n :]
        args = {
            "mass_matrix": (q, th),
            "bias": (q, qd, th),
            "gravity": (q, th),
            "tracked_point": (q, th),
            "camera": (q, th),
            "camera_jacobian": (q, th),
            "camera_measure": (q, th),
            "transition": (x, u),
            "transition_jacobian": (x, u),
            "noise_gain": (x, u),
            "transition_step": (x, u),
            "transition_inverse": (x, u),
            "plant_step": (x[: 4 * n], u, th, rng.normal(size=2 * n)),
            **estimator_args(fns, x, u, rng),
        }
        # the control laws: every input drawn from its manifest shape (gains positive)
        for fname, sig in lib.manifest.functions.items():
            if fname.startswith("control_"):
                args[fname] = tuple(
                    x
                    if io.name == "x"
                    else th
                    if io.name == "theta"
                    else np.array([0.6])
                    if io.name == "p"
                    else rng.uniform(0.1, 2.0, io.shape[0])
                    for io in sig.inputs
                )
        # rk4 libraries: the step chained in C (amsfe_model.c) against the generated one's VM
        chained = {"transition_step_chain": "transition_step"}
        for fname, target in chained.items():
            if fname in lib.manifest.functions:
                args[fname] = args[target]
        assert set(args) == set(lib.manifest.functions)
        for fname, a in args.items():
            vm = fns[chained.get(fname, fname)](*a)
            vm = vm if isinstance(vm, tuple) else (vm,)
            out = lib.function(fname)(*a)
            for v, c in zip(vm, out, strict=True):
                v = np.array(v).reshape(c.shape, order="F")
                scale = max(1.0, float(np.max(np.abs(v), initial=0.0)))
                assert np.max(np.abs(c - v), initial=0.0) <= 1e-13 * scale, fname


@pytest.mark.parametrize("name", COMPILED)
def test_every_function_against_reference(name: str, libraries) -> None:
    """Jacobians vs central finite differences (<= 1e-6), terms vs Pinocchio (<= 1e-10),
    inverse round trip (<= 1e-9), plant vs numpy RK4 on pin.aba: ``amsfe check``'s table."""
    robot, lib = libraries.get(name)
    results = run_checks(robot, lib, samples=50, seed=1)
    failed = [(r.function, r.max_error, r.tolerance) for r in results if not r.passed]
    assert not failed
    assert {r.function for r in results} >= {
        "mass_matrix",
        "bias",
        "tracked_point",
        "camera",
        "camera_jacobian",
        "transition",
        "transition_jacobian",
        "transition_inverse",
    }


@pytest.mark.parametrize(
    ("rel", "lock"),
    [
        ("ur_description/urdf/ur5_robot.urdf", None),  # 6 revolute
        ("double_pendulum_description/urdf/double_pendulum_continuous.urdf", None),  # continuous
        # 7 revolute + 1 prismatic finger; the other finger mimics it, so it is locked
        ("panda_description/urdf/panda.urdf", {"panda_finger_joint2": 0.02}),
        ("so_arm_description/urdf/so101.urdf", None),  # very light links: default Ks adapts
    ],
    ids=["ur5", "double_pendulum_continuous", "panda_prismatic", "so101"],
)
def test_third_party_urdfs(rel: str, lock: dict[str, float] | None, libraries) -> None:
    """Real third-party URDFs, bare (default spec): generate and pass every check (the model
    part: the control laws are checked on paper_2link and the UR5 in test_control.py).  At
    -O0: no other test compiles these libraries and none times them, the checks' tolerances
    are far above rounding (every shipped robot's library is compiled and checked at -O1),
    and -O0 cuts the four tests from 37 to 10 s of CPU (docs/how-to/tests.md)."""
    robot, lib = libraries.get(erd_urdf(rel), lock=lock, parts=("model",), cflags=("-O0",))
    if lock:
        assert not set(lock) & {j.name for j in robot.joints}
    results = run_checks(robot, lib, samples=20, seed=2)
    assert all(r.passed for r in results), [(r.function, r.max_error) for r in results]
    # the default actuator keeps the discrete model from blowing up (|lambda| of A at rest;
    # gravity can make a configuration open-loop unstable, by a hair per step, never more)
    A = lib.function("transition_jacobian")(np.zeros(lib.N), np.zeros(lib.n))[0]
    assert np.max(np.abs(np.linalg.eigvals(A))) <= 1.01


def test_paper_integrator_inverse_and_jacobian_inverse(libraries) -> None:
    """The backward map's jacobian is the inverse of the forward one (PAPER-NOTES 1)."""
    robot, lib = libraries.get("paper_2link")
    assert lib.manifest.integrator == "paper"
    rng = np.random.default_rng(9)
    tr, jac, inv = (
        lib.function(k) for k in ("transition", "transition_jacobian", "transition_inverse")
    )
    for x in random_states(robot, 10, rng):
        u = rng.uniform(-3, 3, robot.n)
        xn = tr(x, u)[0]
        assert np.max(np.abs(inv(xn, u)[0] - x)) <= 1e-9
        # jacobian of the inverse by finite differences == inverse of the forward jacobian
        h = 1e-6
        Jb = np.stack(
            [(inv(xn + h * e, u)[0] - inv(xn - h * e, u)[0]) / (2 * h) for e in np.eye(xn.size)],
            axis=1,
        )
        A = jac(x, u)[0]
        assert np.max(np.abs(Jb @ A - np.eye(xn.size))) <= 1e-6


#: The model functions only (``generate(parts=MODEL)``): a library without the controller's
#: laws and the estimator's C.
MODEL = ("model",)


def test_cache_reuse_and_invalidation(tmp_path) -> None:
    """Unchanged input is reused without recompiling; a changed spec or flag rebuilds.  (A
    model-only library: the cache's rules are the same for every part, and it builds in a
    fraction of the full one's CPU: test_a_model_only_library_has_no_laws_and_keeps_the_full_one
    shows the full and the partial libraries are cached apart.)"""
    src = tmp_path / "robot"
    src.mkdir()
    urdf = tmp_path / "dp.urdf"
    shutil.copy(erd_urdf("double_pendulum_description/urdf/double_pendulum_simple.urdf"), urdf)
    (src / "robot.toml").write_text(f'name = "dp"\nurdf = "{urdf}"\n[model]\nT = 0.002\n')
    out = tmp_path / "gen"
    first = generate(src, out=out, parts=MODEL)
    assert not first.reused and first.library_path.is_file()
    lib_mtime = first.library_path.stat().st_mtime_ns
    second = generate(src, out=out, parts=MODEL)
    assert second.reused and second.library_path.stat().st_mtime_ns == lib_mtime
    # changed spec -> rebuilt, and the manifest records the new T
    (src / "robot.toml").write_text(f'name = "dp"\nurdf = "{urdf}"\n[model]\nT = 0.003\n')
    third = generate(src, out=out, parts=MODEL)
    assert not third.reused
    assert json.loads(third.manifest_path.read_text())["T"] == 0.003
    # changed compiler flags -> rebuilt
    fourth = generate(src, out=out, extra_cflags=["-DAMSFE_TEST_FLAG=1"], parts=MODEL)
    assert not fourth.reused
    # a corrupted manifest is repaired by rebuilding
    fourth.manifest_path.write_text("{ not json")
    fifth = generate(src, out=out, extra_cflags=["-DAMSFE_TEST_FLAG=1"], parts=MODEL)
    assert not fifth.reused and json.loads(fifth.manifest_path.read_text())["T"] == 0.003
    # no temporary folders left: the library and the object cache, which holds objects only
    # (codegen/compile_units; tests/test_compile_units.py tests that cache)
    assert sorted(p.name for p in out.iterdir()) == [".objects", "dp-model"]
    assert {p.suffix for p in (out / ".objects").iterdir()} == {".o"}


def test_a_model_only_library_has_no_laws_and_keeps_the_full_one(tmp_path, libraries) -> None:
    # the full library: a copy of the session's build (the cache takes it as its own)
    shutil.copytree(libraries.get("paper_2link")[1].dir, tmp_path / "paper_2link")
    full = generate("paper_2link", out=tmp_path)
    assert full.reused
    part = generate("paper_2link", out=tmp_path, parts=("model",))
    assert part.out_dir.name == "paper_2link-model" and not part.reused
    names = set(json.loads(part.manifest_path.read_text())["functions"])
    assert "transition_inverse" in names
    assert not any(n.startswith(("control_", "est_")) for n in names)
    assert generate("paper_2link", out=tmp_path).reused  # the full library was not evicted
    assert full.out_dir.name == "paper_2link"


@pytest.mark.parametrize("substeps", [1, 3])
def test_chained_rk4_step_equals_the_generated_one(tmp_path, substeps: int) -> None:
    """The rk4 step chained in C over the generated stage (runtime/c/amsfe_model.c) against
    the generated transition_step (CasADi VM) at random states, and ``amsfe check``'s rows
    (the transition against numpy RK4 on pin.aba with the same steps, A and Gamma against
    central differences), on a 4-joint arm-like chain (the chain is used beyond
    EXPAND_MAX_JOINTS joints), with one RK4 step per T and with ``model_substeps = 3``."""
    from amsfe_sym.apps.bench.scaling import chain_urdf
    from amsfe_sym.apps.check import run_checks
    from amsfe_sym.codegen import generate
    from amsfe_sym.load import load_robot
    from amsfe_sym.load.spec import load_spec
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.symbolic.transition import EXPAND_MAX_JOINTS

    n = EXPAND_MAX_JOINTS + 2
    (tmp_path / "chain.urdf").write_text(chain_urdf(n))
    (tmp_path / "robot.toml").write_text(
        f'urdf = "chain.urdf"\n[model]\nintegrator = "rk4"\nmodel_substeps = {substeps}\n'
        "[[theta]]\nname = 'payload'\nkind = 'payload_mass'\ntarget = 'l4'\ntrue = 0.5\n"
        "initial = 0.3\n"
    )
    spec = load_spec(tmp_path / "robot.toml")
    lib = ModelLibrary(generate(spec, out=tmp_path / "gen", parts=("model",)).out_dir)
    assert "transition_step_chain" in lib.manifest.functions
    robot = load_robot(spec)
    vm = build_functions(robot, ("model",)).functions["transition_step"]
    chain = lib.function("transition_step_chain")
    rng = np.random.default_rng(3)
    for x in random_states(robot, 10, rng):
        u = rng.uniform(-3, 3, robot.n)
        for c, v in zip(chain(x, u), vm(x, u), strict=True):
            v = np.array(v).reshape(c.shape, order="F")
            assert np.max(np.abs(c - v)) <= 1e-12 * max(1.0, float(np.max(np.abs(v))))
    assert lib.manifest.model_substeps == substeps
    if substeps == 1:
        _dynamics_jacobian_equals_pinocchio(robot, lib, rng)
    rows = {r.function: r for r in run_checks(robot, lib, samples=5, seed=1)}
    for name in ("transition_step_chain", "transition", "transition_jacobian", "noise_gain"):
        assert rows[name].passed, rows[name]


def _dynamics_jacobian_equals_pinocchio(robot, lib, rng) -> None:
    """``forward_dynamics_jacobian`` (the chained libraries' dynamics and its jacobian, what
    ``amsfe bench`` times next to Pinocchio) against ``pin.computeABADerivatives`` with the
    spring torque as tau (1e-10), and its theta column against central differences of qdd."""
    import pinocchio as pin

    n, N = robot.n, lib.N
    f = lib.function("forward_dynamics_jacobian")
    Ks = np.asarray(robot.Ks, float)
    for x in random_states(robot, 5, rng):
        th = x[4 * n :]
        q, qd, qm = x[:n], x[n : 2 * n], x[2 * n : 3 * n]
        qdd, J = f(x[: 4 * n], th)
        model = robot.pin_model_at(th)
        data = model.createData()
        tau = Ks * (qm - q)
        pin.computeABADerivatives(model, data, q, qd, tau)
        Minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
        scale = max(1.0, float(np.max(np.abs(data.ddq_dq))))
        np.testing.assert_allclose(
            qdd, data.ddq, rtol=0, atol=1e-10 * max(1.0, np.abs(data.ddq).max())
        )
        np.testing.assert_allclose(J[:, :n], data.ddq_dq - Minv * Ks, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(J[:, n : 2 * n], data.ddq_dv, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(J[:, 2 * n : 3 * n], Minv * Ks, rtol=0, atol=1e-10 * scale)
        assert np.all(J[:, 3 * n : 4 * n] == 0)
        for t in range(N - 4 * n):  # theta: central differences of qdd
            e = np.zeros(N - 4 * n)
            e[t] = 1e-6
            fd = (f(x[: 4 * n], th + e)[0] - f(x[: 4 * n], th - e)[0]) / 2e-6
            np.testing.assert_allclose(J[:, 4 * n + t], fd, rtol=1e-6, atol=1e-6)
