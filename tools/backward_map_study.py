"""oosm's two backward maps (eq. (24)), paired by seed: ``[filter] backward_map =
"linearised"`` (about the stored forward pass) against ``"inverse"`` (the paper's eq. (22):
``L`` generated inverse transitions, the jacobian at the retrodicted states).
Reported in docs/explanation/estimation-algorithms.md ("The backward map"), written to
docs/data/backward-map.json.

Per scenario (paper-sim, panda-control, and paper-sim with the paper's own explicit-Euler
integrator in the estimator: the amsfe closed loop with oosm, on the compiled loop, through
``amsfe study``'s machinery with one variant per map) and seed:

- estimation RMSE of the link angles q [mrad] and rates qd [mrad/s] over the last 80 % of
  the run (root mean square over the joints), and the mean NEES over that window (N dof);
- divergences (the loop stopped) and failed runs: counted, and their RMSE and NEES count as
  +inf in every statistic (never dropped);
- frames applied and frames refused because an inverse did not converge.

Per map: median, p90, worst.  Per pair (inverse - linearised, same seed): the median of the
differences with a bootstrap 95 % interval (2000 resamples of the seeds), and how many seeds
each map is better on.  Cost per late frame: one recorded run per scenario replayed through
both compiled estimators, interleaved frame by frame in one process, each
``amsfe_est_camera_frame`` call timed with ``perf_counter_ns`` (ctypes call included, the same
for both): median ns and the ratio inverse / linearised.

Seeds 7000-7199 by default: disjoint from every tuning block of the project (0-739).  Run at
low priority, one worker (the machine is shared)::

    nice -n 10 .venv/bin/python tools/backward_map_study.py --first-seed 7000 --seeds 200 \\
        --out docs/data/backward-map.json
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

MAPS = ("linearised", "inverse")
SCENARIOS = ("paper-sim", "panda-control", "paper-sim+integrator=paper")
METRICS = ("q_rmse_mrad", "qd_rmse_mrad_s", "nees_mean")


def run_metrics(summary: dict[str, Any]) -> dict[str, Any]:
    """The per-run numbers of one study summary (inf for a diverged or failed run)."""
    failed = bool(summary.get("failed"))
    diverged = failed or summary.get("diverged_at_s") is not None
    out: dict[str, Any] = {"seed": int(summary["seed"]), "diverged": diverged, "failed": failed}
    if diverged:
        out.update({m: math.inf for m in METRICS})
    else:
        rm = summary["estimation_rmse"]
        out["q_rmse_mrad"] = 1e3 * float(np.sqrt(np.mean(np.square(rm["q"]))))
        out["qd_rmse_mrad_s"] = 1e3 * float(np.sqrt(np.mean(np.square(rm["qd"]))))
        out["nees_mean"] = float(summary["nees_mean"])
    counters = summary.get("counters", {})
    out["frames_applied"] = int(counters.get("frames_applied", 0))
    out["refused_no_convergence"] = int(counters.get("refused_no_convergence", 0))
    return out


def spread(v: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(v)),
        "p90": float(np.percentile(v, 90, method="lower")),
        "worst": float(np.max(v)),
    }


def paired(a: np.ndarray, b: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """``b - a`` by seed: median with a bootstrap 95 % interval; seeds where each is lower.
    Both diverged: a tie (0); one diverged: +-inf."""
    d = np.where(np.isinf(a) & np.isinf(b), 0.0, b - a)
    idx = rng.integers(0, d.size, size=(2000, d.size))
    boot = np.median(d[idx], axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5], method="lower")
    verdict = "indistinguishable" if lo <= 0.0 <= hi else ("lower" if hi < 0 else "higher")
    return {
        "median": float(np.median(d)),
        "ci95": [float(lo), float(hi)],
        "mean": float(np.mean(d)) if np.isfinite(d).all() else None,
        "max_abs": float(np.max(np.abs(d))),
        "inverse_lower_on": int(np.sum(d < 0)),
        "linearised_lower_on": int(np.sum(d > 0)),
        "equal_on": int(np.sum(d == 0)),
        "inverse_vs_linearised": verdict,
    }


def parse_spec(spec: str) -> tuple[str, list[str]]:
    """``NAME[+KEY=VALUE...]`` -> (scenario name, --set overrides)."""
    name, *sets = spec.split("+")
    return name, sets


def late_frame_cost(spec: str, seed: int) -> dict[str, Any]:
    """One compiled run recorded, replayed through both compiled estimators (interleaved):
    ns per ``amsfe_est_camera_frame`` of a late frame."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import apply_sets, load_scenario
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.loop import run

    scenario, sets = parse_spec(spec)
    base = apply_sets(load_scenario(scenario), sets).with_overrides(seed=seed)
    lib = library_for(base)
    res = run(base, lib, runtime="compiled")
    ests = {}
    for m in MAPS:
        sc = apply_sets(base, [f"filter.backward_map={m}"])
        ests[m] = build_run(sc, lib, compiled=True).estimator
    frames: dict[int, list[tuple[int, np.ndarray]]] = {}
    for kappa, k, zu, zv in res.frames:
        frames.setdefault(int(k), []).append((int(kappa), np.array([zu, zv])))
    ns: dict[str, list[int]] = {m: [] for m in MAPS}
    lags: list[int] = []
    nis = ctypes.c_double()
    # the C calls directly (the estimators' ctypes bindings), so that only the late frame is
    # timed: CompiledEstimator.step would add its Python bookkeeping to both
    for k in range(len(res.t) - 1):
        u = np.ascontiguousarray(res.u[k], dtype=np.float64)
        z = np.ascontiguousarray(res.z_enc[k + 1], dtype=np.float64)
        for m in MAPS:
            est = ests[m]
            est._c["amsfe_est_tick"](est._h, z.ctypes.data, u.ctypes.data)
        for kappa, zc in sorted(frames.get(k + 1, []), key=lambda f: f[0]):
            if kappa == k + 1:
                continue
            lags.append(k + 1 - kappa)
            for m in MAPS:
                est = ests[m]
                t0 = time.perf_counter_ns()
                st = est._c["amsfe_est_camera_frame"](
                    est._h, zc.ctypes.data, kappa, ctypes.byref(nis)
                )
                ns[m].append(time.perf_counter_ns() - t0)
                if st < 0:
                    raise RuntimeError(f"{scenario} {m}: status {st} at step {k + 1}")
    med = {m: float(np.median(ns[m])) for m in MAPS}
    return {
        "seed": seed,
        "frames": len(lags),
        "lag_steps": int(np.median(lags)) if lags else None,
        "N": int(lib.N),
        "median_ns": med,
        "p90_ns": {m: float(np.percentile(ns[m], 90)) for m in MAPS},
        "ratio_inverse_over_linearised": med["inverse"] / med["linearised"],
    }


