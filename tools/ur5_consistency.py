"""Is the UR5 filter consistent under the controllers it ships with?  (issue 17, item 1)

Per run of ``ur5-control`` (oosm, compiled loop): the time-averaged NEES over the metric
window (the last 80 % of the run) and, for every state, the time average of e_i^2 / P_ii
(1 for a consistent filter).  Runs each controller with the estimator's rk4 model at the
given ``model_substeps`` (the UR5 spec's value replaced), paired by seed, and writes
docs/data/ur5-consistency.{json,md}.

Seed sets: ``model_substeps = 4`` was chosen on seeds 0-1 (tuning); the default test seeds
2000-2199 were never used for any choice::

    .venv/bin/python tools/ur5_consistency.py --seeds 2000-2199 --substeps 1 4 \\
        --controllers amsfe dtsmc truth truth-ct
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "data" / "ur5-consistency"
BAND = (0.8, 1.25)  # issue 17's target band for NEES / N


def one(job: tuple[int, str, int, float]) -> dict[str, Any]:
    seed, controller, m, duration = job
    from amsfe_sym.codegen import library_for
    from amsfe_sym.load.spec import load_spec
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import window

    spec = load_spec("ur5")
    if m != spec.model.model_substeps:
        spec = dataclasses.replace(
            spec, name=f"ur5_m{m}", model=dataclasses.replace(spec.model, model_substeps=m)
        )
    sc = load_scenario("ur5-control").with_overrides(
        controller=controller, estimator="oosm", duration=duration, seed=seed
    )
    res = run(sc, library_for(sc, robot=spec), runtime="compiled")
    w = window(res.t.size)
    diverged = res.diverged_at is not None
    e = (res.x_true - res.x_hat)[w]
    n, N = res.lib.n, res.lib.N
    return {
        "seed": seed,
        "controller": controller,
        "model_substeps": m,
        "diverged": diverged,
        "nees_over_N": float(np.mean(res.nees[w])) / N if not diverged else float("inf"),
        "ratio": np.mean(e**2 / res.P_diag[w], axis=0).tolist(),
        "qd_rmse": np.sqrt(np.mean(e[:, n : 2 * n] ** 2, axis=0)).tolist(),
        "track_rmse": np.sqrt(np.mean((res.x_true[w, :n] - res.q_des[w]) ** 2, axis=0)).tolist(),
    }


def _compact(value: Any) -> Any:
    """Rows with 3 significant digits (the data file stays small)."""
    if isinstance(value, float):
        return float(f"{value:.3g}")
    if isinstance(value, list):
        return [_compact(v) for v in value]
    if isinstance(value, dict):
        return {k: _compact(v) for k, v in value.items()}
    return value


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson interval of a proportion k / n."""
    p = k / n
    c = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    return float(mid - c), float(mid + c)


def summarize(rows: list[dict[str, Any]], names: list[str]) -> list[dict[str, Any]]:
    out = []
    keys = sorted({(r["controller"], r["model_substeps"]) for r in rows})
    rng = np.random.default_rng(0)
    for c, m in keys:
        rs = [r for r in rows if r["controller"] == c and r["model_substeps"] == m]
        v = np.array([r["nees_over_N"] for r in rs])
        inside = int(np.sum((v >= BAND[0]) & (v <= BAND[1])))
        ratio = np.array([r["ratio"] for r in rs if not r["diverged"]])
        boot = np.median(rng.choice(v, size=(2000, v.size)), axis=1)
        worst = {names[i]: float(np.percentile(ratio[:, i], 90)) for i in range(ratio.shape[1])}
        out.append(
            {
                "controller": c,
                "model_substeps": m,
                "runs": len(rs),
                "diverged": int(sum(r["diverged"] for r in rs)),
                "nees_over_N": {
                    "median": float(np.median(v)),
                    "median_ci95": [
                        float(np.percentile(boot, 2.5)),
                        float(np.percentile(boot, 97.5)),
                    ],
                    "p10": float(np.percentile(v, 10)),
                    "p90": float(np.percentile(v, 90)),
                    "worst": float(np.max(v)),
                    "worst_seed": int(rs[int(np.argmax(v))]["seed"]),
                },
                "in_band": inside,
                "in_band_ci95": _wilson(inside, len(rs)),
                "ratio_median": {
                    names[i]: float(np.median(ratio[:, i])) for i in range(len(names))
                },
                "ratio_p90": worst,
                "qd_rmse_median": np.median(
                    np.array([r["qd_rmse"] for r in rs if not r["diverged"]]), axis=0
                ).tolist(),
            }
        )
    return out


