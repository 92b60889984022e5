"""The C estimators on logs without the applied torque (issue 26; docs/explanation/effort.md,
"Compiled").

The input carried as states and the joint torque sensors' measurement are computed by the C
runtime (``runtime/c/amsfe_est_tick.c``) and compared here with the Python reference
(``estimation/effort_models.py`` wrapped around the same compiled robot functions): tick by
tick and through the batch call (``amsfe_est_run``), on a simulated paper_2link run whose
joint stiffnesses are theta parameters (the bilinear torque jacobian).

Tolerances: both sides evaluate the same formulas in another order (BLAS and LAPACK against
the runtime's kernels, which use FMA on an AVX2 CPU), so a tick differs by rounding, ~1e-16
relative, which the filter carries over the run.  Measured over these 0.5 s runs (the 20
cases of CASES, every tick): x differs by at most 8e-13 of its largest entry, P by 3e-12 of
its largest entry (cloning; 9e-13 for the others), an encoder NIS by 4e-11 of itself.  The
tests allow 1e-11 on x and P and 1e-9 on NIS values (a NIS divides by small innovation variances).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.estimation.effort import EffortSpec

#: (effort kind, input model) pairs the C estimators compute.
KINDS = [
    ("joint_torque", "state"),
    ("none", "state"),
    ("joint_torque", "reconstruct"),
    ("none", "reconstruct"),
]
#: The estimators the C runtime serves for them: all five.
ESTIMATORS = ["encoders", "naive", "oosm", "replay", "cloning"]
CASES = [(k, m, e) for k, m in KINDS for e in ESTIMATORS]
#: Relative tolerance of x and P (module docstring), and of the NIS values.
RTOL, RTOL_NIS = 1e-11, 1e-9


@pytest.fixture(scope="module")
def paper(libraries):  # type: ignore[no-untyped-def]
    """paper-sim's library (compiled once per session) and a 0.5 s closed-loop run."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    libraries.get("paper_2link")
    sc = load_scenario("paper-sim").with_overrides(duration=0.5, seed=12)
    lib = library_for(sc)
    return sc, lib, run(sc, lib, runtime="compiled")


def _pair(
    paper: Any, kind: str, input_model: str, estimator: str, holes: bool = False
) -> tuple[Any, Any, Any]:
    """The Python and the C estimator of one log, its effort, and the frames by delivery;
    ``holes``: encoder gaps (NaN rows) and torque samples lost (NaN) in the log."""
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.effort import effort_estimator, frames_by_delivery, simulated_effort

    sc, lib, res = paper
    sc = sc.with_overrides(estimator=estimator)
    sensors = build_run(sc, lib).sensors
    effort = simulated_effort(res, kind, np.random.default_rng(3), 0.05)
    z = res.z_enc.copy()
    if holes:
        z[[50, 51, 52, 300]] = np.nan
        if effort is not None:
            effort[[120, 126, 400]] = np.nan
    spec = EffortSpec(kind, input_model=input_model)
    py = effort_estimator(sc, lib, sensors, z, effort, spec)
    c = effort_estimator(sc, lib, sensors, z, effort, spec, compiled=True)
    return py, c, frames_by_delivery(res.frames, len(res.t))


def _close(name: str, got: np.ndarray, ref: np.ndarray, rtol: float) -> float:
    """The largest difference relative to ref's largest entry; fails above rtol."""
    scale = max(float(np.max(np.abs(ref))), 1e-300)
    err = float(np.max(np.abs(got - ref))) / scale
    assert err <= rtol, f"{name}: {err:.3g} of its largest entry (> {rtol:g})"
    return err


