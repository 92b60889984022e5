"""The public Python API (amsfe_sym.api, docs/api.md) on the paper's 2-link robot: each
function against the path the commands take (``amsfe estimate``'s estimates read back from
its run folder, ``sim.loop.run``'s run, ``--set``'s scenario), at tight tolerance."""

from __future__ import annotations

import inspect
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import amsfe_sym as am
from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError, ShapeError
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.scenario import apply_sets
from amsfe_sym.scenario import load_scenario as load_internal
from amsfe_sym.sim.loop import run
from tests.test_log_reader import arm_events, write_log

ROOT = Path(__file__).resolve().parents[1]


def test_importing_the_package_builds_nothing_and_names_the_api() -> None:
    """``import amsfe_sym`` imports neither CasADi, Pinocchio nor the API's modules; every
    public name resolves on first use, still without CasADi or Pinocchio."""
    code = (
        "import sys, amsfe_sym as am\n"
        "before = sorted(m for m in ('casadi', 'pinocchio', 'amsfe_sym.api') if m in sys.modules)\n"
        "names = [getattr(am, n) for n in am.__all__]\n"
        "after = sorted(m for m in ('casadi', 'pinocchio', 'rclpy') if m in sys.modules)\n"
        "print(before, after)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == "[] []"
    for name in ("simulate", "Estimator", "LogArrays", "read_log", "load_scenario"):
        assert name in am.__all__ and name in dir(am)
    with pytest.raises(AttributeError):
        am.no_such_name  # noqa: B018


def test_load_scenario_overrides_are_the_command_lines_set() -> None:
    """A mapping of overrides gives the scenario ``--set`` gives (numbers, lists, words,
    booleans), plus ``seed`` and ``estimator``; a bad key is one ConfigError line."""
    over = {
        "duration": 2.5,
        "filter.link_torque_std": 0.3,
        "plant.q0": [0.1, -0.2],
        "integrator": "rk4",
        "camera.round_to_pixel": False,
        "seed": 7,
        "estimator": "replay",
    }
    got = am.load_scenario("paper-sim", over)
    sets = [
        "duration=2.5",
        "filter.link_torque_std=0.3",
        "plant.q0=0.1,-0.2",
        "integrator=rk4",
        "camera.round_to_pixel=false",
    ]
    ref = apply_sets(load_internal("paper-sim"), sets).with_overrides(seed=7, estimator="replay")
    assert got.to_dict() == ref.to_dict()
    assert am.load_scenario().to_dict() == load_internal("paper-sim").to_dict()
    with pytest.raises(ConfigError) as exc:
        am.load_scenario("paper-sim", {"filter.no_such_key": 1})
    assert "\n" not in str(exc.value) and "no_such_key" in str(exc.value)
    with pytest.raises(ConfigError):
        am.load_scenario("paper-sim", {"seed": -1})


def test_generate_reports_the_library() -> None:
    robot = am.generate("paper_2link")
    assert isinstance(robot, am.Robot)
    assert robot.library_path.is_file() and robot.manifest_path.is_file()
    assert robot.seconds >= 0.0


def test_simulate_is_the_loops_run_and_its_nis_the_estimators() -> None:
    """``simulate`` returns the closed loop's own arrays (bit for bit ``sim.loop.run`` of
    the same scenario); its NIS per tick is the same on the compiled and the Python
    runtime (two implementations of the estimator) and averages near its 2 n degrees of
    freedom."""
    sim = am.simulate("paper-sim", duration=1.0, seed=3)
    sc = load_internal("paper-sim").with_overrides(controller="amsfe", seed=3, duration=1.0)
    ref = run(sc, library_for(sc), runtime="compiled")
    for name in ("t", "x_true", "x_hat", "P_diag", "u", "q_des", "nees"):
        np.testing.assert_array_equal(getattr(sim, name), getattr(ref, name), err_msg=name)
    K, n = sim.t.size, len(sim.joints)
    assert sim.x_hat.shape == (K, sim.run.lib.N) and sim.u.shape == (K, n)
    np.testing.assert_array_equal(sim.q_hat, sim.x_hat[:, :n])
    assert np.isnan(sim.nis[0]) and np.isfinite(sim.nis[1:]).all()
    assert 0.5 * 2 * n < float(np.mean(sim.nis[1:])) < 2.0 * 2 * n
    py = am.simulate("paper-sim", duration=1.0, seed=3, runtime="python")
    # (the two runtimes agree to ~1e-7 relative over a run: docs/how-to/runtime-c.md)
    np.testing.assert_allclose(py.x_hat, sim.x_hat, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(py.nis[1:], sim.nis[1:], rtol=1e-5, atol=1e-8)
    with pytest.raises(ConfigError):
        am.simulate("paper-sim", runtime="fortran")


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 1 s paper-sim run as amsfe writes it (``/amsfe/config``, applied torque), and the
    same run as a driver writes it (one ``/joint_states`` with fingers, clock offset,
    jitter; its effort a measured one, kind ``none``)."""
    root = tmp_path_factory.mktemp("api")
    sc = load_internal("paper-sim").with_overrides(controller="amsfe", duration=1.0, seed=5)
    res = run(sc, library_for(sc), runtime="compiled")
    bag = write_run_bag(res, root / "amsfe")
    ev, _ = arm_events(res)
    driver = write_log(root / "driver.bag", ev, "bag")
    return bag, driver


def _cli_estimates(log: Path, out: Path, *args: str) -> np.ndarray:
    code = main(["estimate", str(log), *args, "--out", str(out), "--no-plots"])
    assert code == 0
    table = pd.read_parquet(out / "estimates.parquet")
    cols = sorted((c for c in table.columns if c.startswith("est_")), key=lambda c: int(c[4:]))
    return table[cols].to_numpy()


def test_model_is_the_librarys_transition_and_camera() -> None:
    """``Model`` on paper-sim: step is the generated ``transition`` (the contract's function,
    not the one Model calls), its jacobian and the camera's are central differences of step
    and of the pixel, Qd is Gamma Qw Gamma^T with the scenario's noise; a wrong shape is one
    ShapeError line."""
    model = am.Model.for_scenario("paper-sim", {"filter.link_torque_std": 0.7})
    lib = library_for(model.scenario)
    assert (model.n, model.p, model.N) == (lib.n, lib.p, lib.N) and model.T == lib.T
    assert model.joints == tuple(lib.manifest.joints)
    rng = np.random.default_rng(5)
    tr, gain = lib.function("transition"), lib.function("noise_gain")
    h = 1e-6
    for _ in range(5):
        x = np.concatenate([rng.uniform(-1, 1, 4 * model.n), model.theta_true])
        u = rng.uniform(-3, 3, model.n)
        xn = model.step(x, u)
        assert np.max(np.abs(xn - tr(x, u)[0])) <= 1e-12 * max(1.0, float(np.max(np.abs(xn))))
        fd = np.stack(
            [
                (model.step(x + h * e, u) - model.step(x - h * e, u)) / (2 * h)
                for e in np.eye(x.size)
            ],
            axis=1,
        )
        assert np.max(np.abs(model.jacobian(x, u) - fd)) <= 1e-6 * max(
            1.0, float(np.max(np.abs(fd)))
        )
        G = gain(x, u)[0]
        T, n = model.T, model.n
        Qw = np.diag(
            [(0.7 * T) ** 2] * n
            + [(model.scenario.filter.motor_torque_std * T) ** 2] * n
            + [model.scenario.filter.theta_rate_std**2] * model.p
        )
        assert np.allclose(model.process_noise(x, u), G @ Qw @ G.T, rtol=1e-12, atol=1e-30)
        q = x[model.layout["q"]]
        y, J = model.camera(q)
        assert y.shape == (2,) and J.shape == (2, n)
        fdc = np.stack(
            [
                (model.camera(q + h * e)[0] - model.camera(q - h * e)[0]) / (2 * h)
                for e in np.eye(n)
            ],
            axis=1,
        )
        assert np.max(np.abs(J - fdc)) <= 1e-5 * max(1.0, float(np.max(np.abs(fdc))))
    with pytest.raises(ShapeError, match="x"):
        model.step(np.zeros(model.N + 1), np.zeros(model.n))
    with pytest.raises(ShapeError, match="q"):
        model.camera(np.zeros(model.n + 1))


@pytest.mark.parametrize("which", ["amsfe", "driver"])
def test_run_on_a_read_log_is_amsfe_estimate(
    which: str, recording: tuple[Path, Path], tmp_path: Path
) -> None:
    """``Estimator.for_log(robot).run(read_log(LOG, robot))`` is ``amsfe estimate LOG
    --robot ROBOT`` to 1e-12, on amsfe's own bag (the applied torque: oosm) and on a
    driver's (effort kind none: replay, the input as states)."""
    log_path = recording[0] if which == "amsfe" else recording[1]
    log = am.read_log(log_path, "paper_2link")
    assert log.effort_kind == ("applied" if which == "amsfe" else "none")
    got = am.Estimator.for_log("paper_2link").run(log)
    ref = _cli_estimates(log_path, tmp_path / "cli", "--robot", "paper_2link")
    assert got.x_hat.shape == ref.shape
    assert np.max(np.abs(got.x_hat - ref)) <= 1e-12
    assert got.counters["frames_applied"] > 0
    assert np.isnan(got.nis[0]) and np.isfinite(got.nis[1:]).all()


def test_run_for_a_scenario_is_amsfe_estimate_with_it(
    recording: tuple[Path, Path], tmp_path: Path
) -> None:
    """``Estimator.for_scenario(sc, kind)`` is ``amsfe estimate LOG --scenario FILE
    --estimator KIND``; and the same recording rebuilt with ``LogArrays.from_arrays`` from
    the read log's own arrays gives the same estimates."""
    log_path = recording[0]
    log = am.read_log(log_path, "paper_2link")
    est = am.Estimator.for_scenario("paper-sim", kind="replay")
    got = est.run(log)
    ref = _cli_estimates(
        log_path, tmp_path / "cli", "--scenario", "paper-sim", "--estimator", "replay"
    )
    assert np.max(np.abs(got.x_hat - ref)) <= 1e-12
    arrays = am.LogArrays.from_arrays(
        log.t,
        log.q_motor,
        log.effort,
        log.camera_t,
        log.camera_uv,
        qd_motor=log.qd_motor,
        camera_arrival_t=log.camera_arrival_t,
        truth=log.truth,
    )
    again = am.Estimator.for_scenario("paper-sim", kind="replay").run(arrays)
    assert np.max(np.abs(again.x_hat - got.x_hat)) <= 1e-12
    assert again.nees is not None and np.isfinite(again.nees).all()


def test_for_scenario_on_a_simulations_arrays_is_the_simulations_estimator() -> None:
    """A simulated run's sensors given as arrays (``LogArrays.from_arrays``) to its own
    scenario's estimator give the run's estimates and covariances bit for bit: the arrays
    are placed on the grid, the frames at their exposure and arrival ticks, as the loop
    had them."""
    sim = am.simulate("paper-sim", duration=1.0, seed=2)
    n, T, z = len(sim.joints), sim.T, sim.run.z_enc
    log = am.LogArrays.from_arrays(
        sim.t,
        z[:, :n],
        sim.u,
        sim.frames[:, 0] * T,
        sim.frames[:, 2:4],
        qd_motor=z[:, n:],
        camera_arrival_t=sim.frames[:, 1] * T,
        truth=sim.x_true,
    )
    est = am.Estimator.for_scenario(sim.run.scenario, kind="oosm").run(log)
    np.testing.assert_array_equal(est.x_hat, sim.x_hat)
    np.testing.assert_array_equal(est.P_diag, sim.P_diag)
    np.testing.assert_array_equal(est.nis, sim.nis)
    assert est.nees is not None
    np.testing.assert_allclose(est.nees, sim.nees, rtol=1e-9)


def test_step_is_run_sample_by_sample(recording: tuple[Path, Path]) -> None:
    """The live step API (each sample, each frame as it arrives) gives the estimates of
    the batch run over the same recording, tick by tick, to 1e-9; a sample of the wrong
    size is one ShapeError line."""
    log = am.read_log(recording[0], "paper_2link")
    batch = am.Estimator.for_scenario("paper-sim").run(log)
    live = am.Estimator.for_scenario("paper-sim")
    by_arrival: dict[int, list[int]] = {}
    for i, ta in enumerate(log.camera_arrival_t):
        by_arrival.setdefault(round(ta / log.T), []).append(i)
    applied = 0
    for k, t in enumerate(log.t):
        for i in by_arrival.get(k, []):
            live.camera(log.camera_t[i], log.camera_uv[i])
        eff = None if log.effort is None else log.effort[k]
        out = live.step(t, log.q_motor[k], eff, qd_motor=log.qd_motor[k])
        assert out is not None and out.k == k
        applied += out.frames_applied
        assert np.max(np.abs(out.x_hat - batch.x_hat[k])) <= 1e-9, k
    assert applied == batch.counters["frames_applied"] > 0
    with pytest.raises(ShapeError):
        live.step(log.t[-1] + log.T, np.zeros(3))


def test_from_arrays_refuses_what_it_cannot_place() -> None:
    t = np.arange(10) * 1e-3
    q = np.zeros((10, 2))
    with pytest.raises(ShapeError) as exc:
        am.LogArrays.from_arrays(t, np.zeros((9, 2)))
    assert "\n" not in str(exc.value)
    with pytest.raises(ConfigError):
        am.LogArrays.from_arrays(t[::-1], q)
    jitter = t.copy()
    jitter[4] += 0.4e-3
    with pytest.raises(ConfigError) as exc:
        am.LogArrays.from_arrays(jitter, q, T=1e-3)
    assert "t[4]" in str(exc.value)
    with pytest.raises(ConfigError):
        am.LogArrays.from_arrays(t, q, effort_kind="torque")
    gap = np.delete(t, [3, 4])
    log = am.LogArrays.from_arrays(gap, np.ones((8, 2)), np.ones((8, 2)), T=1e-3)
    assert log.q_motor.shape == (10, 2) and np.isnan(log.q_motor[3:5]).all()
    assert log.effort is not None and np.all(log.effort == 1.0)  # held over the gap


@pytest.mark.slow
def test_the_notebook_example_runs() -> None:
    """examples/estimate_arrays.py (a jupytext percent script) runs as a script: it
    estimates a recording held as numpy arrays and checks its own result."""
    path = ROOT / "examples" / "estimate_arrays.py"
    assert path.read_text().startswith("# %% [markdown]")
    ns = runpy.run_path(str(path), run_name="__main__")
    assert ns["rmse_q"].shape == (2,) and np.all(ns["rmse_q"] < 5e-3)


def test_libraries_go_to_the_current_directory_by_default(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``$AMSFE_GENERATED_DIR`` when set, else ``generated/`` in the current directory (as
    ``runs/``), never the checkout the package was installed from."""
    from amsfe_sym.codegen import default_out_dir

    monkeypatch.delenv("AMSFE_GENERATED_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    assert default_out_dir() == tmp_path / "generated"
    monkeypatch.setenv("AMSFE_GENERATED_DIR", str(tmp_path / "elsewhere"))
    assert default_out_dir() == tmp_path / "elsewhere"


def test_generate_names_each_lowered_default_stiffness() -> None:
    """A bare URDF's default Ks lowered for a light joint is one line naming the joint, the
    two values and why; a spec that gives Ks says nothing."""
    from dataclasses import replace

    from amsfe_sym.codegen.build import lowered_stiffness
    from amsfe_sym.load.spec import load_spec

    spec = load_spec("paper_2link")
    assert lowered_stiffness(spec, [10.0, 10.0], ["a", "b"]) == []
    bare = replace(spec, actuators=replace(spec.actuators, Ks=None))
    lines = lowered_stiffness(bare, [1000.0, 130.9], ["shoulder", "wrist_3_joint"])
    assert len(lines) == 1
    assert "wrist_3_joint" in lines[0] and "1000 to 130.9 N m/rad" in lines[0]
    assert "w T <= 0.5" in lines[0] and "[actuators] Ks" in lines[0]


def test_check_tolerance_of_a_chain_grows_with_what_it_chains() -> None:
    """``transition_step_chain``'s tolerance is 64 m kappa(M) eps (at least the former
    1e-13): the UR10 of a bare URDF with model_substeps = 7 (kappa of its M in the
    thousands) passes its 1.31e-13."""
    from amsfe_sym.apps.check import chain_tolerance

    eps = float(np.finfo(float).eps)
    assert chain_tolerance(1, 1.0) == 1e-13
    assert chain_tolerance(7, 1e3) == pytest.approx(64 * 7 * 1e3 * eps)
    assert chain_tolerance(7, 1e3) > 1.31e-13
    assert chain_tolerance(14, 1e3) == pytest.approx(2 * chain_tolerance(7, 1e3))


@pytest.mark.slow
def test_a_build_says_so_and_names_the_lowered_stiffness(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bare URDF built with progress (what ``amsfe simulate`` and ``generate`` show): the
    first line says the library is not cached and is being generated, then one line per
    joint whose default stiffness was lowered (the UR10's wrist 3, from 1000 to ~131
    N m/rad), before the compiler runs; a second call reuses it silently."""
    from tests.conftest import erd_urdf

    urdf = erd_urdf("ur_description/urdf/ur10_robot.urdf")
    out = tmp_path / "gen"
    res = am.generate(urdf, out=out, parts=("model",), progress=True)
    err = capsys.readouterr().err.splitlines()
    assert not res.reused
    assert "no library in the cache" in err[0] and "generating it" in err[0]
    lowered = [ln for ln in err if "default stiffness Ks lowered" in ln]
    assert len(lowered) == 1 and "wrist_3_joint" in lowered[0]
    compiling = next(i for i, ln in enumerate(err) if "compiling" in ln)
    assert err.index(lowered[0]) < compiling
    again = am.generate(urdf, out=out, parts=("model",))
    assert again.reused and capsys.readouterr().err == ""


def test_the_api_page_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/api.md's Python blocks, run in order in one namespace (as a reader would paste
    them into one session), import nothing but the public API."""
    import re

    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 5
    for code in blocks:
        for line in code.splitlines():
            if line.startswith(("import amsfe_sym", "from amsfe_sym")):
                assert line.strip() == "import amsfe_sym as am", line
    monkeypatch.chdir(tmp_path)
    ns: dict[str, object] = {}
    for code in blocks:
        exec(compile(code, "docs/api.md", "exec"), ns)
    assert list(tmp_path.iterdir()) == []  # the API wrote nothing here (a temporary bag)


def test_the_package_root_names_the_api_and_nothing_else() -> None:
    """The root's ``__all__`` (written out, so that importing the package imports nothing)
    is every public name :mod:`amsfe_sym.api` imports (``X as X``, its only list) plus the
    error base, the version and the two library loaders."""
    from amsfe_sym import api

    public = {n for n, v in vars(api).items() if not n.startswith("_") and not inspect.ismodule(v)}
    extra = {"AmsfeError", "__version__", "library_for", "load_library"}
    assert sorted(am.__all__) == sorted(public | extra)
    assert len(am.__all__) == len(set(am.__all__))
