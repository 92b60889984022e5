"""Soak: run the estimators of paper-sim for many ticks and check that they stay healthy.

Usage (the 10^6-tick run recorded in docs/explanation/estimation.md)::

    python tools/soak.py --ticks 1000000 --estimators oosm replay cloning

Each estimator runs the closed loop (``amsfe_sym.sim.loop.run``) for ``--ticks`` ticks in
its own process.  After every estimator step the script checks that P is symmetric
(max|P - P^T| <= 1e-9 max|P|) and positive definite (a Cholesky factorisation succeeds);
at the end it reports the NEES over consecutive windows of 10^4 ticks against the 99 %
chi-square band of a window mean, and the refusal counters.  Exit code 1 if P ever lost
symmetry or definiteness, or the run stopped.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from scipy.stats import chi2

WINDOW = 10_000


def soak(estimator: str, ticks: int, seed: int) -> dict[str, Any]:
    """One estimator over ``ticks`` ticks of paper-sim; returns the health record."""
    import amsfe_sym.sim.loop as loop
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario

    sc = load_scenario("paper-sim").with_overrides(estimator=estimator, seed=seed)
    lib = library_for(sc)
    sc = sc.with_overrides(duration=(ticks - 1) * lib.T)
    health = {"asymmetric": 0, "not_pd": 0, "worst_asymmetry": 0.0, "min_eig_min": np.inf}
    build_run = loop.build_run

    def build(s: Any, library: Any) -> Any:
        parts = build_run(s, library)
        est = parts.estimator
        step = est.step

        def checked_step(*args: Any, **kw: Any) -> Any:
            rep = step(*args, **kw)
            P = est.P
            asym = float(np.max(np.abs(P - P.T)) / np.max(np.abs(P)))
            health["worst_asymmetry"] = max(health["worst_asymmetry"], asym)
            health["asymmetric"] += asym > 1e-9
            try:
                L = np.linalg.cholesky(P)
                health["min_eig_min"] = min(health["min_eig_min"], float(np.min(np.diag(L))) ** 2)
            except np.linalg.LinAlgError:
                health["not_pd"] += 1
            return rep

        est.step = checked_step
        return parts

    loop.build_run = build
    t0 = time.perf_counter()
    res = loop.run(sc, lib)
    wall = time.perf_counter() - t0
    N = lib.N
    windows = res.nees[1 : 1 + (res.nees.size - 1) // WINDOW * WINDOW].reshape(-1, WINDOW)
    means = windows.mean(axis=1)
    # band of a window mean if the WINDOW samples were independent chi2(N) (they are not:
    # neighbouring ticks are correlated, so this band is a loose sanity check, not a test)
    lo, hi = chi2.ppf([0.005, 0.995], N * WINDOW) / WINDOW
    return {
        "estimator": estimator,
        "ticks": int(res.t.size),
        "wall_s": round(wall, 1),
        "us_per_tick": round(1e6 * wall / res.t.size, 1),
        "P_asymmetric_steps": int(health["asymmetric"]),
        "P_worst_relative_asymmetry": health["worst_asymmetry"],
        "P_not_positive_definite_steps": int(health["not_pd"]),
        "nees_mean": float(res.nees.mean()),
        "nees_window_mean_min_max": [float(means.min()), float(means.max())],
        "nees_windows_inside_iid_band": f"{int(np.sum((means > lo) & (means < hi)))}/{means.size}",
        "N": N,
        "counters": res.counters,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--ticks", type=int, default=1_000_000)
    p.add_argument("--estimators", nargs="+", default=["oosm", "replay", "cloning"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args(argv)
    with ProcessPoolExecutor(a.workers) as pool:
        results = list(
            pool.map(
                soak, a.estimators, [a.ticks] * len(a.estimators), [a.seed] * len(a.estimators)
            )
        )
    print(json.dumps(results, indent=2))
    bad = any(r["P_not_positive_definite_steps"] or r["P_asymmetric_steps"] for r in results)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