def _tick_by_tick(py: Any, c: Any, frames: list[list[Any]], estimator: str) -> None:
    """Step both over the log: x, P, the encoder NIS and every frame's decision and NIS."""
    inputs = py.inputs
    reached = refused = 0
    for k in range(1, inputs.z_encoder.shape[0]):
        z = inputs.z_encoder[k]
        zk = z if np.isfinite(z).all() else None
        rp = py.estimator.step(inputs.u[k - 1], zk, frames[k])
        rc = c.estimator.step(inputs.u[k - 1], zk, frames[k])
        _close(f"x at {k}", c.estimator.x, py.estimator.x, RTOL)
        _close(f"P at {k}", c.estimator.P, py.estimator.P, RTOL)
        assert (rc.encoder_nis is None) == (rp.encoder_nis is None)
        if rp.encoder_nis is not None:
            assert rc.encoder_nis == pytest.approx(rp.encoder_nis, rel=RTOL_NIS)
        assert rc.encoder_accepted == rp.encoder_accepted
        assert rc.used == rp.used and rc.frames_applied == rp.frames_applied
        assert rc.frames_rejected == rp.frames_rejected
        assert [r.split(":")[0] for r in rc.rejections] == [r.split(":")[0] for r in rp.rejections]
        np.testing.assert_allclose(rc.frame_nis, rp.frame_nis, rtol=RTOL_NIS)
        reached += len(rp.frame_nis)
        refused += rp.frames_rejected
    if estimator in ("naive", "replay", "cloning"):
        assert reached > 0  # the camera update was computed
    if estimator == "oosm":
        assert refused + reached > 0  # A1: its decision (docs/explanation/effort.md)


@pytest.mark.parametrize(("kind", "input_model", "estimator"), CASES)
def test_c_matches_python_tick_by_tick(
    paper: Any, kind: str, input_model: str, estimator: str
) -> None:
    """x, P, the encoder NIS and every frame's decision and NIS of each tick equal."""
    py, c, frames = _pair(paper, kind, input_model, estimator)
    lib = paper[1]
    assert c.estimator.nx == py.estimator.nx == lib.N + (lib.n if input_model == "state" else 0)
    _tick_by_tick(py, c, frames, estimator)


