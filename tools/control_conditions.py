"""The paper's stability conditions and divergences over seed blocks (docs/explanation/control.md
2, 5).

    .venv/bin/python tools/control_conditions.py B1000/study.json B13000/study.json \
        --variant rk4 --estimator oosm --out docs/data/control-conditions
    .venv/bin/python tools/control_conditions.py P1000/study.json P13000/study.json \
        --out docs/data/control-printed-laws

Reads ``amsfe study`` outputs (one per seed block) and, per block, variant and estimator,
writes the divergences (how many runs, and the range of their times) and, per joint, each
``sliding_conditions`` field of the runs' summaries (the fractions of ticks where Sarpturk's
(43a), (43b), the gain bound (38) and the sampling bound (39) hold, and the median of (38)'s
bound [rad/s^2]) as the median over seeds with its bootstrap 95 % interval (2000 resamples,
amsfe_sym.apps.study.effects' convention), and the smallest and largest seed's value.
Diverged runs are counted (a study records a stopped loop as an error with its time), never
dropped; their conditions are not recorded.
Writes ``conditions.json`` and ``conditions.md``.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.study.effects import N_BOOT
from amsfe_sym.apps.study.records import study_runs

FIELDS: tuple[tuple[str, str, float], ...] = (
    ("sarpturk_43a_fraction", "(43a) holds [%]", 100.0),
    ("sarpturk_43b_fraction", "(43b) holds [%]", 100.0),
    ("gain_38_holds_fraction", "(38) holds [%]", 100.0),
    ("gain_38_eps_bound_median", "median bound of (38) [rad/s^2]", 1.0),
    ("sampling_39_holds_fraction", "(39) holds [%]", 100.0),
)


def summary(x: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """Median over seeds with its bootstrap 95 % interval, and the extremes."""
    idx = rng.integers(0, x.size, size=(N_BOOT, x.size))
    boot = np.percentile(x[idx], 50, axis=1, method="lower")
    return {
        "median": float(np.percentile(x, 50, method="lower")),
        "median_ci95": [float(np.percentile(boot, 2.5, method="lower")),
                        float(np.percentile(boot, 97.5, method="higher"))],
        "min": float(x.min()),
        "max": float(x.max()),
    }  # fmt: skip


def diverged_at(run: dict[str, Any]) -> float | None:
    """When a run diverged [s]: its summary's ``diverged_at_s``, or the time in the error a
    study records for a loop that stopped on divergence; None otherwise."""
    if run.get("diverged_at_s") is not None:
        return float(run["diverged_at_s"])
    m = re.search(r"diverged at t = ([0-9.]+) s", str(run.get("error", "")))
    return float(m.group(1)) if m else None


def key_controller(variant: str) -> str:
    """A study's failed run records no controller: the variant names it here."""
    return variant


def block(doc: dict[str, Any], variant: str | None, estimator: str | None) -> dict[str, Any]:
    """One block's rows: per (variant, estimator), divergences and condition summaries."""
    rng = np.random.default_rng(0)
    runs = study_runs(doc)
    keys = sorted({(r.get("variant", "base"), r["estimator"]) for r in runs})
    out: dict[str, Any] = {"seeds": [min(doc["seeds"]), max(doc["seeds"])], "rows": {}}
    for v, e in keys:
        if (variant and v != variant) or (estimator and e != estimator):
            continue
        rs = [r for r in runs if r.get("variant", "base") == v and r["estimator"] == e]
        div = [diverged_at(r) for r in rs if diverged_at(r) is not None]
        ok = [r for r in rs if "sliding_conditions" in r]
        row: dict[str, Any] = {
            "controller": rs[0].get("controller", key_controller(v)),
            "runs": len(rs),
            "diverged": len(div),
            "diverged_at_s": [min(div), max(div)] if div else None,
            "conditions": {},
        }
        for name, _, _ in FIELDS if ok else ():
            vals = np.array([r["sliding_conditions"][name] for r in ok], float)
            row["conditions"][name] = [summary(vals[:, j], rng) for j in range(vals.shape[1])]
        out["rows"][f"{v}/{e}"] = row
    return out


def table(blocks: list[dict[str, Any]]) -> str:
    """Markdown: one line per block and row, joints separated by ' / '."""
    head = ["block", "variant / estimator (controller)", "diverged", *[f[1] for f in FIELDS]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for b in blocks:
        for key, r in b["rows"].items():
            div = f"{r['diverged']} / {r['runs']}"
            if r["diverged_at_s"]:
                div += f" ({r['diverged_at_s'][0]:.3f}-{r['diverged_at_s'][1]:.3f} s)"
            cells = []
            for name, _, k in FIELDS if r["conditions"] else ():
                fmt = "{:.0f}" if k == 100.0 or name.startswith("gain_38_eps") else "{:.2f}"
                cells.append(" / ".join(
                    f"{fmt.format(k * j['median'])} [{fmt.format(k * j['median_ci95'][0])}, "
                    f"{fmt.format(k * j['median_ci95'][1])}] ({fmt.format(k * j['min'])}-"
                    f"{fmt.format(k * j['max'])})"
                    for j in r["conditions"][name]
                ))  # fmt: skip
            s = b["seeds"]
            cells = cells or ["-"] * len(FIELDS)
            lines.append(f"| {s[0]}-{s[1]} | {key} ({r['controller']}) | {div} | "
                         + " | ".join(cells) + " |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("studies", type=Path, nargs="+", help="one study.json per seed block")
    ap.add_argument("--variant", default=None)
    ap.add_argument("--estimator", default=None)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    docs = [json.loads(p.read_text()) for p in args.studies]
    blocks = [block(d, args.variant, args.estimator) for d in docs]
    caption = (
        "Per seed block: divergences, and per joint each condition's median over seeds "
        f"[bootstrap 95 % interval, {N_BOOT} resamples] (smallest-largest seed) over the runs "
        "that did not diverge (a diverged run is counted, with its time, never dropped).\n\n"
    )
    md = caption + table(blocks)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "conditions.json").write_text(json.dumps(
        {"commands": [d["command"] for d in docs], "blocks": blocks}, indent=1) + "\n")  # fmt: skip
    (args.out / "conditions.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
