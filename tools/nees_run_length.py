"""NEES against run length as effect sizes (docs/explanation/estimation.md section 7, README).

    .venv/bin/python tools/nees_run_length.py --first-seed 1000 --seeds 200 \
        --second-block 13000 --out docs/data/nees-run-length
    .venv/bin/python tools/nees_run_length.py --first-seed 7000 --seeds 200 --out /tmp/n

Runs, on each block, paper-sim under ``truth-ct`` (every estimator sees the same plant):
3 s runs, and 10 s runs with the shipped payload random walk (``shipped``) and without it
(``theta0``: ``filter.theta_rate_std=0``), for ``oosm``, ``replay`` and ``cloning``; then
compares per seed the time-averaged NEES over the last 80 % of each run (N = 9): the median
over seeds of the paired difference a - b with its bootstrap 95 % interval, a failed run
+inf (never dropped), stated only where both blocks agree (tools/estimator_effects.py,
amsfe_sym.apps.study.effects). Writes ``effects.json`` (per block also the fraction of steps
the seed-averaged NEES spends inside its 95 % band: one trajectory per block, quoted per
named block, not as a claim) and ``effects.md``. The studies go to ``--studies`` (default:
a temporary folder).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from estimator_effects import METRICS, as_claims  # tools/ is this script's sys.path[0]

from amsfe_sym.apps.study.effects import combine, format_effects, pair_effects

#: The studies of one block: (name, extra arguments).
STUDIES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("3s", ("--duration", "3")),
    ("10s", ("--duration", "10", "--variant", "shipped", "--variant", "theta0",
             "filter.theta_rate_std=0")),
)  # fmt: skip
#: (a, b) rows: "<run length> <variant>/<estimator>".
PAIRS: tuple[tuple[str, str], ...] = tuple(
    p
    for e in ("replay", "oosm")
    for p in ((f"10s shipped/{e}", f"3s base/{e}"), (f"10s shipped/{e}", f"10s theta0/{e}"))
)


def run_block(first_seed: int, seeds: int, folder: Path, workers: int) -> list[dict[str, Any]]:
    """The block's studies (``amsfe study``), written under ``folder``; their documents."""
    docs = []
    for name, extra in STUDIES:
        out = folder / f"{name}-{first_seed}"
        if not (out / "study.json").is_file():
            argv = [sys.executable, "-m", "amsfe_sym", "study", "paper-sim", "--seeds",
                    str(seeds), "--first-seed", str(first_seed), "--estimators",
                    "oosm,replay,cloning", "--workers", str(workers), "--no-progress",
                    "--out", str(out), "--set", "controller=truth-ct", *extra]  # fmt: skip
            subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
        docs.append(json.loads((out / "study.json").read_text()))
    return docs


def in_band(docs: list[dict[str, Any]]) -> dict[str, float]:
    """Per row, the fraction of steps the seed-averaged NEES is inside its 95 % band."""
    return {
        f"{name} {v}/{e}": a["avg_nees_in_band_fraction"]
        for (name, _), d in zip(STUDIES, docs, strict=True)
        for v, per in d["aggregate"].items()
        for e, a in per.items()
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first-seed", type=int, required=True)
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--second-block", type=int, default=None, help="the second block's seed")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--studies", type=Path, default=None, help="keep the studies here")
    ap.add_argument("--out", type=Path, required=True, help="folder for effects.json / .md")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="nees-run-length-") as tmp:
        folder = args.studies or Path(tmp)
        blocks = [args.first_seed] + ([args.second_block] if args.second_block else [])
        docs = [run_block(b, args.seeds, folder, args.workers) for b in blocks]
    what, unit, scale = METRICS["nees"]
    claims = [as_claims(d, "nees", list(PAIRS), "all") for d in docs]
    out: dict[str, Any] = {
        "commands": [s["command"] for d in docs for s in d],
        "blocks": [c["seeds"] for c in claims],
        "in_band": [in_band(d) for d in docs],
        "pairs": pair_effects(claims[0]),
    }
    text = ""
    if len(claims) == 2:
        out["claims"] = combine(claims[0], claims[1])
        text = format_effects(claims[0], claims[1], what=what, unit=unit, scale=scale)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "effects.json").write_text(json.dumps(out, indent=1) + "\n")
    if text:
        (args.out / "effects.md").write_text(text)
    print(text or json.dumps(out["pairs"], indent=1))


if __name__ == "__main__":
    main()
