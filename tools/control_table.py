"""The controller table of docs/explanation/reproduction.md: every (controller, estimator) pair on
one
scenario over many seeds, mean +- std of the closed-loop metrics, in parallel processes.

    .venv/bin/python tools/control_table.py paper-sim --first-seed 1000 --seeds 200 \
        --out docs/data/control-paper-sim.json

On the compiled loop (``--runtime python`` for the reference loop: the same statistics,
docs/how-to/runtime-c.md).

Metrics (after the transient: the last 80 % of each run): tracking RMSE and max error per
joint [rad], RMS torque [N m], chattering as the total variation of u per second [N m/s],
the fraction of saturated ticks, and how many runs diverged, with when. A diverged run counts
as +inf in every statistic, never dropped (issue 28): a row with a divergence has mean inf
(and no std), and its medians are over every run.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
from pathlib import Path
from typing import Any

import numpy as np

PAIRS = (
    ("amsfe", "oosm"),
    ("amsfe", "replay"),
    ("amsfe", "encoders"),
    ("dtsmc-ekf", "encoders"),
    ("dtsmc", "oosm"),
    ("truth", "oosm"),
    ("amsfe-paper", "oosm"),
)


def run_once(
    scenario: str,
    ctrl: str,
    est: str,
    seed: int,
    duration: float | None,
    gains: dict[str, float] | None = None,
    runtime: str = "python",
) -> dict[str, Any]:
    """``summary.json`` of one run: ``scenario`` with controller ``ctrl`` (its gains updated by
    ``gains``), estimator ``est`` and ``seed`` (also used by tools/tune_controllers.py)."""
    from dataclasses import replace

    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    sc = load_scenario(scenario).with_overrides(
        controller=ctrl, estimator=est, seed=seed, duration=duration
    )
    if gains:
        sc = replace(sc, controller_gains={ctrl: {**sc.gains_for(ctrl), **gains}})
    return summarize(run(sc, library_for(sc), runtime=runtime))


def _one(job: tuple[str, str, str, int, float | None, str]) -> dict[str, Any]:
    scenario, ctrl, est, seed, duration, runtime = job
    s = run_once(scenario, ctrl, est, seed, duration, runtime=runtime)
    return {
        "controller": ctrl,
        "estimator": est,
        "seed": seed,
        **s["control"],
        "diverged_at_s": s["diverged_at_s"],
        "estimation_rmse_q": s["estimation_rmse"]["q"],
    }


def _values(rows: list[dict[str, Any]], key: str) -> np.ndarray:
    """``key`` of every run, (runs, width); a diverged run's values are +inf."""
    ok = [r for r in rows if r["diverged_at_s"] is None]
    width = np.asarray(ok[0][key], dtype=float).size if ok else 1
    return np.array(
        [r[key] if r["diverged_at_s"] is None else [np.inf] * width for r in rows], dtype=float
    ).reshape(len(rows), width)


def _stat(rows: list[dict[str, Any]], key: str) -> tuple[list[float], list[float]]:
    """Mean and std over every run; with a diverged run the mean is inf and the std NaN."""
    v = _values(rows, key)
    if np.isinf(v).any():
        return np.full(v.shape[1], np.inf).tolist(), np.full(v.shape[1], np.nan).tolist()
    return v.mean(axis=0).tolist(), v.std(axis=0).tolist()


def print_table(scenario: str, seeds: int, pairs: tuple, rows: list[dict[str, Any]]) -> list:
    """Print the markdown table; return its entries (means and stds per controller)."""
    table = []
    print(f"{scenario}: {seeds} seeds; mean ± std (and median); a diverged run counts as inf")
    print(
        "| controller | estimator | diverged | tracking RMSE [mrad] | median RMSE [mrad] | "
        "max error [mrad] | RMS u [N m] | TV(u) [N m/s] | saturated [%] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for c, e in pairs:
        rs = [r for r in rows if r["controller"] == c and r["estimator"] == e]
        ok = [r for r in rs if r["diverged_at_s"] is None]
        div = [r["diverged_at_s"] for r in rs if r["diverged_at_s"] is not None]
        entry: dict[str, Any] = {
            "controller": c,
            "estimator": e,
            "runs": len(rs),
            "diverged": len(div),
        }
        when = f" (t = {min(div):.2f}-{max(div):.2f} s)" if div else ""
        if div:
            entry["diverged_at_s"] = [min(div), max(div)]
        if not ok:  # every run diverged: every statistic is inf
            print(f"| {c} | {e} | {len(rs)}/{len(rs)}{when} | inf | inf | inf | inf | inf | inf |")
            table.append(entry)
            continue
        for key in (
            "tracking_rmse",
            "tracking_max_error",
            "u_rms",
            "u_total_variation_per_s",
            "saturated_fraction",
        ):
            entry[key] = _stat(rs, key)
        med = np.median(_values(rs, "tracking_rmse"), axis=0)
        entry["tracking_rmse_median"] = med.tolist()

        def fmt(key: str, scale: float = 1.0, digits: int = 2, entry: dict = entry) -> str:
            m, sd = entry[key]
            return " / ".join(
                "inf" if np.isinf(a) else f"{scale * a:.{digits}f} ± {scale * b:.{digits}f}"
                for a, b in zip(m, sd, strict=True)
            )

        print(
            f"| {c} | {e} | {len(div)}/{len(rs)}{when} | {fmt('tracking_rmse', 1e3)} | "
            + " / ".join("inf" if np.isinf(v) else f"{1e3 * v:.2f}" for v in med)
            + f" | {fmt('tracking_max_error', 1e3)} | {fmt('u_rms', 1, 1)} | "
            f"{fmt('u_total_variation_per_s', 1, 0)} | {fmt('saturated_fraction', 100, 1)} |"
        )
        table.append(entry)
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--runtime", default="compiled", choices=("compiled", "python"))
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--pairs", default=None, help="ctrl/est,ctrl/est (default: all)")
    ap.add_argument("--out", default=None, help="JSON with every run's row and the table")
    ap.add_argument("--from-json", default=None, help="re-print the table of a saved JSON")
    args = ap.parse_args()
    if args.from_json:
        d = json.loads(Path(args.from_json).read_text())
        pairs = tuple(dict.fromkeys((r["controller"], r["estimator"]) for r in d["runs"]))
        print_table(d["scenario"], d["seeds"], pairs, d["runs"])
        return
    pairs = tuple(tuple(p.split("/")) for p in args.pairs.split(",")) if args.pairs else PAIRS
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    jobs = [(args.scenario, c, e, s, args.duration, args.runtime) for c, e in pairs for s in seeds]
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario

    library_for(load_scenario(args.scenario))  # build once before the workers start
    with mp.get_context("spawn").Pool(args.workers) as pool:
        rows = pool.map(_one, jobs, chunksize=1)
    table = print_table(args.scenario, args.seeds, pairs, rows)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(
            json.dumps(
                {
                    "scenario": args.scenario,
                    "seeds": args.seeds,
                    "first_seed": args.first_seed,
                    "runtime": args.runtime,
                    "table": table,
                    "runs": rows,
                },
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
