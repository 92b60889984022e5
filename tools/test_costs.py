"""What the test suite costs, by file and by test (docs/how-to/tests.md).

    AMSFE_TEST_COSTS=costs.jsonl .venv/bin/python -m pytest -q -n 2
    .venv/bin/python tools/test_costs.py costs.jsonl [--top 30]

tests/conftest.py appends one JSON line per test to ``$AMSFE_TEST_COSTS``: the CPU seconds of
the test's process and of the children it waited for (DDS nodes, the compiler, docs blocks),
and its wall seconds.  This script sums them by file and lists the costliest tests.  CPU
seconds are the measure on a shared machine (its load moves wall time, not CPU time); the
sum of CPU over the run, divided by the cores, is the least wall time the run can take on an
idle machine of that many cores.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("costs", type=Path, nargs="+", help="JSON lines written by the suite")
    p.add_argument("--top", type=int, default=30, help="how many tests to list [30]")
    p.add_argument("--cores", type=int, default=2, help="cores of the run's machine [2]")
    args = p.parse_args(argv)
    rows = [json.loads(x) for f in args.costs for x in f.read_text().splitlines() if x.strip()]
    by_file: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
    for r in rows:
        acc = by_file[r["test"].split("::")[0]]
        acc[0] += 1
        acc[1] += r["cpu"] + r["cpu_children"]
        acc[2] += r["wall"]
    cpu = sum(r["cpu"] + r["cpu_children"] for r in rows)
    wall = sum(r["wall"] for r in rows)
    print(f"{len(rows)} tests: CPU {cpu:.0f} s (test processes and their children), "
          f"wall {wall:.0f} s summed over workers; CPU / {args.cores} cores = "
          f"{cpu / args.cores:.0f} s")  # fmt: skip
    print("\n| file | tests | CPU [s] | share | wall [s] |\n|---|---:|---:|---:|---:|")
    for name, (n, c, w) in sorted(by_file.items(), key=lambda kv: -kv[1][1]):
        print(f"| {name} | {n:.0f} | {c:.1f} | {100 * c / max(cpu, 1e-9):.1f} % | {w:.1f} |")
    print(f"\n| test (the {args.top} costliest) | CPU [s] | of which children | wall [s] |")
    print("|---|---:|---:|---:|")
    for r in sorted(rows, key=lambda r: -(r["cpu"] + r["cpu_children"]))[: args.top]:
        total = r["cpu"] + r["cpu_children"]
        print(f"| {r['test']} | {total:.1f} | {r['cpu_children']:.1f} | {r['wall']:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
