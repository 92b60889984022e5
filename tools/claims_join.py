"""Join claim tables of consecutive seed ranges into one (the same scenario and duration).

    .venv/bin/python tools/claims_join.py /tmp/a/claims.json /tmp/b/claims.json \
        --out /tmp/ur5-13000

Used where a block was run in parts (a 50-seed block completed to 200 seeds): the per-seed
tracking RMSE of each part, in seed order, recomputed as one table with today's statistics
(amsfe_sym.apps.study.claims.tabulate); refuses parts that are not consecutive or differ in
scenario or duration. Writes ``claims.json`` and ``claims.md`` as ``amsfe study --claims``.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

from amsfe_sym.apps.study.claims import format_claims, tabulate, write_claims


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("parts", type=Path, nargs="+", help="claims.json files, in seed order")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args()
    docs = [json.loads(p.read_text()) for p in args.parts]
    for a, b in itertools.pairwise(docs):
        if b["seeds"][0] != a["seeds"][1] + 1 or (a["scenario"], a["duration"]) != (
            b["scenario"], b["duration"]):  # fmt: skip
            ap.error(f"parts not consecutive or not alike: {a['seeds']} then {b['seeds']}")
    rmse = {k: [row for d in docs for row in d["rmse"][k]] for k in docs[0]["rmse"]}
    seeds = list(range(docs[0]["seeds"][0], docs[-1]["seeds"][1] + 1))
    t = tabulate(docs[0]["scenario"], seeds, docs[0]["duration"], rmse)
    print(format_claims(t))
    write_claims(t, args.out, force=args.force)


if __name__ == "__main__":
    main()
