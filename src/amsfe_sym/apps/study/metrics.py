"""The study's metrics over seeds: theta settling, mean +- std, NEES bands, and the markdown
tables of ``study.md``."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.sim.record import nees_band, window

__all__ = ["THETA_SETTLE_REL", "aggregate", "format_block_table", "format_table", "settle_time"]

FloatArray = NDArray[np.float64]

#: A theta estimate has "settled" once it stays within this fraction of the true value.
THETA_SETTLE_REL = 0.10


def settle_time(
    t: FloatArray, est: FloatArray, true: float, rel: float = THETA_SETTLE_REL
) -> float:
    """First time after which ``|est - true| <= rel |true|`` for the rest of the run (NaN if
    the last sample is outside).  ``true == 0`` uses an absolute tolerance ``rel``."""
    tol = rel * abs(true) if true != 0 else rel
    outside = np.abs(est - true) > tol
    if outside[-1]:
        return math.nan
    idx = np.flatnonzero(outside)
    return float(t[0]) if idx.size == 0 else float(t[idx[-1] + 1])


def _mean_std(values: Sequence[Sequence[float]] | FloatArray) -> dict[str, list[float]]:
    a = np.asarray(values, dtype=float)
    return {
        "mean": np.mean(a, axis=0).tolist(),
        "std": (np.std(a, axis=0, ddof=1) if a.shape[0] > 1 else np.zeros(a.shape[1])).tolist(),
    }


def aggregate(
    summaries: Sequence[Mapping[str, Any]],
    nees: FloatArray,
    theta_hat: FloatArray,
    t: FloatArray,
    theta_true: Sequence[float],
) -> dict[str, Any]:
    """Metrics of one (variant, estimator) over its seeds.

    Args:
        summaries: The runs' summaries (``simulate.summarize`` + ``theta_settle_s``).
        nees: NEES series, (M, K).
        theta_hat: theta estimates, (M, K, p).
        t: Times, (K,).
        theta_true: True theta, (p,).
    """
    M, K = nees.shape
    dof = int(summaries[0]["nees_dof"])
    lo, hi = nees_band(dof, M)
    w = window(K)
    avg = nees.mean(axis=0)
    er = [s["estimation_rmse"] for s in summaries]
    settle = np.array([s["theta_settle_s"] for s in summaries], dtype=float).reshape(M, -1)
    marks = [tm for tm in (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0) if tm < t[-1]]
    marks.append(float(t[-1]))
    idx = [min(int(np.searchsorted(t, tm)), K - 1) for tm in marks]
    counters = {
        key: float(np.mean([s["counters"].get(key, 0) for s in summaries]))
        for key in summaries[0]["counters"]
    }
    return {
        "seeds": [int(s["seed"]) for s in summaries],
        "M": M,
        "rmse_q": _mean_std([e["q"] for e in er]),
        "rmse_qd": _mean_std([e["qd"] for e in er]),
        "rmse_theta": _mean_std([e["theta"] for e in er]),
        "tracking_q": _mean_std([s["tracking_rmse"]["q"] for s in summaries]),
        "cost_per_tick_us_median": float(np.median([s["cost_per_tick_us"] for s in summaries])),
        "cost_per_tick_us_iqr": [
            float(v) for v in np.percentile([s["cost_per_tick_us"] for s in summaries], [25, 75])
        ],
        "nees_time_avg": _mean_std([[s["nees_mean"]] for s in summaries]),
        "nees_dof": dof,
        "nees_band95": [lo, hi],
        "avg_nees_window_mean": float(avg[w].mean()),
        "avg_nees_in_band_fraction": float(np.mean((avg[w] >= lo) & (avg[w] <= hi))),
        "avg_nees_below_band_fraction": float(np.mean(avg[w] < lo)),
        "avg_nees_above_band_fraction": float(np.mean(avg[w] > hi)),
        "theta_true": [float(v) for v in theta_true],
        "theta_final": _mean_std(theta_hat[:, -1, :]),
        "theta_mean_at": {
            f"{float(t[i]):g}": np.mean(theta_hat[:, i, :], axis=0).tolist() for i in idx
        },
        "theta_settle_rel": THETA_SETTLE_REL,
        "theta_settle_s_median": np.nanmedian(settle, axis=0).tolist()
        if np.any(np.isfinite(settle))
        else [math.nan] * settle.shape[1],
        "theta_settle_s_max": np.max(settle, axis=0).tolist(),
        "theta_not_settled": np.sum(~np.isfinite(settle), axis=0).astype(int).tolist(),
        "counters_mean": counters,
        "nes_block_mean": {
            b: float(np.mean([s["nes_block"][b] for s in summaries]))
            for b in summaries[0].get("nes_block", {})
        },
    }


def _pm(ms: Mapping[str, list[float]], scale: float, digits: int = 3) -> str:
    return " / ".join(
        f"{m * scale:.{digits}g} ± {s * scale:.2g}"
        for m, s in zip(ms["mean"], ms["std"], strict=True)
    )


def format_table(agg: Mapping[str, Mapping[str, Any]], theta_unit: str = "") -> str:
    """Markdown table of one variant: a row per estimator (see the module docstring)."""
    full = [a for a in agg.values() if a.get("M")]
    lo, hi = full[0]["nees_band95"] if full else (math.nan, math.nan)
    tu = f" [{theta_unit}]" if theta_unit else ""
    head = (
        "| estimator | q RMSE [mrad] | qd RMSE [mrad/s] | theta RMSE"
        + tu
        + " | tracking RMSE [mrad] | cost/tick [us] (median) | NEES (time avg) "
        + f"| avg NEES in 95% band [{lo:.2f}, {hi:.2f}] | theta settle [s] | frames used |"
    )
    rows = [head, "|" + "---|" * 10]
    for name, a in agg.items():
        if not a.get("M"):
            msg = (a.get("errors") or ["?"])[0].replace("|", "/")
            rows.append(f"| {name} | all runs failed: {msg} |" + " |" * 8)
            continue
        if a.get("failed_seeds"):
            name = f"{name} ({len(a['failed_seeds'])} runs failed, M = {a['M']})"
        c = a["counters_mean"]
        st = a["theta_settle_s_median"]
        ns = a["theta_not_settled"]
        settle = " / ".join(
            ("–" if not math.isfinite(v) else f"{v:.2f}") + (f" ({k} never)" if k else "")
            for v, k in zip(st, ns, strict=True)
        )
        rows.append(
            f"| {name} | {_pm(a['rmse_q'], 1e3)} | {_pm(a['rmse_qd'], 1e3)} "
            f"| {_pm(a['rmse_theta'], 1.0)} | {_pm(a['tracking_q'], 1e3)} "
            f"| {a['cost_per_tick_us_median']:.0f} | {_pm(a['nees_time_avg'], 1.0)} "
            f"| {100 * a['avg_nees_in_band_fraction']:.0f} % "
            f"(mean {a['avg_nees_window_mean']:.2f}) | {settle} "
            f"| {c.get('frames_applied', 0):.1f} / {c.get('frames_delivered', 0):.1f} |"
        )
    return "\n".join(rows) + "\n"


def format_block_table(agg: Mapping[str, Mapping[str, Any]]) -> str:
    """Markdown table of the per-block normalised error squared ``e_i^2 / P_ii``."""
    full = {k: a for k, a in agg.items() if a.get("M")}
    if not full:
        return ""
    blocks = list(next(iter(full.values()))["nes_block_mean"])
    rows = [
        "| estimator | " + " | ".join(blocks) + " |",
        "|---|" + "---|" * len(blocks),
    ]
    for name, a in full.items():
        b = a["nes_block_mean"]
        rows.append(f"| {name} | " + " | ".join(f"{b[k]:.3g}" for k in blocks) + " |")
    return "\n".join(rows) + "\n"
