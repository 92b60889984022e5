"""``amsfe bench``: it runs, prints every row, and its routes agree on the numbers.

No timing is asserted (the machines are shared and noisy); only that each route computes
the same outputs and that the report has the expected structure.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.apps.bench import (
    CALL_FUNCTIONS,
    ESTIMATOR_NAMES,
    CTimer,
    Timing,
    _inputs,
    _state,
    time_calls,
)
from amsfe_sym.apps.cli import main
from amsfe_sym.apps.reference import PinocchioModel
from amsfe_sym.codegen import generate
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import load_spec
from amsfe_sym.runtime.library import ModelLibrary


def test_bench_prints_every_row_and_the_routes_agree(capsys, libraries, tmp_path: Path) -> None:
    libraries.get("paper_2link")
    out_json = tmp_path / "bench.json"
    argv = ["bench", "--repeat", "200", "--rounds", "2", "--duration", "0.2", "--joints", "1"]
    argv += ["--no-panda", "--scaling-loop-duration", "0.2"]
    argv += ["--loop-duration", "0.3", "--loop-scenarios", "paper-sim", "--logs", "paper-sim:0.3"]
    argv += ["--vision-frames", "4"]  # (tests/test_bench_vision.py checks that section)
    assert main([*argv, "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    for section in (
        "1. generation",
        "2. per-call cost",
        "3. estimator tick",
        "4. one est",
        "5. sc",
        "closed loop: paper-sim",
        "6. amsfe estimate",
        "7. camera chain",
    ):
        assert section in out
    for row in ("cold (force", "cached (second", *CALL_FUNCTIONS, "ekf_predict"):
        assert row in out
    for est in ESTIMATOR_NAMES:
        assert f"   {est} " in out
    assert "binding overhead" in out and "differ" not in out

    report = json.loads(out_json.read_text())
    (loop,) = report["closed_loop"]
    for rt in ("compiled", "python"):
        assert loop[rt]["sim_time_s"] == pytest.approx(0.301)  # 301 ticks of 1 ms
        assert loop[rt]["real_time_factor"] > 0
    assert report["robot"] == "paper_2link"
    assert report["generation"]["cached"]["reused"] is True
    assert report["generation"]["cold"]["reused"] is False
    assert set(report["generation"]["cold"]["timings"]) >= {"symbolic", "codegen", "compile"}
    rows = {r["function"]: r for r in report["calls"]}
    assert set(rows) == {*CALL_FUNCTIONS, "ekf_predict"}
    for name in CALL_FUNCTIONS:
        r = rows[name]
        # the ctypes binding, casadi.external and the SX VM give the same numbers
        assert r["max_diff_external"] == 0.0, name
        assert r["max_diff_sx_vm"] is not None and r["max_diff_sx_vm"] <= 1e-9, name
        for route in ("ctypes", "pure_c", "external", "sx_vm"):
            t = r[route]
            assert t["median_us"] > 0 and t["min_us"] <= t["median_us"] and t["rounds"] == 2
        assert r["overhead_us"] == pytest.approx(
            r["ctypes"]["median_us"] - r["pure_c"]["median_us"], abs=1e-3
        )
    for name in ("mass_matrix", "camera_measure", "plant_step"):
        assert rows[name]["max_diff_pinocchio"] <= 1e-9, name
    ests = {r["estimator"]: r for r in report["estimators"]}
    assert set(ests) == set(ESTIMATOR_NAMES)
    for r in ests.values():
        assert r["ticks"] == 201 and r["cost_per_tick_us"] > 0 and r["real_time_factor"] > 0
    (row,) = report["tick"]["rows"]  # section 4: oosm by default
    assert row["estimator"] == "oosm" and row["max_dx_compiled_python"] <= 1e-10
    (chain,) = report["scaling"]["rows"]  # section 5: one chain, no Panda
    assert (chain["robot"], chain["joints"], chain["N"]) == ("chain1", 1, 4)
    assert chain["scenario"] == "bench-chain1" and chain["diverged_at_s"] is None
    assert chain["real_time_factor"] > 0 and chain["loop_us_per_tick"] > 0
    assert 0 < chain["baseline_us"] <= chain["baseline_p99_us"]
    assert chain["aba_derivatives_us"] > 0 and chain["peak_mb"] > 0
    assert report["scaling"]["exponents"] == {}  # nothing to fit with one chain
    tick = report["tick_compiled_us"]
    assert set(tick) == {"plant_step", "transition_step", "mass_matrix", "bias", "total"}
    assert tick["total"] == pytest.approx(sum(v for k, v in tick.items() if k != "total"))
    (log,) = report["logs"]  # section 6: amsfe estimate over a 0.3 s log, 2 fresh processes
    assert (log["log"], log["ticks"], log["rounds"]) == ("paper-sim 0.3 s", 301, 2)
    m, f = log["median"], log["real_time_factor"]
    assert f["log"] == pytest.approx(0.301 / (m["read_s"] + m["estimate_s"]), rel=0.02, abs=0.01)
    assert f["process"] == pytest.approx(0.301 / m["process_s"], rel=0.02, abs=0.01)
    assert f["process_cpu"] == pytest.approx(0.301 / m["process_cpu_s"], rel=0.02, abs=0.01)
    assert m["startup_s"] + m["wall_s"] <= m["process_s"] + 0.02  # (start: 10 ms ticks)


def test_binding_matches_casadi_external(libraries) -> None:
    _, lib = libraries.get("paper_2link")
    x, u = _state(lib, np.random.default_rng(3))
    for name in CALL_FUNCTIONS:
        args = _inputs(lib, name, x, u)
        ours = lib.function(name)(*args)
        theirs = lib.external(name)(*args)
        theirs = theirs if isinstance(theirs, tuple) else (theirs,)
        assert len(ours) == len(theirs)
        for a, b in zip(ours, theirs, strict=True):
            np.testing.assert_array_equal(a, np.asarray(b).reshape(a.shape, order="F"))


def test_pure_c_timer_computes_the_same_outputs(libraries, tmp_path: Path) -> None:
    _, lib = libraries.get("paper_2link")
    timer = CTimer(tmp_path)
    x, u = _state(lib, np.random.default_rng(5))
    args = _inputs(lib, "transition_step", x, u)
    timing, checksum = timer.time(lib.library_path, "transition_step", args, rounds=2)
    ref = lib.function("transition_step")(*args)
    assert checksum == pytest.approx(sum(float(np.sum(r)) for r in ref), rel=1e-12)
    assert timing.rounds == 2 and timing.calls >= 1000 and timing.median_us > 0


def test_pinocchio_transition_matches_the_semi_implicit_library() -> None:
    """The Pinocchio comparison model computes the same x+, A (but d/dtheta) and Gamma."""
    spec = load_spec("paper_2link")
    spec = replace(
        spec,
        name="paper_2link_semi_implicit",  # the library_for override's: compiled once
        model=replace(spec.model, integrator="semi_implicit"),
    )
    lib = ModelLibrary(generate(spec).out_dir)
    robot = load_robot(spec)
    pm = PinocchioModel(robot, np.eye(2 * lib.n + lib.p))
    n = lib.n
    for seed in range(3):
        x, u = _state(lib, np.random.default_rng(seed))
        xn, A, G = lib.function("transition_step")(x, u)
        pxn, pA, pG = pm.transition_step(x, u)
        np.testing.assert_allclose(pxn, xn, atol=1e-12)
        np.testing.assert_allclose(pA[:, : 4 * n], A[:, : 4 * n], atol=1e-10)
        np.testing.assert_allclose(pG, G, atol=1e-12)


def test_compare_cflags_rebuilds_and_times(capsys, libraries) -> None:
    libraries.get("paper_2link")
    argv = ["bench", "--repeat", "200", "--rounds", "2", "--skip", "generation", "calls"]
    argv += ["tick", "loop", "scaling", "logs", "vision"]  # (logs: a 10 s and a 60 s log estimated)
    assert main([*argv, "estimators", "--compare-cflags=-O0,-O1"]) == 0
    out = capsys.readouterr().out
    assert "6. amsfe estimate" not in out  # only the section asked for
    assert "compiler flags" in out
    assert "   -O0 " in out and "   -O1 " in out


def test_time_calls_sizes_rounds_by_budget() -> None:
    t = time_calls(lambda: None, (), repeat=50, rounds=3)
    assert isinstance(t, Timing) and t.calls == 50 and t.rounds == 3
    assert 0 < t.min_us <= t.median_us


@pytest.mark.parametrize(
    "text", ["paper-sim", "paper-sim:0", "paper-sim:x", ":10", "a:inf", "paper-sim:images"]
)
def test_a_bad_log_case_is_one_line(text: str) -> None:
    from amsfe_sym.apps.bench.logs import log_case
    from amsfe_sym.errors import ConfigError

    with pytest.raises(ConfigError) as exc:
        log_case(text)
    assert "\n" not in str(exc.value) and "paper-sim:10" in str(exc.value)
    assert log_case("panda-control:60").duration == 60.0
    case = log_case("paper-sim:60:images")
    assert (case.scenario, case.duration, case.camera) == ("paper-sim", 60.0, "images")
    assert log_case("paper-sim:60:pixels").label == "paper-sim 60 s, 30 Hz pixels"
    serial = log_case("paper-sim:60:jpeg:threads=0")
    assert (serial.camera, serial.threads) == ("jpeg", 0)
    assert serial.label == "paper-sim 60 s, 30 Hz jpeg, serial decoding"
    assert log_case("paper-sim:60:jpeg:threads=2").label.endswith("2 decoding threads")
    assert serial.log_key == log_case("paper-sim:60:jpeg").log_key
    with pytest.raises(ConfigError) as exc:
        log_case("paper-sim:60:jpeg:threads=x")
    assert "\n" not in str(exc.value) and "AMSFE_IMAGE_THREADS" in str(exc.value)
