"""The estimators' claims as effect sizes: paired differences of estimation RMSE on two blocks.

    .venv/bin/python tools/estimator_effects.py FIRST/study.json SECOND/study.json \
        --out docs/data/study-paper-sim-camera/effects

Reads two ``amsfe study`` outputs of the same command on two seed blocks (the full
``study.json``, with its per-run records), and per variant compares estimators seed by seed
on the q RMSE of each joint (the last 80 % of each run): the median over seeds of the paired
difference a - b with its bootstrap 95 % interval, a failed run counted as +inf (never
dropped), and the verdict stated only where both blocks agree
(amsfe_sym.apps.study.effects). Writes ``effects.json`` and ``effects.md``. Reported in
docs/estimation.md section 6.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from amsfe_sym.apps.study.effects import combine, format_effects

#: (a, b): "a lower" means a estimates q better than b.
PAIRS: tuple[tuple[str, str], ...] = (
    ("replay", "encoders"),
    ("oosm", "encoders"),
    ("replay", "oosm"),
    ("cloning", "replay"),
    ("naive", "encoders"),
)


def as_claims(study: dict[str, Any], variant: str) -> dict[str, Any]:
    """One variant of a study as a claims document: per estimator the q RMSE [rad] per seed
    and joint (inf for a failed run), and the pairs of :data:`PAIRS` that ran."""
    seeds = sorted({r["seed"] for r in study["runs"] if r.get("variant") == variant})
    rmse: dict[str, list[list[float]]] = {}
    for r in study["runs"]:
        if r.get("variant") != variant:
            continue
        n = len(next(x for x in study["runs"] if "estimation_rmse" in x)["estimation_rmse"]["q"])
        q = r["estimation_rmse"]["q"] if "estimation_rmse" in r else [float("inf")] * n
        rmse.setdefault(r["estimator"], [[]] * len(seeds))[seeds.index(r["seed"])] = q
    pairs = [{"label": f"{a} vs {b}", "a": a, "b": b} for a, b in PAIRS if a in rmse and b in rmse]
    return {"scenario": f"{study['scenario']} {variant}", "seeds": [seeds[0], seeds[-1]],
            "rmse": rmse, "pairs": pairs}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("second", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="folder for effects.json / .md")
    args = ap.parse_args()
    one, two = (json.loads(p.read_text()) for p in (args.first, args.second))
    doc: dict[str, Any] = {"first": one["command"], "second": two["command"], "variants": {}}
    text = []
    for variant in one["aggregate"]:
        a, b = as_claims(one, variant), as_claims(two, variant)
        doc["variants"][variant] = combine(a, b)
        text.append(format_effects(a, b, what="q estimation RMSE"))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "effects.json").write_text(json.dumps(doc, indent=1) + "\n")
    (args.out / "effects.md").write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
