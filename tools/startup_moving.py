"""The start-up on moving starts, on fresh seeds, and with the paper's integrator
(docs/explanation/control.md, "Start-up"; issue 28 items 1 and 2).  paper-sim, ``amsfe``, compiled
loop.

Three studies, each over a block of seeds (pick one disjoint from the tuning seeds 700-899):

``grid``: per seed one moving start drawn from the seed: the plant within 0.5 rad of the path
(each joint uniform in [-0.5, 0.5] rad off q_d(0)), moving at a rate vector of length uniform
in [0, pi] rad/s in a uniform direction (the path moves at (pi, 0) rad/s at t = 0); the
estimate 0.4 rad off in angle in a uniform direction and off in rate by a vector of length
uniform in [0, pi] rad/s in a uniform direction.  Run with ``amsfe`` (and its estimator) and
with the oracle ``truth`` (the same law and start-up on the true state) from the same plant
start and seed, 3 s.  The criterion: no ``amsfe`` run diverges where the oracle does not.

``seeds``: paper-sim as shipped (the paper's start), 10 s: divergence, the largest tracking
error after 1.5 s (criterion: below 0.1 rad on every seed), joint-2 RMSE over the last 80 %.

``paper``: as ``seeds`` with ``--set integrator=paper`` (the estimator's model is the paper's
eqs. (1a)-(1d)), with ``oosm`` and ``replay``: divergence and the same metrics.

Every run also records when the start-up trusted the estimate (``ready_s``) and the true
link-angle and -rate errors of the estimate then.  Diverged runs count as +inf in every
statistic, never dropped::

    .venv/bin/python tools/startup_moving.py grid --first-seed 12000 --seeds 200 \\
        --out docs/data/startup-moving-grid.json

An ``--out`` ending in ``.gz`` is written gzip-compressed (the 1000-seed studies).
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

STUDIES = ("grid", "seeds", "paper")


def _start(seed: int) -> tuple[tuple[float, ...], ...]:
    """The grid's moving start of ``seed``: plant q0, qd0, estimate q, qd."""
    rng = np.random.default_rng([28, seed])
    qd_path0 = np.array([0.0, 1.0])  # paper-sim's q_d(0) = (sin 0, cos 0)
    q0 = qd_path0 + rng.uniform(-0.5, 0.5, 2)
    c = rng.uniform(0.0, 2.0 * np.pi)
    qd0 = rng.uniform(0.0, np.pi) * np.array([np.cos(c), np.sin(c)])
    a = rng.uniform(0.0, 2.0 * np.pi)
    b = rng.uniform(0.0, 2.0 * np.pi)
    dq = 0.4 * np.array([np.cos(a), np.sin(a)])
    dqd = rng.uniform(0.0, np.pi) * np.array([np.cos(b), np.sin(b)])
    return (
        tuple(q0.tolist()),
        tuple(qd0.tolist()),
        tuple((q0 + dq).tolist()),
        tuple((qd0 + dqd).tolist()),
    )


def covariance_ready(res: Any, gains: dict[str, Any]) -> np.ndarray:
    """Per tick of ``res``, whether the start-up's covariance tests pass: every link angle's
    and rate's posterior std within ``ready_q_std`` and ``ready_qd_std`` (their defaults
    when the gains do not set them)."""
    n = res.lib.n
    sd = np.sqrt(res.P_diag[:, : 2 * n])
    return np.all(sd[:, :n] <= gains.get("ready_q_std", 0.03), axis=1) & np.all(
        sd[:, n:] <= gains.get("ready_qd_std", np.inf), axis=1
    )


def one(job: tuple[str, int, str, str, float, tuple[str, ...], str]) -> dict[str, Any]:
    """One run and its metrics."""
    study, seed, controller, estimator, duration, sets, runtime = job
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import apply_sets, load_scenario
    from amsfe_sym.sim.loop import run

    sc = load_scenario("paper-sim").with_overrides(
        controller=controller, estimator=estimator, duration=duration, seed=seed
    )
    if study == "paper":
        sc = apply_sets(sc, ["integrator=paper"])
    sc = apply_sets(sc, [s.replace("GAINS.", f"controller_gains.{controller}.") for s in sets])
    if study == "grid":
        q0, qd0, qh, qdh = _start(seed)
        sc = replace(
            sc,
            plant=replace(sc.plant, q0=q0, qd0=qd0),
            estimate0=replace(sc.estimate0, q=qh, qd=qdh),
        )
    res = run(sc, library_for(sc), runtime=runtime)
    n, T = res.lib.n, res.lib.T
    e = np.abs(res.x_true[:, :n] - res.q_des)
    diverged = res.diverged_at is not None
    K = round(duration / T) + 1
    w = slice(int(0.2 * K), len(e))
    rmse = np.sqrt(np.mean(e[w] ** 2, axis=0)) if not diverged else np.full(n, np.inf)
    late = e[int(1.5 / T) :]
    ok = covariance_ready(res, sc.gains_for(controller))
    ready = float(res.t[int(np.argmax(ok))]) if controller != "truth" and ok.any() else None
    out: dict[str, Any] = {
        "study": study,
        "seed": seed,
        "controller": controller,
        "estimator": estimator,
        "diverged": diverged,
        "diverged_at": res.diverged_at,
        "initial_error": float(e[0].max()),
        "peak_over_initial": float(e.max() - e[0].max()) if not diverged else float("inf"),
        "error_after_1_5s": float(late.max()) if late.size and not diverged else float("inf"),
        "rmse": rmse.tolist(),
        "saturated_fraction": float(np.mean(res.saturated)),
        "nees_mean": float(np.mean(res.nees)),
        "ready_s": ready,
    }
    if ready is not None:
        kr = round(ready / T)
        if kr < len(res.t):
            err = res.x_true[kr] - res.x_hat[kr]
            out["ready_q_error"] = float(np.max(np.abs(err[:n])))
            out["ready_qd_error"] = float(np.max(np.abs(err[n : 2 * n])))
            out["ready_nees"] = float(res.nees[kr])
    return out


