"""Per-call cost of the compiled estimator tick against the Python one (docs/how-to/runtime-c.md).

    .venv/bin/python examples/bench_estimator.py [scenario] [estimator ...]

Records the scenario once (truth-ct: the inputs do not depend on the estimator), then for each
estimator: the Python reference's ``step`` per tick (perf_counter_ns), the compiled runtime
driven through ctypes (``CompiledEstimator.step``, the same checks in Python around one C
call), and the C example program over the same log with ``--time`` (the bare C tick,
clock_gettime around ``amsfe_est_tick``).  Medians and 99th percentiles; a tick is a step
without a camera frame, the frame cost is the mean ``amsfe_est_camera_frame``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.test_compiled_estimator import record
from tests.test_embed_estimator import build_example

from amsfe_sym.estimation import make_estimator
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator, write_log


def per_tick(est, rec) -> np.ndarray:  # type: ignore[no-untyped-def]
    K = rec.u.shape[0] - 1
    times = []
    for k in range(K):
        t0 = time.perf_counter_ns()
        est.step(rec.u[k], rec.z[k + 1], rec.frames[k + 1])
        dt = time.perf_counter_ns() - t0
        if not rec.frames[k + 1]:
            times.append(dt)
    return np.array(times) / 1e3


def main() -> None:
    scenario = sys.argv[1] if len(sys.argv) > 1 else "paper-sim"
    names = sys.argv[2:] or ["oosm"]
    rec = record(scenario)
    print(f"{scenario}: library {rec.lib.name}, N = {rec.lib.N}, {rec.u.shape[0] - 1} steps")
    with tempfile.TemporaryDirectory() as tmp:
        exe = build_example(rec.lib.dir, rec.lib.manifest.library, Path(tmp) / "est")
        for name in names:
            py = per_tick(make_estimator(name, **rec.kwargs), rec)  # type: ignore[arg-type]
            comp = make_compiled_estimator(name, **rec.kwargs)
            cy = per_tick(comp, rec)
            comp = make_compiled_estimator(name, **rec.kwargs)
            K = rec.u.shape[0] - 1
            log = write_log(Path(tmp) / "run.log", comp, rec.u[:K], list(rec.z[1:]), rec.frames[1:])
            err = subprocess.run(
                [str(exe), str(log), "--time"], check=True, capture_output=True, text=True
            ).stderr.strip()
            for label, t in (("python", py), ("compiled via ctypes", cy)):
                print(
                    f"  {name:8s} {label:20s} tick median {np.median(t):8.2f} us, "
                    f"p99 {np.percentile(t, 99):8.2f} us"
                )
            print(f"  {name:8s} {'C (example, --time)':20s} {err}")


if __name__ == "__main__":
    main()