@pytest.mark.parametrize("estimator", ["oosm", "replay"])
def test_a_stiffness_parameter_enters_the_torque_jacobian(
    paper: Any, estimator: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With a joint's stiffness a theta parameter, ``tau_J = theta_i (qm_j - q_j)`` is bilinear
    and its jacobian has the column ``d/dtheta_i = qm_j - q_j``.  No robot the suite compiles
    has such a parameter, so the torque sensors' model is told that paper_2link's theta (the
    payload) is joint 1's stiffness: a model of the sensor only, the same on both sides (the
    transition keeps the payload); the C and the Python estimator agree tick by tick."""
    import amsfe_sym.sim.builders as builders
    import amsfe_sym.sim.effort as sim_effort

    real = builders.motor_params

    def with_theta(lib: Any) -> Any:
        return dataclasses.replace(real(lib), stiffness_theta=np.array([0, -1], np.int32))

    monkeypatch.setattr(builders, "motor_params", with_theta)
    monkeypatch.setattr(sim_effort, "motor_params", with_theta)
    py, c, frames = _pair(paper, "joint_torque", "state", estimator)
    assert c.estimator.effort.ks_theta.tolist() == [0, -1]
    theta0 = float(py.estimator.x[paper[1].N - 1])
    _tick_by_tick(py, c, frames, estimator)
    assert abs(float(py.estimator.x[paper[1].N - 1]) - theta0) > 1.0  # the sensor moved it


@pytest.mark.parametrize("estimator", ["oosm", "replay"])
@pytest.mark.parametrize("kind", ["joint_torque", "none"])
def test_gaps_and_lost_torques_match(paper: Any, kind: str, estimator: str) -> None:
    """Encoder gaps and lost torque samples (a ``[qm, qmd, tau_J]`` row holding NaN is
    dropped whole, docs/explanation/effort.md section 6): the same steps, tick by tick and in the
    batch."""
    py, c, frames = _pair(paper, kind, "state", estimator, holes=True)
    missing = ~np.isfinite(py.inputs.z_encoder).all(axis=1)
    assert missing.sum() == (7 if kind == "joint_torque" else 4)
    _tick_by_tick(py, c, frames, estimator)
    _, c2, _ = _pair(paper, kind, "state", estimator, holes=True)
    res, _ = _batch(c2, frames)
    N = py.N
    _close("x_hat[-1]", res.x_hat[-1], py.estimator.x[:N], RTOL)
    assert np.isnan(res.encoder_nis[missing]).all()


def _batch(c: Any, frames: list[list[Any]], **kw: Any) -> tuple[Any, Any]:
    """``run_log`` (the C batch) over the pair's C side, its frames in delivery order (by
    delivery tick, then exposure); and those frame rows (exposure, delivery, u, v)."""
    from amsfe_sym.runtime.estimator_batch import run_log

    rows = [(fr.exposure_step, k, *fr.z) for k in range(len(frames)) for fr in frames[k]]
    rows.sort(key=lambda r: (r[1], r[0]))
    fr = np.array(rows, dtype=float).reshape(-1, 4)
    ticks = fr[:, :2].astype(np.int64)
    res = run_log(
        c.estimator, c.inputs.u, c.inputs.z_encoder, ticks[:, 0], ticks[:, 1], fr[:, 2:], **kw
    )
    return res, fr


def _decisions(py: Any, frames: list[list[Any]]) -> tuple[Any, ...]:
    """The Python reference over the log: x, diag P, encoder NIS per tick, and each frame's
    status code (``STATUS``) in the batch's frame order."""
    from amsfe_sym.runtime.compiled_estimator import STATUS

    est, inputs = py.estimator, py.inputs
    K, N = inputs.z_encoder.shape[0], py.N
    x, Pd, nis = np.zeros((K, N)), np.zeros((K, N)), np.full(K, np.nan)
    status: list[int] = []
    x[0], Pd[0] = est.x[:N], np.diag(est.P)[:N]
    for k in range(1, K):
        rep = est.step(inputs.u[k - 1], inputs.z_encoder[k], frames[k])
        nis[k] = np.nan if rep.encoder_nis is None else rep.encoder_nis
        for fr in sorted(frames[k], key=lambda f: f.exposure_step):
            kappa = fr.exposure_step
            if kappa in rep.used:
                gated = any(
                    r.startswith(f"camera frame kappa={kappa} gated") for r in rep.rejections
                )
                status.append(STATUS["gated" if gated else "ok"])
            elif any("indefinite" in r for r in rep.rejections):
                status.append(STATUS["refused_indefinite"])
            else:
                status.append(STATUS["ignored"])
        x[k], Pd[k] = est.x[:N], np.diag(est.P)[:N]
    return x, Pd, nis, np.array(status, np.int32)


@pytest.mark.parametrize(("kind", "input_model", "estimator"), CASES)
def test_the_batch_call_matches_python(
    paper: Any, kind: str, input_model: str, estimator: str
) -> None:
    """``run_log`` (one C call per chunk of ticks) gives the reference's x, diag P, encoder NIS
    and frame statuses; the robot's N states, the input states apart."""
    py, c, frames = _pair(paper, kind, input_model, estimator)
    x, Pd, nis, status = _decisions(py, frames)
    res, fr = _batch(c, frames, chunk=97)
    assert res.x_hat.shape == x.shape
    assert (res.input_hat is None) == (input_model != "state")
    _close("x_hat", res.x_hat, x, RTOL)
    _close("diag P", res.P_diag, Pd, RTOL)
    np.testing.assert_array_equal(np.isnan(res.encoder_nis), np.isnan(nis))
    np.testing.assert_allclose(res.encoder_nis, nis, rtol=RTOL_NIS)
    delivered = fr[:, 1] > 0  # frames arriving at tick 0 are not used
    np.testing.assert_array_equal(res.frame_status[delivered], status)