def _stats(values: list[float]) -> dict[str, float]:
    v = np.sort(np.array(values, dtype=float))
    pct = {f"p{p}": float(np.percentile(v, p, method="lower")) for p in (50, 90, 99)}
    return {**pct, "worst": float(v[-1])}


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    keys = sorted({(r["controller"], r["estimator"]) for r in rows})
    for c, est in keys:
        r = [x for x in rows if x["controller"] == c and x["estimator"] == est]
        out[f"{c}/{est}"] = {
            "runs": len(r),
            "diverged": int(sum(x["diverged"] for x in r)),
            "diverged_seeds": [x["seed"] for x in r if x["diverged"]],
            "late_over_0_1": int(sum(x["error_after_1_5s"] > 0.1 for x in r)),
            "late_over_0_1_seeds": [x["seed"] for x in r if x["error_after_1_5s"] > 0.1],
            "error_after_1_5s_rad": _stats([x["error_after_1_5s"] for x in r]),
            "peak_over_initial_rad": _stats([x["peak_over_initial"] for x in r]),
            "rmse_j2_rad": _stats([x["rmse"][1] for x in r]),
            "nees_mean": _stats([x["nees_mean"] for x in r]),
            "ready_s": _stats([x["ready_s"] for x in r if x["ready_s"] is not None] or [0.0]),
        }
    oracle = {x["seed"]: x for x in rows if x["controller"] == "truth"}
    if oracle and len(oracle) * 2 == len(rows):
        bad = [
            x["seed"]
            for x in rows
            if x["controller"] != "truth" and x["diverged"] and not oracle[x["seed"]]["diverged"]
        ]
        out["diverged_where_oracle_does_not"] = {"count": len(bad), "seeds": bad}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", choices=STUDIES)
    ap.add_argument("--first-seed", type=int, default=6000)
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--duration", type=float, default=None, help="[s] (grid 3, else 10)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--set", dest="sets", action="append", default=[], help="GAINS.key=value")
    ap.add_argument("--runtime", default="compiled", choices=("compiled", "python"))
    ap.add_argument("--controllers", nargs="+", default=None, help="only these (amsfe truth)")
    ap.add_argument("--seed-list", type=int, nargs="+", default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    duration = args.duration or (3.0 if args.study == "grid" else 10.0)
    pairs = {
        "grid": [("amsfe", "oosm"), ("truth", "oosm")],
        "seeds": [("amsfe", "oosm")],
        "paper": [("amsfe", "oosm"), ("amsfe", "replay")],
    }[args.study]
    if args.controllers:
        pairs = [p for p in pairs if p[0] in args.controllers]
    if args.seed_list:
        seeds = args.seed_list
    sets = tuple(args.sets)
    jobs = [(args.study, s, c, e, duration, sets, args.runtime) for s in seeds for c, e in pairs]
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as ex:
            rows = list(ex.map(one, jobs, chunksize=4))
    else:
        rows = [one(j) for j in jobs]
    summary = summarize(rows)
    doc = {
        "command": "python tools/startup_moving.py "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "machine": "2-core shared VM, loaded by other jobs (times are not benchmarks)",
        "scenario": "paper-sim",
        "study": args.study,
        "duration_s": duration,
        "seeds": [seeds[0], seeds[-1]],
        "tuning_seeds": [700, 899],
        "summary": summary,
        "runs": rows,
    }
    print(json.dumps(summary, indent=1))
    if args.out:
        text = json.dumps(doc, indent=1) + "\n"
        if args.out.suffix == ".gz":  # 1000-seed studies: stored compressed (gzip -9 -n alike)
            with args.out.open("wb") as f, gzip.GzipFile(fileobj=f, mode="wb", mtime=0) as z:
                z.write(text.encode())
        else:
            args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