def markdown(summary: list[dict[str, Any]], meta: dict[str, Any], names: list[str]) -> str:
    n = (len(names) - 1) // 4
    lines = [
        "# UR5 filter consistency under its own controllers",
        "",
        "<!-- written by tools/ur5_consistency.py; edit the script, not this page -->",
        "",
        f"Command: `{meta['command']}`  ",
        f"Machine: {meta['machine']}; {meta['wall_s']:.0f} s wall.  Seeds {meta['seeds']} "
        "(test seeds: `model_substeps = 4` was chosen on seeds 0-1); ur5-control, oosm, "
        f"compiled loop, {meta['duration']} s, metrics over the last 80 %.  NEES/N: the "
        f"time-averaged NEES over N = {len(names)}; in band: {BAND[0]} <= NEES/N <= {BAND[1]} "
        "(issue 17's target: >= 90 % of seeds), with a 95 % Wilson interval.  A diverged run "
        "counts as NEES/N = inf.",
        "",
        "| controller | model_substeps | runs | diverged | NEES/N median [95 % CI] | p10 | p90 "
        "| worst (seed) | in band | in band 95 % CI |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summary:
        v = s["nees_over_N"]
        lines.append(
            f"| {s['controller']} | {s['model_substeps']} | {s['runs']} | {s['diverged']} | "
            f"{v['median']:.2f} [{v['median_ci95'][0]:.2f}, {v['median_ci95'][1]:.2f}] | "
            f"{v['p10']:.2f} | {v['p90']:.2f} | {v['worst']:.2f} ({v['worst_seed']}) | "
            f"{s['in_band']}/{s['runs']} | {100 * s['in_band_ci95'][0]:.0f}-"
            f"{100 * s['in_band_ci95'][1]:.0f} % |"
        )
    lines += [
        "",
        "Per state, e_i^2 / P_ii time-averaged per run: median over seeds / 90th percentile "
        "(1 = consistent; q6, qd6, qm6, qmd6 are wrist 3):",
        "",
        "| controller | m | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for s in summary:
        lines.append(
            f"| {s['controller']} | {s['model_substeps']} | "
            + " | ".join(f"{s['ratio_median'][k]:.2f} / {s['ratio_p90'][k]:.1f}" for k in names)
            + " |"
        )
    lines += [
        "",
        "Median RMS estimation error of the link rates qd1..qd6 [rad/s]:",
        "",
        "| controller | m | " + " | ".join(f"qd{i + 1}" for i in range(n)) + " |",
        "|---|---|" + "---|" * n,
    ]
    for s in summary:
        lines.append(
            f"| {s['controller']} | {s['model_substeps']} | "
            + " | ".join(f"{v:.3f}" for v in s["qd_rmse_median"])
            + " |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="2000-2199")
    ap.add_argument("--substeps", type=int, nargs="+", default=[1, 4])
    ap.add_argument("--controllers", nargs="+", default=["amsfe", "dtsmc", "truth", "truth-ct"])
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    jobs = [
        (s, c, m, a.duration) for m in a.substeps for c in a.controllers for s in _seeds(a.seeds)
    ]
    for m in a.substeps:  # build each library once, before the workers race for it
        one((0, a.controllers[0], m, 0.01))
    t0 = time.time()
    with ProcessPoolExecutor(a.workers) as ex:
        rows = list(ex.map(one, jobs, chunksize=4))
    n = 6
    names = (
        [f"q{i + 1}" for i in range(n)]
        + [f"qd{i + 1}" for i in range(n)]
        + [f"qm{i + 1}" for i in range(n)]
        + [f"qmd{i + 1}" for i in range(n)]
        + ["theta"]
    )
    summary = summarize(rows, names)
    meta = {
        "command": "python tools/ur5_consistency.py " + " ".join(argv or sys.argv[1:]),
        "machine": f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}",
        "seeds": a.seeds,
        "duration": a.duration,
        "wall_s": time.time() - t0,
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "summary": summary, "rows": _compact(rows)}) + "\n"
    )
    md = markdown(summary, meta, names)
    a.out.with_suffix(".md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
