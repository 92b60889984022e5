"""The start-up on a grid of starts (docs/explanation/control.md, "Start-up"; issue 17 item 2):
paper-sim,
``amsfe``, 3 s, compiled loop, seed 0, the start-ups: the paper's (``first``), the wait
(``converged``), the wait with the blended reference (``blend``, ``blend_accel`` given by
``--blend-accel``), and the oracles without and with the blend.

Starts: the plant at 4 places (the paper's q0 = (0.5, 0.5), on the trajectory, and two
others), at rest or moving with the trajectory's velocity (pi, 0) rad/s; the estimate off by
0.4 rad in 4 directions; with the camera (``oosm``) and without (``encoders``); and the
``truth`` oracle (the same law on the true state) from the same 8 plant starts.  Per start:
divergence, the peak tracking error past the initial one, the largest error after 1.5 s::

    .venv/bin/python tools/startup_grid.py --out docs/data/startup-grid.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

PLACES = {"paper": (0.5, 0.5), "on-path": (0.0, 1.0), "far": (-0.5, 1.5), "near": (0.3, 0.8)}
MOTION = {"rest": (0.0, 0.0), "moving": (float(np.pi), 0.0)}
OFFSETS = {"++": (0.4, 0.4), "--": (-0.4, -0.4), "+-": (0.4, -0.4), "-+": (-0.4, 0.4)}
ESTIMATORS = ("oosm", "encoders")
STARTUPS = ("first", "converged", "blend", "oracle", "oracle-blend")  # oracle: true state


def one(job: tuple[str, str, str, str, str, float, float, int]) -> dict[str, Any]:
    place, motion, offset, estimator, startup, accel, rate, seed = job
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import apply_sets, load_scenario
    from amsfe_sym.sim.loop import run

    controller = "truth" if startup.startswith("oracle") else "amsfe"
    sc = load_scenario("paper-sim").with_overrides(
        controller=controller, estimator=estimator, duration=3.0, seed=seed
    )
    if startup in ("first", "converged"):
        sc = apply_sets(sc, [f"controller_gains.amsfe.startup={startup}"])
    blend = accel if startup.endswith("blend") else float("inf")
    sc = apply_sets(
        sc,
        [
            f"controller_gains.{controller}.blend_accel={blend}",
            f"controller_gains.{controller}.blend_rate={rate}",
        ],
    )
    q0, qd0, dq = PLACES[place], MOTION[motion], OFFSETS[offset]
    sc = replace(
        sc,
        plant=replace(sc.plant, q0=q0, qd0=qd0),
        estimate0=replace(
            sc.estimate0, q=tuple(a + b for a, b in zip(q0, dq, strict=True)), qd=qd0
        ),
    )
    res = run(sc, library_for(sc), runtime="compiled")
    n, T = res.lib.n, res.lib.T
    e = np.abs(res.x_true[:, :n] - res.q_des)
    div = res.diverged_at is not None
    late = e[int(1.5 / T) :]
    return {
        "place": place,
        "motion": motion,
        "offset": offset,
        "estimator": estimator,
        "startup": startup,
        "diverged": div,
        "initial_error": float(e[0].max()),
        "peak_over_initial": float("inf") if div else float(e.max() - e[0].max()),
        "error_after_1_5s": float("inf") if div or not late.size else float(late.max()),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--blend-accel", type=float, default=20.0)
    ap.add_argument("--blend-rate", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--startups", nargs="+", default=list(STARTUPS))
    args = ap.parse_args(argv)
    jobs = [
        (*j, args.blend_accel, args.blend_rate, args.seed)
        for j in itertools.product(PLACES, MOTION, OFFSETS, ESTIMATORS, args.startups)
        if not j[4].startswith("oracle") or (j[2] == "++" and j[3] == "oosm")  # no estimate
    ]
    with ProcessPoolExecutor(args.workers) as ex:
        rows = list(ex.map(one, jobs, chunksize=4))
    summary = {}
    for st in args.startups:
        r = [x for x in rows if x["startup"] == st]
        summary[st] = {
            "starts": len(r),
            "diverged": sum(x["diverged"] for x in r),
            "peak_over_initial_gt_0_1": sum(x["peak_over_initial"] > 0.1 for x in r),
            "error_after_1_5s_gt_0_1": sum(x["error_after_1_5s"] > 0.1 for x in r),
            "worst_peak_over_initial": max(x["peak_over_initial"] for x in r),
            "median_peak_over_initial": float(np.median([x["peak_over_initial"] for x in r])),
        }
    print(json.dumps(summary, indent=1))
    if args.out:
        doc = {
            "command": "python tools/startup_grid.py " + " ".join(argv or sys.argv[1:]),
            "seed": args.seed,
            "blend_accel": args.blend_accel,
            "blend_rate": args.blend_rate,
            "summary": summary,
            "runs": rows,
        }
        args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
