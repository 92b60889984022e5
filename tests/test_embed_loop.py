"""The real-time loop embeds without Python: examples/control_from_log.c links only the
generated library and its headers, runs estimator + controller (amsfe_loop_tick) over the
sensor log of a simulated run, and writes torques and estimates equal to the Python loop's
(1e-8) and to the C simulation's (1e-12, the same C code)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.codegen import compiler, library_for
from amsfe_sym.runtime.compiled_loop import write_loop_log
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import build_run
from amsfe_sym.sim.compiled import controller_params, simulation_inputs
from amsfe_sym.sim.loop import run
from tests.conftest import build_example


@pytest.mark.parametrize(("estimator", "controller"), [("oosm", "amsfe"), ("cloning", "dtsmc")])
def test_c_example_runs_the_loop_of_a_run(estimator: str, controller: str, tmp_path: Path) -> None:
    if shutil.which(compiler()) is None:
        pytest.skip("no C compiler")
    sc = load_scenario("paper-sim").with_overrides(
        estimator=estimator, controller=controller, duration=1.0, seed=3
    )
    lib = library_for(sc)
    exe = build_example("control_from_log", lib, tmp_path / "control_from_log")
    c = run(sc, lib, runtime="compiled")
    py = run(sc, lib, runtime="python", compiled_estimator=True)
    parts = build_run(sc, lib, compiled=True)
    inputs, _ = simulation_inputs(sc, lib, c.t.size, parts)
    log = write_loop_log(
        tmp_path / "run.log",
        parts.estimator,  # type: ignore[arg-type]
        controller_params(parts.controller, lib),
        c.z_enc,
        inputs.ref,
        c.frames,
    )
    out = subprocess.run([str(exe), str(log)], check=True, capture_output=True, text=True)
    rows = np.array([[float(v) for v in line.split()[1:]] for line in out.stdout.splitlines()])
    n = lib.n
    assert rows.shape == (c.t.size, 1 + n + lib.N)
    np.testing.assert_array_equal(rows[:, 0], np.arange(c.t.size))
    np.testing.assert_allclose(rows[:, 1 : 1 + n], c.u, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rows[:, 1 + n :], c.x_hat, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rows[:, 1 : 1 + n], py.u, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(rows[:, 1 + n :], py.x_hat, rtol=1e-8, atol=1e-8)
    assert c.counters["frames_applied"] > 0
