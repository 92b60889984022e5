"""``backward_map = "inverse"`` (the paper's eqs. (22), (24)) on both paths: the compiled C
runtime against the Python reference over a paper-sim and a UR5 run (x, P within 1e-9, the
same decisions), a non-converged inverse refused on both paths as a counted frame, and the scenario
setting ``[filter] backward_map`` reaching the estimator (``--set filter.backward_map=inverse``).

The linear-model identity of the two maps is in tests/estimation/test_backward_map.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.estimation import Estimator, make_estimator
from amsfe_sym.estimation.base import FilterConfig
from amsfe_sym.runtime.compiled_estimator import (
    STATUS,
    estimator_log_lines,
    make_compiled_estimator,
)
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import CompiledTransition
from amsfe_sym.scenario import apply_sets, load_scenario
from amsfe_sym.sim.builders import filter_config, scenario_timing
from amsfe_sym.sim.result import refusal_kind
from tests.test_compiled_estimator import Recording, decisions, on_library, record

#: The brief's bound for the two paths over a run (absolute; entries are O(1e-6 .. 1)).
TOL = 1e-9


@pytest.fixture(scope="module")
def paper_sim() -> Recording:
    return record("paper-sim", duration=4.0)


def with_map(rec: Recording, backward_map: str, **model_kw: float) -> dict[str, object]:
    kwargs = dict(rec.kwargs)
    cfg = kwargs["config"]
    assert isinstance(cfg, FilterConfig)
    kwargs["config"] = dataclasses.replace(cfg, backward_map=backward_map)
    if model_kw:
        old = kwargs["model"]
        assert isinstance(old, CompiledTransition)
        kwargs["model"] = CompiledTransition(rec.lib, old.Qw, **model_kw)
    return kwargs


def run_both(rec: Recording, kwargs: dict[str, object], steps: int) -> dict[str, float]:
    py: Estimator = make_estimator("oosm", **kwargs)  # type: ignore[arg-type]
    c = make_compiled_estimator("oosm", **kwargs)
    worst = {"x": 0.0, "P": 0.0, "applied": 0.0, "no_convergence": 0.0}
    for k in range(steps):
        rp = py.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        rc = c.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        assert decisions(rp) == decisions(rc), f"step {k + 1}: {rp} != {rc}"
        kinds = [refusal_kind(r) for r in rc.rejections]
        assert [refusal_kind(r) for r in rp.rejections] == kinds
        dx = float(np.max(np.abs(py.x - c.x)))
        dP = float(np.max(np.abs(py.P - c.P)))
        assert dx <= TOL and dP <= TOL, f"step {k + 1}: |dx| {dx:.3g}, |dP| {dP:.3g}"
        worst["x"], worst["P"] = max(worst["x"], dx), max(worst["P"], dP)
        worst["applied"] += rp.frames_applied
        worst["no_convergence"] += kinds.count("no_convergence")
    return worst


def test_inverse_map_compiled_equals_python(paper_sim: Recording) -> None:
    """4 s of paper-sim (31 late frames, lag 125): both paths within 1e-9, frames applied."""
    worst = run_both(paper_sim, with_map(paper_sim, "inverse"), len(paper_sim.u) - 1)
    print(worst)
    assert worst["applied"] >= 20 and worst["no_convergence"] == 0


def test_the_maps_differ_on_the_nonlinear_model(paper_sim: Recording) -> None:
    """Not vacuous: on the nonlinear arm the setting changes the estimate (both paths)."""
    steps = 1000  # 7 late frames
    for make in (make_estimator, make_compiled_estimator):
        a: Estimator = make("oosm", **with_map(paper_sim, "linearised"))  # type: ignore[arg-type]
        b: Estimator = make("oosm", **with_map(paper_sim, "inverse"))  # type: ignore[arg-type]
        for k in range(steps):
            a.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
            b.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
        assert float(np.max(np.abs(a.x - b.x))) > 1e-9


def test_a_non_converged_inverse_refuses_the_frame_on_both_paths(paper_sim: Recording) -> None:
    """A tolerance no residual meets (1e-300): every late frame is refused as a counted
    ``no_convergence`` on both paths, with the same message start, and the estimate stays
    finite (never a silent NaN): the frames are simply not used."""
    kwargs = with_map(paper_sim, "inverse", inverse_tol=1e-300)
    steps = 800  # 5 late frames
    worst = run_both(paper_sim, kwargs, steps)
    assert worst["applied"] == 0 and worst["no_convergence"] >= 4
    c = make_compiled_estimator("oosm", **kwargs)
    enc = make_compiled_estimator("encoders", **kwargs)
    for k in range(steps):
        rc = c.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
        enc.step(paper_sim.u[k], paper_sim.z[k + 1], paper_sim.frames[k + 1])
        for msg in rc.rejections:
            assert "transition_inverse (eq. 22)" in msg
    assert np.isfinite(c.x).all()
    # every frame refused: the encoders-only filter's estimate, exactly
    np.testing.assert_array_equal(c.x, enc.x)
    assert c.diagnostics().frames_refused >= 4
    assert c.status_string(STATUS["refused_no_convergence"]).startswith("refused: the inverse")


def test_scenario_setting_reaches_both_paths() -> None:
    sc = apply_sets(load_scenario("paper-sim"), ["filter.backward_map=inverse"])
    assert sc.filter.backward_map == "inverse"
    from amsfe_sym.codegen import library_for

    cfg = filter_config(sc, scenario_timing(sc, library_for(sc)))
    assert cfg.backward_map == "inverse"
    with pytest.raises(ConfigError, match="backward_map"):
        apply_sets(load_scenario("paper-sim"), ["filter.backward_map=exact"])
    with pytest.raises(ConfigError, match="backward_map"):
        FilterConfig(backward_map="Inverse")


def test_the_log_refuses_an_inverse_estimator(paper_sim: Recording) -> None:
    """The log format (examples/estimate_from_log.c) records no backward map: logging an
    inverse-map estimator is refused rather than replayed with the other map."""
    c = make_compiled_estimator("oosm", **with_map(paper_sim, "inverse"))
    with pytest.raises(ConfigError, match="backward_map"):
        estimator_log_lines(c)
    assert estimator_log_lines(make_compiled_estimator("oosm", **paper_sim.kwargs))


def test_inverse_map_compiled_equals_python_on_the_6dof_ur5() -> None:
    """The same equivalence on the UR5 (N = 25, ur5-demo, 1 s: lag 33, rk4 inverse)."""
    rec = record("ur5-demo", duration=1.0)
    worst = run_both(rec, with_map(rec, "inverse"), len(rec.u) - 1)
    print(worst)
    assert worst["applied"] >= 20 and worst["no_convergence"] == 0


def test_inverse_map_closed_loop_same_on_both_runtimes() -> None:
    """The amsfe closed loop on paper-sim with ``--set filter.backward_map=inverse``: the C loop
    reproduces the Python reference loop (Python estimator) signal by signal, counters too."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.sim.loop import run
    from tests.test_compiled_loop import assert_same_run

    sc = apply_sets(load_scenario("paper-sim"), ["filter.backward_map=inverse"])
    sc = apply_sets(sc, ["controller_gains.amsfe.blend_accel=inf"])
    sc = sc.with_overrides(estimator="oosm", controller="amsfe", duration=2.0, seed=2)
    lib = library_for(sc)
    c = run(sc, lib, runtime="compiled")
    assert_same_run(run(sc, lib), c)
    assert c.counters["frames_applied"] >= 10 and c.counters["refused_no_convergence"] == 0


@pytest.mark.slow
def test_a_real_non_converged_inverse_is_refused_on_both_paths(
    paper_sim: Recording, one_chord_2link: ModelLibrary
) -> None:
    """A model whose generated inverse really does not converge: the paper_2link arm with its
    ``paper`` integrator and one chord step (``inverse_iterations = 1``: residuals ~1e-6..1e-4,
    as in test_compiled_estimator.py's issue-18 test).  With ``backward_map = "inverse"``
    every late frame is refused as ``no_convergence`` on both paths, same decisions and
    estimates; the linearised map applies the same frames."""
    kwargs = on_library(with_map(paper_sim, "inverse"), one_chord_2link)
    rec = dataclasses.replace(paper_sim, lib=one_chord_2link)
    worst = run_both(rec, kwargs, 2000)
    assert worst["applied"] == 0 and worst["no_convergence"] >= 10
    linear = dict(kwargs, config=dataclasses.replace(kwargs["config"], backward_map="linearised"))
    assert run_both(rec, linear, 2000)["applied"] >= 10