def study(spec: str, first_seed: int, seeds: int, workers: int, folder: Path) -> dict:
    from amsfe_sym.apps.study.runner import run_study

    scenario, sets = parse_spec(spec)
    res = run_study(
        scenario,
        seeds=seeds,
        estimators="oosm",
        workers=workers,
        out=folder / spec.replace("+", "_").replace("=", "-"),
        sets=sets,
        variants={m: [f"filter.backward_map={m}"] for m in MAPS},
        first_seed=first_seed,
        progress=True,
    )
    per: dict[str, list[dict[str, Any]]] = {m: [] for m in MAPS}
    for s in res.runs:
        per[str(s["variant"])].append(run_metrics(s))
    for m in MAPS:
        per[m].sort(key=lambda r: r["seed"])
    assert [r["seed"] for r in per["linearised"]] == [r["seed"] for r in per["inverse"]]
    rng = np.random.default_rng(28)
    out: dict[str, Any] = {"maps": {}, "paired_inverse_minus_linearised": {}}
    for m in MAPS:
        rows = per[m]
        out["maps"][m] = {
            "runs": len(rows),
            "diverged": sum(r["diverged"] for r in rows),
            "failed": sum(r["failed"] for r in rows),
            "frames_applied": sum(r["frames_applied"] for r in rows),
            "refused_no_convergence": sum(r["refused_no_convergence"] for r in rows),
            **{k: spread(np.array([r[k] for r in rows])) for k in METRICS},
        }
    for k in METRICS:
        a = np.array([r[k] for r in per["linearised"]])
        b = np.array([r[k] for r in per["inverse"]])
        out["paired_inverse_minus_linearised"][k] = paired(a, b, rng)
    out["runs"] = per
    return out


