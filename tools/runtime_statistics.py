"""The two runtimes over many seeds on the loops that amplify last-digit differences
(docs/how-to/runtime-c.md): per seed, the compiled and the Python reference run of `amsfe` + `oosm`
on paper-sim give different sample paths after a few seconds; this prints how their metrics
compare over seeds (median, and the paired differences).

    .venv/bin/python tools/runtime_statistics.py --seeds 10
"""

from __future__ import annotations

import argparse
import logging

import numpy as np


def main() -> None:
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper-sim")
    ap.add_argument("--controller", default="amsfe")
    ap.add_argument("--estimator", default="oosm")
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    base = load_scenario(args.scenario).with_overrides(
        controller=args.controller, estimator=args.estimator
    )
    lib = library_for(base)
    rows: dict[str, list[list[float]]] = {"compiled": [], "python": []}
    for seed in range(args.seeds):
        for rt in rows:
            s = summarize(run(base.with_overrides(seed=seed), lib, runtime=rt))
            diverged = s["diverged_at_s"] is not None
            track = s["control"]["tracking_rmse"] if not diverged else [np.nan, np.nan]
            rows[rt].append([*track, *s["estimation_rmse"]["q"], float(diverged)])
        c, p = rows["compiled"][-1], rows["python"][-1]
        print(
            f"seed {seed}: tracking [mrad] C {np.round(1e3 * np.array(c[:2]), 2)} "
            f"Py {np.round(1e3 * np.array(p[:2]), 2)}; est q [mrad] C "
            f"{np.round(1e3 * np.array(c[2:4]), 3)} Py {np.round(1e3 * np.array(p[2:4]), 3)}",
            flush=True,
        )
    for rt, r in rows.items():
        a = np.array(r)
        print(
            f"{rt:9s} median tracking {np.round(1e3 * np.nanmedian(a[:, :2], axis=0), 2)} mrad, "
            f"estimation q {np.round(1e3 * np.median(a[:, 2:4], axis=0), 3)} mrad, "
            f"diverged {int(a[:, 4].sum())}/{len(a)}"
        )


if __name__ == "__main__":
    main()
