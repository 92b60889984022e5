"""Claims as effect sizes: paired differences with bootstrap intervals, on two seed blocks.

A claim of docs/explanation/reproduction.md compares two rows of the claim table (a vs b, the same
seeds). Its effect on one block of seeds is the median over seeds of the paired difference
of tracking RMSE, a - b [rad], with a bootstrap 95 % interval (2000 resamples of the seeds,
fixed generator). A diverged run counts as +inf RMSE, never dropped: a seed where only a
diverged gives +inf, only b -inf, both 0 (a tie); medians and percentiles are order
statistics (``method="lower"`` / ``"higher"``), so they stay defined.

Verdict on one block: ``"a lower"`` when the whole interval is below zero, ``"a higher"``
above, ``"indistinguishable"`` when it spans zero. Stated (:func:`combine`) only where both
blocks give the same verdict; otherwise ``"not reproduced"``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["N_BOOT", "combine", "format_effects", "pair_effects", "paired_effect", "verdict"]

#: Bootstrap resamples per interval.
N_BOOT = 2000


def _differences(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    fin = np.isfinite(x) & np.isfinite(y)
    d = np.zeros_like(x)  # both diverged: a tie
    d[fin] = x[fin] - y[fin]
    d[np.isinf(x) & ~np.isinf(y)] = np.inf
    d[~np.isinf(x) & np.isinf(y)] = -np.inf
    return d


def verdict(ci95: tuple[float, float] | list[float]) -> str:
    """``"a lower"``, ``"a higher"`` or ``"indistinguishable"`` from a 95 % interval of a - b."""
    lo, hi = ci95
    if hi < 0:
        return "a lower"
    if lo > 0:
        return "a higher"
    return "indistinguishable"


def paired_effect(x: np.ndarray, y: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """The paired effect of a vs b over the same seeds (RMSE per seed [rad], inf = diverged):
    median difference, its bootstrap 95 % interval, the verdict, seeds a is better on, and
    the divergences of each."""
    d = _differences(np.asarray(x, float), np.asarray(y, float))
    idx = rng.integers(0, d.size, size=(N_BOOT, d.size))
    boot = np.percentile(d[idx], 50, axis=1, method="lower")
    ci = [
        float(np.percentile(boot, 2.5, method="lower")),
        float(np.percentile(boot, 97.5, method="higher")),
    ]
    return {
        "median_difference": float(np.percentile(d, 50, method="lower")),
        "difference_ci95": ci,
        "verdict": verdict(ci),
        "a_better_seeds": int((d < 0).sum()),
        "seeds": int(d.size),
        "diverged_a": int(np.isinf(x).sum()),
        "diverged_b": int(np.isinf(y).sum()),
    }


def pair_effects(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """Every pair of a claims document (``claims.json``: ``rmse`` per row, ``pairs`` with
    their rows ``a`` and ``b``), per joint, as :func:`paired_effect`."""
    rng = np.random.default_rng(0)
    out = []
    for p in doc["pairs"]:
        ra, rb = np.array(doc["rmse"][p["a"]], float), np.array(doc["rmse"][p["b"]], float)
        joints = [paired_effect(ra[:, j], rb[:, j], rng) for j in range(ra.shape[1])]
        out.append({"label": p["label"], "a": p["a"], "b": p["b"], "joints": joints})
    return out


def combine(first: dict[str, Any], second: dict[str, Any]) -> list[dict[str, Any]]:
    """The claims of two blocks side by side: per pair and joint, each block's effect and
    the stated verdict (the common one, or ``"not reproduced"``)."""
    e2 = {p["label"]: p for p in pair_effects(second)}
    rows = []
    for p in pair_effects(first):
        q = e2.get(p["label"])
        if q is None:
            continue
        for j, (s, t) in enumerate(zip(p["joints"], q["joints"], strict=True)):
            same = s["verdict"] == t["verdict"]
            rows.append(
                {
                    "label": p["label"],
                    "a": p["a"],
                    "b": p["b"],
                    "joint": j + 1,
                    "first": s,
                    "second": t,
                    "stated": s["verdict"] if same else "not reproduced",
                }
            )
    return rows


def _show(v: float, scale: float) -> str:
    return ("+inf" if v > 0 else "-inf") if np.isinf(v) else f"{scale * v:+.3f}"


def _cell(e: dict[str, Any], scale: float = 1e3) -> str:
    lo, hi = e["difference_ci95"]
    return (
        f"{_show(e['median_difference'], scale)} [{_show(lo, scale)}, {_show(hi, scale)}] | "
        f"{e['diverged_a']} / {e['diverged_b']} | {e['a_better_seeds']} / {e['seeds']}"
    )


def _stated(r: dict[str, Any]) -> str:
    v = r["stated"]
    if v == "a lower":
        return f"**{r['a']} lower**"
    if v == "a higher":
        return f"**{r['a']} higher**"
    return v


def _block(doc: dict[str, Any]) -> str:
    s = doc["seeds"]
    return f"seeds {s[0]}-{s[-1]}"


def format_effects(
    first: dict[str, Any],
    second: dict[str, Any],
    what: str = "tracking RMSE",
    unit: str = "mrad",
    scale: float = 1e3,
) -> str:
    """The effect-size table (Markdown) of two claims documents; ``what`` names the per-seed
    quantity compared, ``unit`` its display unit and ``scale`` the factor from the stored
    value to it (default: [rad] shown in [mrad])."""
    b1, b2 = _block(first), _block(second)
    head = (
        f"Claims as effect sizes: {first['scenario']}, {b1} and {b2}; median over seeds of the "
        f"paired difference of {what} a - b [{unit}] with its bootstrap 95 % interval "
        f"({N_BOOT} resamples), a diverged run counted as +inf (never dropped); stated only "
        "where both blocks agree, indistinguishable where the interval spans zero.\n\n"
        f"| claim (a vs b) | joint | {b1}: a - b [95% CI] | diverged a / b | a better on "
        f"| {b2}: a - b [95% CI] | diverged a / b | a better on | stated |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = [
        f"| {r['label']} | {r['joint']} | {_cell(r['first'], scale)} | "
        f"{_cell(r['second'], scale)} | "
        f"{_stated(r)} |"
        for r in combine(first, second)
    ]
    return head + "\n".join(lines) + "\n"
