"""How closely the compiled closed loop reproduces the Python reference: docs/how-to/runtime-c.md.

For every estimator x controller pair of paper-sim (10 s, one seed) it runs

- the C loop (``runtime="compiled"``),
- the Python loop over the library's C estimator (isolates the loop, sensors, controllers),
- the full Python reference (numpy estimators),

and reports the largest difference of every recorded signal (relative to 1 + |reference|),
whether the decisions (counters, divergence time, saturation flags) are equal, and, for the
full reference, the time at which the difference first exceeds 1e-8.  With ``--perturb`` it
also runs the Python reference with the plant's initial link angles moved by 1e-13 rad and
reports the same figures against the unperturbed reference: how much the loop itself
amplifies a last-digit difference.

    .venv/bin/python tools/loop_equivalence.py --out docs/data/loop-equivalence.json --perturb
"""

from __future__ import annotations

import argparse
import json
import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

SIGNALS = ("x_true", "x_hat", "P_diag", "nees", "u", "z_enc", "s", "bound", "frames", "tau_d")
ESTIMATORS = ("encoders", "naive", "oosm", "replay", "cloning")
CONTROLLERS = ("amsfe", "dtsmc", "dtsmc-ekf", "truth", "amsfe-paper", "dtsmc-paper", "truth-ct")


def compare(a: Any, b: Any, T: float) -> dict[str, Any]:
    """Largest relative difference per signal, first time above 1e-8, equal decisions."""
    worst: dict[str, float] = {}
    first = None
    if a.t.size != b.t.size:
        return {"same_length": False, "ticks": [int(a.t.size), int(b.t.size)]}
    per_tick = np.zeros(a.t.size)
    for name in SIGNALS:
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape:
            worst[name] = float("inf")
            continue
        if x.size == 0:
            worst[name] = 0.0
            continue
        d = np.abs(x - y) / (1.0 + np.abs(x))
        d = np.where(np.isnan(x) & np.isnan(y), 0.0, d)
        worst[name] = float(np.nanmax(d))
        if name != "frames" and d.shape[0] == a.t.size:
            per_tick = np.maximum(per_tick, d.reshape(a.t.size, -1).max(axis=1))
    above = np.flatnonzero(per_tick > 1e-8)
    if above.size:
        first = float(above[0] * T)
    return {
        "same_length": True,
        "max_rel_diff": max(worst.values()),
        "worst_signal": max(worst, key=lambda k: worst[k]),
        "first_above_1e-8_s": first,
        "same_decisions": bool(
            a.counters == b.counters
            and a.diverged_at == b.diverged_at
            and np.array_equal(a.saturated, b.saturated)
        ),
    }


def main() -> None:
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper-sim")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--perturb", action="store_true", help="also the 1e-13 rad experiment")
    ap.add_argument("--out", default=None, help="write the table as JSON")
    args = ap.parse_args()
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    base = load_scenario(args.scenario).with_overrides(duration=args.duration, seed=args.seed)
    lib = library_for(base)
    rows = []
    for ctrl in CONTROLLERS:
        for est in ESTIMATORS:
            sc = base.with_overrides(estimator=est, controller=ctrl)
            c = run(sc, lib, runtime="compiled")
            loop = run(sc, lib, compiled_estimator=True)
            ref = run(sc, lib)
            row = {
                "controller": ctrl,
                "estimator": est,
                "ticks": int(c.t.size),
                "diverged_at_s": c.diverged_at,
                "c_vs_python_loop": compare(loop, c, lib.T),
                "c_vs_reference": compare(ref, c, lib.T),
            }
            if args.perturb:
                q0 = tuple(v + 1e-13 for v in sc.plant.q0)
                pert = run(replace(sc, plant=replace(sc.plant, q0=q0)), lib)
                row["reference_vs_perturbed_reference"] = compare(ref, pert, lib.T)
            rows.append(row)
            r = row["c_vs_reference"]
            line = (
                f"{ctrl:12s} {est:9s} loop {row['c_vs_python_loop'].get('max_rel_diff', -1):.1e}"
                f" ref {r.get('max_rel_diff', -1):.1e} (>1e-8 at {r.get('first_above_1e-8_s')})"
            )
            if args.perturb:
                pr = row["reference_vs_perturbed_reference"]
                line += (
                    f" perturbed {pr.get('max_rel_diff', -1):.1e}"
                    f" (>1e-8 at {pr.get('first_above_1e-8_s')})"
                )
            print(line, flush=True)
    if args.out:
        doc = {
            "command": "tools/loop_equivalence.py "
            + f"--scenario {args.scenario} --duration {args.duration:g} --seed {args.seed}"
            + (" --perturb" if args.perturb else ""),
            "rows": rows,
        }
        Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
