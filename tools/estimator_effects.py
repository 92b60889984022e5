"""The estimators' claims as effect sizes: paired differences on two seed blocks.

    .venv/bin/python tools/estimator_effects.py FIRST/study.json SECOND/study.json \
        --out docs/data/study-paper-sim-camera/effects
    .venv/bin/python tools/estimator_effects.py A-1000/study.json B-1000/study.json \
        --second A-13000/study.json B-13000/study.json --metric nees \
        --pair "3s base/replay" "10s shipped/replay" --out OUT

Reads ``amsfe study`` outputs of the same commands on two seed blocks (the full
``study.json``, with its per-run records) and compares rows seed by seed: the median over
seeds of the paired difference a - b with its bootstrap 95 % interval, a failed run counted
as +inf (never dropped), and the verdict stated only where both blocks agree
(amsfe_sym.apps.study.effects). Writes ``effects.json`` (with each block's studies' aggregates,
``aggregates``) and
``effects.md``.

A row is ``VARIANT/ESTIMATOR`` (the variant is ``base`` without ``--variant``), prefixed by
the run length (``3s base/replay``) when a block is more than one study. Without ``--pair``
each variant's estimators are compared as :data:`PAIRS` (docs/explanation/estimation.md section 6);
``--pair A B`` (repeatable) names the rows instead (another variant, another run length).
``--metric``: ``q`` (q estimation RMSE per joint [rad], shown in mrad), ``nees`` (the
time-averaged NEES over the window), ``theta`` (theta RMSE [kg], shown in g),
``theta_settle`` (the time theta stays within 10 % after [s]; never: +inf).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from amsfe_sym.apps.study.effects import combine, format_effects, pair_effects
from amsfe_sym.apps.study.records import study_runs

#: (a, b): "a lower" means a estimates q better than b.
PAIRS: tuple[tuple[str, str], ...] = (
    ("replay", "encoders"),
    ("oosm", "encoders"),
    ("replay", "oosm"),
    ("cloning", "replay"),
    ("naive", "encoders"),
)

#: metric -> (what it is, display unit, display scale)
METRICS: dict[str, tuple[str, str, float]] = {
    "q": ("q estimation RMSE", "mrad", 1e3),
    "nees": ("time-averaged NEES", "-", 1.0),
    "theta": ("theta estimation RMSE", "g", 1e3),
    "theta_settle": ("theta settling time (10 %)", "s", 1.0),
}


def metric(run: dict[str, Any], name: str, n: int) -> list[float]:
    """One run's values of ``name`` (``n`` of them); +inf for a failed run."""
    inf = [float("inf")] * n
    if "estimation_rmse" not in run or run.get("diverged_at_s") is not None:
        return inf
    if name == "q":
        return [float(x) for x in run["estimation_rmse"]["q"]]
    if name == "theta":
        return [float(x) for x in run["estimation_rmse"]["theta"]]
    if name == "nees":
        return [float(run["nees_mean"])]
    return [float("inf") if x is None else float(x) for x in run["theta_settle_s"]]


def rows_of(studies: list[dict[str, Any]], name: str) -> tuple[list[int], dict[str, Any]]:
    """Per row key, the metric per seed (and joint) of one block's studies."""
    runs = [r for s in studies for r in study_runs(s)]
    seeds = sorted({r["seed"] for r in runs})
    n = max(len(metric(r, name, 1)) for r in runs if "estimation_rmse" in r)
    out: dict[str, list[list[float]]] = {}
    for r in runs:
        pre = f"{r['sim_time_s']:g}s " if len(studies) > 1 else ""
        key = f"{pre}{r.get('variant', 'base')}/{r['estimator']}"
        out.setdefault(key, [[]] * len(seeds))[seeds.index(r["seed"])] = metric(r, name, n)
    return seeds, out


def as_claims(
    studies: list[dict[str, Any]], name: str, pairs: list[tuple[str, str]] | None, variant: str
) -> dict[str, Any]:
    """A block as a claims document: the rows and the pairs that ran (``pairs`` given), or
    one variant's estimators as :data:`PAIRS` (``variant`` "all": every row)."""
    seeds, rows = rows_of(studies, name)
    if pairs is None:
        rows = {k.split("/", 1)[1]: v for k, v in rows.items() if k.split("/", 1)[0] == variant}
        pairs = [(a, b) for a, b in PAIRS]
    have = [(a, b) for a, b in pairs if a in rows and b in rows]
    scenario = studies[0]["scenario"] + (f" {variant}" if variant != "all" else "")
    return {"scenario": scenario, "seeds": [seeds[0], seeds[-1]], "rmse": rows,
            "pairs": [{"label": f"{a} vs {b}", "a": a, "b": b} for a, b in have]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", type=Path, nargs="+", help="the first block's study.json files")
    ap.add_argument("--second", type=Path, nargs="+", default=None,
                    help="the second block's (default: the last positional file)")  # fmt: skip
    ap.add_argument("--metric", choices=sorted(METRICS), default="q")
    ap.add_argument("--pair", nargs=2, action="append", default=None, metavar=("A", "B"))
    ap.add_argument("--one-block", action="store_true",
                    help="all files are one block: its effects only")  # fmt: skip
    ap.add_argument("--out", type=Path, required=True, help="folder for effects.json / .md")
    args = ap.parse_args()
    if args.one_block:
        files, second = args.first, []
    else:
        files = args.first if args.second else args.first[:-1]
        second = args.second or args.first[-1:]
        if not files or len(files) != len(second):
            ap.error("give the same number of study.json files for each block")
    one = [json.loads(p.read_text()) for p in files]
    two = [json.loads(p.read_text()) for p in second]
    what, unit, scale = METRICS[args.metric]
    pairs = [(a, b) for a, b in args.pair] if args.pair else None
    variants = list(one[0]["aggregate"]) if pairs is None else ["all"]
    doc: dict[str, Any] = {"first": [s["command"] for s in one], "metric": args.metric}
    doc["aggregates"] = [[s["aggregate"] for s in block] for block in (one, two) if block]
    doc["pairs"] = {v: pair_effects(as_claims(one, args.metric, pairs, v)) for v in variants}
    text = []
    if two:
        doc["second"] = [s["command"] for s in two]
        key = "variants" if pairs is None else "claims"
        doc[key] = {}
        for v in variants:
            a, b = (as_claims(x, args.metric, pairs, v) for x in (one, two))
            doc[key][v] = combine(a, b)
            text.append(format_effects(a, b, what=what, unit=unit, scale=scale))
        if pairs is not None:
            doc["claims"] = doc["claims"]["all"]
        if (
            len(one) == 1 and pairs is None
        ):  # the format docs/explanation/estimation.md section 6 reads
            doc["first"], doc["second"] = doc["first"][0], doc["second"][0]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "effects.json").write_text(json.dumps(doc, indent=1) + "\n")
    if text:
        (args.out / "effects.md").write_text("\n".join(text))
    print("\n".join(text) or json.dumps(doc["pairs"], indent=1))


if __name__ == "__main__":
    main()