@pytest.mark.parametrize(
    ("kind", "input_model"), [("joint_torque", "state"), ("none", "state"), ("none", "reconstruct")]
)
def test_oosms_inverse_map_is_refused_in_one_line(paper: Any, kind: str, input_model: str) -> None:
    """oosm's inverse backward map with input states or a net torque input (the wrapped
    transition's inverse is Python's Newton iteration): one ConfigError line naming what
    works; the other estimators with the same [filter] are built."""
    from amsfe_sym.sim.builders import build_estimator, build_run

    sc, lib, _ = paper
    spec = EffortSpec(kind, input_model=input_model)
    for estimator in ("oosm", "replay"):
        sc_e = sc.with_overrides(estimator=estimator)
        f = dataclasses.replace(sc_e.filter, backward_map="inverse")
        sc_e = dataclasses.replace(sc_e, filter=f)
        parts = build_run(sc_e, lib)
        if estimator == "replay":  # backward_map is oosm's alone
            build_estimator(sc_e, lib, parts.sensors, parts.z0, compiled=True, effort=spec)
            continue
        with pytest.raises(ConfigError, match="replay") as info:
            build_estimator(sc_e, lib, parts.sensors, parts.z0, compiled=True, effort=spec)
        assert "\n" not in str(info.value)
        build_estimator(sc_e, lib, parts.sensors, parts.z0, effort=spec)  # the Python one


@pytest.mark.parametrize(("kind", "input_model"), KINDS)
def test_a_c_log_refuses_an_estimator_without_the_applied_torque(
    paper: Any, kind: str, input_model: str
) -> None:
    """The C log format (examples/estimate_from_log.c) has no effort fields: logging an
    estimator with input states, a joint torque or a net torque input is one ConfigError
    line (the check the C node makes too); the same estimator of the applied torque logs."""
    from amsfe_sym.runtime.compiled_estimator import estimator_log_lines
    from amsfe_sym.sim.builders import build_estimator, build_run

    sc, lib, _ = paper
    parts = build_run(sc, lib)
    spec = EffortSpec(kind, input_model=input_model)
    c = build_estimator(sc, lib, parts.sensors, parts.z0, compiled=True, effort=spec)
    with pytest.raises(ConfigError, match="an estimator of the applied torque") as info:
        estimator_log_lines(c)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)
    applied = build_estimator(sc, lib, parts.sensors, parts.z0, compiled=True)
    assert estimator_log_lines(applied)[0].startswith("params ")  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["joint_torque", "none"])
def test_amsfe_estimate_runs_such_a_log_in_c(
    paper: Any, kind: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``amsfe estimate LOG --robot paper_2link`` with the effort kind in the log spec: the
    default runtime runs the log through the C batch call, with the Python reference's
    estimates."""
    import amsfe_sym.runtime.estimator_batch as batch
    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command
    from tests.test_log_effort import _log

    calls = []
    real = batch.run_log

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(batch, "run_log", counted)
    res = paper[2]
    spec = tmp_path / "spec.toml"
    spec.write_text(f'[effort]\nkind = "{kind}"\n')
    log = _log(res, kind, tmp_path)
    got = {}
    for runtime in ("compiled", "python"):
        opts = EstimateOptions(
            robot="paper_2link", log_spec=str(spec), estimator="replay", plots=False
        )
        opts = dataclasses.replace(opts, runtime=runtime)
        got[runtime] = estimate_command(log, tmp_path / runtime, opts)
    assert len(calls) == 1  # the compiled run, in C
    c, py = got["compiled"].estimate, got["python"].estimate
    assert got["compiled"].log.effort_kind == kind
    assert c.x_hat.shape == (len(res.t), res.lib.N)
    _close("x_hat", c.x_hat, py.x_hat, RTOL)
    _close("diag P", c.P_diag, py.P_diag, RTOL)
    assert c.nees is not None and py.nees is not None
    np.testing.assert_allclose(c.nees, py.nees, rtol=RTOL_NIS)
