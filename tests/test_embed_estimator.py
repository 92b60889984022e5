"""The compiled estimator embeds without Python: examples/estimate_from_log.c links only the
generated library and amsfe_runtime.h, runs the estimator over a recorded log, and writes the
estimates, which must equal the Python reference (1e-8) and the ctypes-driven runtime (1e-12,
the same C code) with the same frame decisions."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.codegen import compiler
from amsfe_sym.estimation import make_estimator
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator, write_log
from tests.conftest import build_example
from tests.test_compiled_estimator import Recording, record


@pytest.fixture(scope="module")
def short_run() -> Recording:
    return record(duration=1.5)


@pytest.mark.parametrize("name", ["oosm", "replay", "cloning"])
def test_c_example_matches_python(name: str, short_run: Recording, tmp_path: Path) -> None:
    if shutil.which(compiler()) is None:
        pytest.skip("no C compiler")
    rec = short_run
    K = rec.u.shape[0] - 1
    exe = build_example("estimate_from_log", rec.lib, tmp_path / "estimate")
    ref = make_estimator(name, **rec.kwargs)  # type: ignore[arg-type]
    comp = make_compiled_estimator(name, **rec.kwargs)
    log = write_log(tmp_path / "run.log", comp, rec.u[:K], list(rec.z[1 : K + 1]), rec.frames[1:])
    out = subprocess.run([str(exe), str(log)], check=True, capture_output=True, text=True).stdout
    N = rec.lib.N
    states = [
        np.array(line.split()[1:], dtype=float)
        for line in out.splitlines()
        if line.startswith("est ")
    ]
    statuses = [int(line.split()[3]) for line in out.splitlines() if line.startswith("frame")]
    assert len(states) == K
    applied: list[int] = []
    for k in range(K):
        rp = ref.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        comp.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        applied += [1] * rp.frames_applied + [0] * rp.frames_rejected
        got = states[k]
        assert int(got[0]) == ref.k
        x, P = got[1 : 1 + N], got[1 + N :].reshape(N, N, order="F")
        np.testing.assert_allclose(x, comp.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(P, comp.P, rtol=0, atol=1e-12)
        np.testing.assert_allclose(x, ref.x, rtol=0, atol=1e-8)
        np.testing.assert_allclose(P, ref.P, rtol=0, atol=1e-8)
    assert len(applied) == len(statuses) and sum(applied) == statuses.count(0) > 0
