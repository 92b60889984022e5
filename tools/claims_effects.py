"""Claims as effect sizes from two stored claim tables, without re-running either block.

    .venv/bin/python tools/claims_effects.py docs/data/claims-ur5-control/claims.json \
        /tmp/ur5-5200/claims.json --out docs/data/claims-ur5-control --force

The first file is the tuning-disjoint test block, the second a later block (any size); the
output folder is what ``amsfe study SCENARIO --claims --first-seed A --seeds N
--second-block B --second-seeds M`` writes (``claims.json`` with ``second_block`` and
``effects``, ``claims.md`` with the effect-size table), recomputed from the stored per-seed
RMSE with today's statistics (amsfe_sym.apps.study.claims.table_from_doc). Used where a
second full run of the first block is costly (ur5-control, panda-control). Reported in
docs/explanation/reproduction.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from amsfe_sym.apps.study.claims import format_claims, table_from_doc, write_claims


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", type=Path, help="claims.json of the first (test) block")
    ap.add_argument("second", type=Path, help="claims.json of the second block")
    ap.add_argument("--out", type=Path, required=True, help="claims folder to write")
    ap.add_argument("--force", action="store_true", help="replace an existing claims folder")
    args = ap.parse_args()
    first = json.loads(args.first.read_text())
    first.pop("second_block", None)
    t = table_from_doc(first)
    t.second = table_from_doc(json.loads(args.second.read_text()))
    print(format_claims(t))
    write_claims(t, args.out, force=args.force)


if __name__ == "__main__":
    main()
