"""A section of ``amsfe bench``: the closed loop's real-time factor on both runtimes.

One scenario (plant substeps, encoders, camera, disturbance, estimator and controller),
simulated for ``duration`` seconds at its control rate: the compiled C loop
(``runtime="compiled"``, median of ``rounds`` runs) and the Python reference loop (one run:
it is the slow one).  The real-time factor is simulated time over wall time; per tick is
wall time over ticks (a mean: the late-frame ticks of ``oosm`` and ``replay`` cost more
than the others, see the tick section for medians).
"""

from __future__ import annotations

import statistics
from typing import Any

from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario

__all__ = ["bench_closed_loop"]


def bench_closed_loop(
    sc: Scenario, lib: ModelLibrary, rounds: int = 3, python_duration: float | None = None
) -> dict[str, Any]:
    """Time the closed loop of ``sc`` on ``lib``: compiled (median of ``rounds``) and Python
    (one run of ``python_duration`` seconds, default the scenario's).

    Returns:
        ``{"scenario", "estimator", "controller", "duration_s", "compiled": {...},
        "python": {...}, "speedup"}`` with per runtime ``wall_s``, ``us_per_tick`` and
        ``real_time_factor``, or ``error`` when the run failed.
    """
    from amsfe_sym.errors import AmsfeError
    from amsfe_sym.sim.loop import run

    out: dict[str, Any] = {
        "scenario": sc.name,
        "estimator": sc.estimator,
        "controller": sc.controller,
        "duration_s": sc.duration,
    }

    def one(s: Scenario, runtime: str) -> tuple[float, int, float]:
        res = run(s, lib, runtime=runtime)
        return res.wall_time_s, res.t.size, float(res.t[-1] + lib.T)

    for runtime, n_rounds, dur in (
        ("compiled", rounds, sc.duration),
        ("python", 1, python_duration or sc.duration),
    ):
        try:
            runs = [one(sc.with_overrides(duration=dur), runtime) for _ in range(n_rounds)]
        except AmsfeError as exc:
            out[runtime] = {"error": str(exc)}
            continue
        wall = statistics.median(r[0] for r in runs)
        ticks, sim = runs[0][1], runs[0][2]
        out[runtime] = {
            "rounds": n_rounds,
            "sim_time_s": round(sim, 4),
            "wall_s": round(wall, 4),
            "us_per_tick": round(1e6 * wall / ticks, 2),
            "real_time_factor": round(sim / max(wall, 1e-12), 1),
        }
    c, p = out.get("compiled", {}), out.get("python", {})
    if "us_per_tick" in c and "us_per_tick" in p:
        out["speedup"] = round(p["us_per_tick"] / max(c["us_per_tick"], 1e-12), 1)
    return out
