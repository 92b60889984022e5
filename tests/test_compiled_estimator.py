"""Two implementations, one answer: the compiled estimators (C runtime over the generated
``est_*`` functions) against the Python reference estimators.

Both are driven with the same recorded inputs of a 10 s paper-sim run (the ``truth-ct``
controller acts on the true state, so one recording serves every estimator): the torques u,
the encoder samples and the delivered camera frames.  Every step, x(k|k) and P(k|k) must agree
to 1e-8 (absolute; entries are O(1e-6 .. 1)) and every decision (encoder accepted, frames
applied, gated or refused, with the same NIS) must be the same.

The exact-reference tests (replay and cloning equal to an in-order Kalman filter on a linear
system, tests/estimation/test_estimation_filters.py) run on the Python path only: the compiled
path is generated from a robot's symbolic model, so its exactness is checked here against the
Python reference, which those tests check against the in-order filter.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np
import pytest
from numpy.typing import NDArray

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError, EstimatorError
from amsfe_sym.estimation import CameraFrame, Estimator, StepReport, make_estimator
from amsfe_sym.estimation.base import FilterConfig
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import filter_config, scenario_timing
from amsfe_sym.sim.loop import run

FloatArray = NDArray[np.float64]
NAMES = ("encoders", "naive", "oosm", "replay", "cloning")
TOL = 1e-8


@dataclass
class Recording:
    """Inputs of a run, step by step: u[k] over [k, k+1], z[k+1], frames delivered at k+1."""

    lib: ModelLibrary
    kwargs: dict[str, object]
    u: FloatArray
    z: FloatArray
    frames: list[list[CameraFrame]]


def record(scenario: str = "paper-sim", duration: float | None = None) -> Recording:
    sc = load_scenario(scenario).with_overrides(duration=duration)
    lib = library_for(sc)
    res = run(sc, lib)
    n, p = lib.n, lib.p
    f = sc.filter
    frames: list[list[CameraFrame]] = [[] for _ in range(len(res.t))]
    for kappa, k, zu, zv in res.frames:
        frames[int(k)].append(CameraFrame(int(kappa), np.array([zu, zv])))
    timing = scenario_timing(sc, lib)
    z0 = res.z_enc[0]
    th0 = np.array(sc.estimate0.theta, dtype=float) if sc.estimate0.theta else lib.theta_initial
    x0 = np.concatenate([sc.estimate0.q, sc.estimate0.qd, z0[:n], z0[n:], th0])
    std = {"q": 0.5, "qd": 0.5, "qm": 0.01, "qmd": 0.1, "theta": 0.2, **dict(sc.estimate0.std)}
    P0 = np.diag(np.repeat([std[b] for b in ("q", "qd", "qm", "qmd")], n) ** 2)
    P0 = np.diag(np.r_[np.diag(P0), np.full(p, std["theta"] ** 2)])
    enc_var = np.r_[np.full(n, sc.encoders.q_std**2), np.full(n, sc.encoders.qd_std**2)]
    kwargs: dict[str, object] = {
        "model": CompiledTransition(
            lib, noise_covariance(lib, f.link_torque_std, f.motor_torque_std, f.theta_rate_std)
        ),
        "encoder": EncoderMeasurement(lib, enc_var[:n], enc_var[n:]),
        "camera": CameraMeasurement(lib, sc.camera.pixel_std**2 + 1.0 / 12.0),
        "x0": x0,
        "P0": P0,
        "config": filter_config(sc, timing),
    }
    return Recording(lib, kwargs, res.u, res.z_enc, frames)


@pytest.fixture(scope="module")
def paper_sim() -> Recording:
    return record("paper-sim")


def decisions(rep: StepReport) -> tuple[object, ...]:
    return (
        rep.encoder_accepted,
        rep.frames_applied,
        rep.frames_rejected,
        rep.frames_ignored,
        len(rep.frame_nis),
        rep.replayed_steps,
        rep.clones,
    )


def compare(rec: Recording, name: str, steps: int | None = None) -> dict[str, float]:
    """Run both paths; assert equality step by step; return the largest differences."""
    py: Estimator = make_estimator(name, **rec.kwargs)  # type: ignore[arg-type]
    c = make_compiled_estimator(name, **rec.kwargs)
    worst = {"x": 0.0, "P": 0.0, "nis": 0.0}
    counts = {"applied": 0, "rejected": 0, "updated": 0}
    K = rec.u.shape[0] - 1 if steps is None else steps
    for k in range(K):
        rp = py.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        rc = c.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        assert decisions(rp) == decisions(rc), f"step {k + 1}: {rp} != {rc}"
        counts["applied"] += rp.frames_applied
        counts["rejected"] += rp.frames_rejected
        counts["updated"] += len(rp.frame_nis)
        dx = float(np.max(np.abs(py.x - c.x)))
        dP = float(np.max(np.abs(py.P - c.P)))
        dn = max((abs(a - b) for a, b in zip(rp.frame_nis, rc.frame_nis, strict=True)), default=0)
        assert dx <= TOL and dP <= TOL, f"{name} step {k + 1}: |dx| {dx:.3g}, |dP| {dP:.3g}"
        worst = {"x": max(worst["x"], dx), "P": max(worst["P"], dP), "nis": max(worst["nis"], dn)}
    assert c.k == py.k
    worst.update({k: float(v) for k, v in counts.items()})
    return worst


@pytest.mark.parametrize("name", NAMES)
def test_compiled_equals_python_over_paper_sim(paper_sim: Recording, name: str) -> None:
    worst = compare(paper_sim, name)
    print(name, worst)
    if name != "encoders":
        assert worst["updated"] > 50  # the camera update ran (naive's frames are gated)


def test_compiled_errors_are_statuses_not_nans(paper_sim: Recording) -> None:
    est = make_compiled_estimator("oosm", **paper_sim.kwargs)
    with pytest.raises(EstimatorError):
        est.step(np.array([np.nan, 0.0]), paper_sim.z[1])
    est.step(paper_sim.u[0], paper_sim.z[1])
    x = est.x.copy()
    # a NaN frame and a NaN encoder sample are refused, never propagated
    rep = est.step(paper_sim.u[1], np.full(4, np.nan), [CameraFrame(1, np.array([np.nan, 1.0]))])
    assert rep.frames_rejected == 1 and not rep.encoder_accepted
    assert np.isfinite(est.x).all() and not np.array_equal(est.x, x)


def test_compiled_refuses_a_full_covariance(paper_sim: Recording) -> None:
    kwargs = dict(paper_sim.kwargs)
    model = kwargs["model"]
    assert isinstance(model, CompiledTransition)
    Qw = model.Qw.copy()
    Qw[0, 1] = Qw[1, 0] = 0.1 * Qw[0, 0]
    kwargs["model"] = CompiledTransition(paper_sim.lib, Qw)
    with pytest.raises(ConfigError, match="diagonal"):
        make_compiled_estimator("oosm", **kwargs)


@pytest.mark.parametrize("name", ["oosm", "cloning"])
def test_compiled_equals_python_on_the_6dof_ur5(name: str) -> None:
    """The same equivalence on the UR5 (N = 25, ur5-demo scenario, 1 s: 30 frames)."""
    worst = compare(record("ur5-demo", duration=1.0), name)
    print(name, worst)
    assert worst["updated"] > 20


def on_library(kwargs: dict, lib: ModelLibrary) -> dict:
    """An estimator's keyword arguments with its model, encoder and camera models on ``lib``
    (the same noise: Qw, the encoders' and the camera's R)."""
    old = kwargs["model"], kwargs["encoder"], kwargs["camera"]
    assert isinstance(old[0], CompiledTransition) and isinstance(old[1], EncoderMeasurement)
    assert isinstance(old[2], CameraMeasurement)
    return dict(
        kwargs,
        model=CompiledTransition(lib, old[0].Qw),
        encoder=EncoderMeasurement(lib, np.diag(old[1].R)[:2], np.diag(old[1].R)[2:]),
        camera=CameraMeasurement(lib, np.diag(old[2].R)),
    )


@pytest.mark.slow
def test_a_non_converged_inverse_does_not_refuse_frames(
    paper_sim: Recording, one_chord_2link: ModelLibrary
) -> None:
    """An inverse transition that does not converge no longer matters to oosm's default
    backward map (issue 18): it is linearised about the stored forward pass on both paths
    (``backward_map = "inverse"`` refuses such frames: tests/test_compiled_backward_map.py).

    The paper_2link arm with its ``paper`` integrator and one chord step in the inverse
    (``inverse_iterations = 1``: residuals ~1e-6..1e-4, which refused every late frame of
    oosm on both paths under issue 10's check): the frames are applied, with the same
    decisions and estimates on both paths."""
    from amsfe_sym.sim.result import refusal_kind

    kwargs = on_library(dict(paper_sim.kwargs), one_chord_2link)
    py: Estimator = make_estimator("oosm", **kwargs)  # type: ignore[arg-type]
    c = make_compiled_estimator("oosm", **kwargs)
    refused = 0
    for k in range(2000):
        rp = py.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
        rc = c.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
        assert decisions(rp) == decisions(rc), f"step {k + 1}: {rp} != {rc}"
        kinds = [refusal_kind(r) for r in rc.rejections]
        assert [refusal_kind(r) for r in rp.rejections] == kinds
        for a, b in zip(rp.rejections, rc.rejections, strict=True):
            assert a.split(", found ")[0] == b.split(", found ")[0]  # same kappa, lag, limit
        refused += kinds.count("no_convergence")
        assert np.max(np.abs(py.x - c.x)) <= TOL and np.max(np.abs(py.P - c.P)) <= TOL
    assert refused == 0 and c.diagnostics().frames_applied >= 10
    assert c.status_string(10).startswith("refused: the inverse transition")


def test_compiled_replay_equals_the_in_order_filter(paper_sim: Recording) -> None:
    """The exactness of replay on the compiled path, on the real (nonlinear) model: once a
    late frame is delivered, replay's posterior is the one of the same filter fed that frame
    at its exposure step (re-filtering repeats the in-order filter's operations).  Every
    other frame is kept so that none is in flight at the comparison steps."""
    rec = paper_sim
    K = 4000
    kept = [
        [fr for fr in frames if fr.exposure_step > 0 and (fr.exposure_step // 125) % 2 == 0]
        for frames in rec.frames[: K + 1]
    ]
    in_order: list[list[CameraFrame]] = [[] for _ in range(K + 1)]
    for frames in kept:
        for fr in frames:
            in_order[fr.exposure_step].append(fr)
    late = make_compiled_estimator("replay", **rec.kwargs)
    now = make_compiled_estimator("replay", **rec.kwargs)
    compared = 0
    for k in range(K):
        rl = late.step(rec.u[k], rec.z[k + 1], kept[k + 1])
        rn = now.step(rec.u[k], rec.z[k + 1], in_order[k + 1])
        assert rl.frames_rejected == rn.frames_rejected == 0
        if kept[k + 1]:  # just delivered: both filters hold the same measurements now
            assert rl.replayed_steps > 100  # a late frame: it re-filtered its lag
            np.testing.assert_allclose(late.x, now.x, rtol=0, atol=1e-10)
            np.testing.assert_allclose(late.P, now.P, rtol=0, atol=1e-12)
            compared += 1
        elif any(in_order[j] for j in range(max(k - 124, 0), k + 2)):
            assert float(np.max(np.abs(late.x - now.x))) > 0  # in flight: not yet the same
    assert compared >= 15


@pytest.mark.parametrize("name", ["naive", "oosm", "replay", "cloning"])
def test_a_repeated_frame_is_not_fused_twice(paper_sim: Recording, name: str) -> None:
    """Measurements are idempotent (issue 20 item 4): every frame delivered twice (again at
    the next step, and twice in one delivery) gives the estimates of single delivery, in
    the Python reference and in C, and the repeats are counted as refused; the C API
    refuses a repeat itself (AMSFE_REFUSED_DUPLICATE) when called directly."""
    K = 400
    for make in (make_estimator, make_compiled_estimator):
        once: Estimator = make(name, **paper_sim.kwargs)  # type: ignore[arg-type]
        twice: Estimator = make(name, **paper_sim.kwargs)  # type: ignore[arg-type]
        repeats = 0
        for k in range(K):
            frames = paper_sim.frames[k + 1]
            again = [f for f in paper_sim.frames[k]] + frames + frames  # late and doubled
            once.step(paper_sim.u[k], paper_sim.z[k + 1], frames)
            rep = twice.step(paper_sim.u[k], paper_sim.z[k + 1], again)
            repeats += sum("duplicate" in r for r in rep.rejections)
            np.testing.assert_array_equal(once.x, twice.x)
        assert repeats >= 2 * sum(len(f) for f in paper_sim.frames[1 : K + 1]) - 2
    c = make_compiled_estimator(name, **paper_sim.kwargs)
    kappa_frames = [(k, f) for k in range(1, K) for f in paper_sim.frames[k]]
    k_first, first = kappa_frames[0]
    for k in range(k_first):
        c.step(paper_sim.u[k], paper_sim.z[k + 1], [])
    nis = ctypes.c_double()
    zbuf = np.ascontiguousarray(first.z, dtype=float)
    fn = c._c["amsfe_est_camera_frame"]
    status = [fn(c._h, zbuf.ctypes.data, first.exposure_step, ctypes.byref(nis)) for _ in range(2)]
    assert status[0] in (0, 1) and status[1] == 11, status


def test_an_outlier_fused_with_the_gate_off_is_named_on_both_paths(paper_sim: Recording) -> None:
    """Gate off (gate_probability = 0) and one frame 1e6 px off: the linearised update moves
    the state (and the payload) hundreds of standard deviations, outside where the EKF holds,
    and the filter breaks down steps later.  Both paths stop there (within 2 steps) with one line
    naming that frame, its NIS and the fix (not a bare covariance or Cholesky error)."""
    import dataclasses

    kwargs = dict(paper_sim.kwargs)
    config = kwargs["config"]
    assert isinstance(config, FilterConfig)
    kwargs["config"] = dataclasses.replace(config, gate_probability=None)
    frames = [list(f) for f in paper_sim.frames]
    delivered = [k for k, f in enumerate(frames) if f]
    bad = delivered[3]
    kappa = frames[bad][0].exposure_step
    frames[bad][0] = CameraFrame(kappa, frames[bad][0].z + 1e6)
    messages = []
    for est in (make_estimator("oosm", **kwargs), make_compiled_estimator("oosm", **kwargs)):  # type: ignore[arg-type]
        with pytest.raises(EstimatorError) as info:
            for k in range(paper_sim.u.shape[0] - 1):
                est.step(paper_sim.u[k], paper_sim.z[k + 1], frames[k + 1])
        messages.append(str(info.value))
        assert f"camera frame kappa={kappa} was fused with NIS" in str(info.value)
        assert "gate is off" in str(info.value) and "\n" not in str(info.value)
    # the breakdown on both paths, steps after the frame: where the covariance first fails
    # its check once the state is hundreds of sigma off is a knife edge that the paths'
    # 1e-12 rounding differences can move by a step (502 / 501 on the recording of
    # paper-sim's issue-28 blend), so within 2 steps of each other, both after the frame
    steps = [int(m.split(":")[0].rsplit(" ", 1)[1]) for m in messages]
    assert all(s_ > bad for s_ in steps) and abs(steps[0] - steps[1]) <= 2, messages