def table(doc: dict[str, Any]) -> str:
    lines = [
        "| scenario | map | diverged | refused (no conv.) | q RMSE median / p90 / worst "
        "[mrad] | qd RMSE median / p90 / worst [mrad/s] | NEES median / p90 / worst | "
        "late frame [us] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for sc, r in doc["scenarios"].items():
        cost = r["late_frame_cost"]
        for m in MAPS:
            s = r["maps"][m]

            def f(k: str, s: dict[str, Any] = s) -> str:
                return " / ".join(f"{s[k][q]:.4g}" for q in ("median", "p90", "worst"))

            lines.append(
                f"| {sc} | {m} | {s['diverged']} / {s['runs']} | {s['refused_no_convergence']} "
                f"| {f('q_rmse_mrad')} | {f('qd_rmse_mrad_s')} | {f('nees_mean')} "
                f"| {cost['median_ns'][m] / 1e3:.1f} |"
            )
    lines += [
        "",
        "| scenario | paired inverse - linearised | median | 95 % interval | inverse lower on "
        "| verdict |",
        "|---|---|---|---|---|---|",
    ]
    for sc, r in doc["scenarios"].items():
        for k in METRICS:
            p = r["paired_inverse_minus_linearised"][k]
            lines.append(
                f"| {sc} | {k} | {p['median']:.3g} | [{p['ci95'][0]:.3g}, {p['ci95'][1]:.3g}] "
                f"| {p['inverse_lower_on']} / {r['maps']['inverse']['runs']} "
                f"| {p['inverse_vs_linearised']} |"
            )
        c = r["late_frame_cost"]
        lines.append(
            f"| {sc} | late frame cost (ratio) | {c['ratio_inverse_over_linearised']:.2f} x | "
            f"lag {c['lag_steps']} steps, N = {c['N']}, {c['frames']} frames | | |"
        )
    return "\n".join(lines)


def finite_json(x: Any) -> Any:
    """``x`` with every non-finite float written as the string "inf" / "-inf" / "nan"."""
    if isinstance(x, dict):
        return {k: finite_json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite_json(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first-seed", type=int, default=7000)
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--scenarios",
        default=",".join(SCENARIOS),
        help="comma-separated NAME[+KEY=VALUE...] (e.g. paper-sim+integrator=paper)",
    )
    ap.add_argument("--out", type=Path, default=Path("docs/data/backward-map.json"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    doc: dict[str, Any] = {
        "command": "nice -n 10 .venv/bin/python tools/backward_map_study.py "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": f"{platform.machine()}, 2-core shared VM loaded by other jobs",
        "seeds": [args.first_seed, args.first_seed + args.seeds - 1],
        "window": "last 80 % of each run",
        "scenarios": {},
    }
    with tempfile.TemporaryDirectory(prefix="backward-map-") as tmp:
        for sc in args.scenarios.split(","):
            r = study(sc, args.first_seed, args.seeds, args.workers, Path(tmp))
            r["late_frame_cost"] = late_frame_cost(sc, args.first_seed)
            doc["scenarios"][sc] = r
            print(f"{sc}: done at {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    doc["wall_time_s"] = round(time.perf_counter() - t0, 1)
    doc["table_md"] = table(doc)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(finite_json(doc), indent=1, allow_nan=False) + "\n")
    print(doc["table_md"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
