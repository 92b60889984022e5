"""Find (and with ``--fix`` rewrite) references to docs pages by the paths they had before the
docs were grouped by the reader's need (docs/tutorials, how-to, reference, explanation).

A branch made before that move still names ``docs/logs.md`` and the like in its code, tests
and pages; after merging it, this rewrites them to the new paths (tests/test_docs_blocks.py
fails on a docs path that does not exist, and ruff on a line the longer path made too long)::

    .venv/bin/python tools/moved_docs_paths.py          # list; exit 1 when any is found
    .venv/bin/python tools/moved_docs_paths.py --fix    # rewrite them in place

Relative links from a page directly in docs/ (``[x](logs.md)``) are rewritten too. Only text
files under git are read; docs/data/ (stored outputs) is left alone but for the
claims registry.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: old path under docs/ -> new path under docs/
MOVED = {
    "architecture.md": "explanation/architecture.md",
    "codegen.md": "explanation/codegen.md",
    "control.md": "explanation/control.md",
    "effort.md": "explanation/effort.md",
    "estimation-algorithms.md": "explanation/estimation-algorithms.md",
    "estimation.md": "explanation/estimation.md",
    "performance.md": "explanation/performance.md",
    "plant-accuracy.md": "explanation/plant-accuracy.md",
    "reproduction.md": "explanation/reproduction.md",
    "ur5-estimation.md": "explanation/ur5-estimation.md",
    "logs.md": "how-to/logs.md",
    "ros.md": "how-to/ros.md",
    "runtime-c.md": "how-to/runtime-c.md",
    "sweeps.md": "how-to/sweeps.md",
    "robot-spec.md": "reference/robot-spec.md",
    "robots.md": "reference/robots.md",
    "scenarios.md": "reference/scenarios.md",
    "topics.md": "reference/topics.md",
}
OLD = re.compile(r"docs/(" + "|".join(re.escape(k) for k in MOVED) + r")(?![\w-])")
SUFFIXES = (".py", ".md", ".toml", ".txt", ".c", ".h", ".yml", ".yaml")
#: a relative Markdown link from a page directly in docs/ (where other branches add theirs)
LINK = re.compile(r"\]\((" + "|".join(re.escape(k) for k in MOVED) + r")(?=[#)])")


def tracked_files() -> list[Path]:
    out = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.split()
    keep = [
        f
        for f in out
        if f.endswith(SUFFIXES)
        and (not f.startswith("docs/data/") or f.endswith("claims-registry.toml"))
    ]
    return [ROOT / f for f in keep if (ROOT / f).is_file() and f != "tools/moved_docs_paths.py"]


def rewrite(path: Path, text: str) -> tuple[str, list[str]]:
    """The text with the old paths replaced, and the old paths found."""
    hits = OLD.findall(text)
    text = OLD.sub(lambda m: "docs/" + MOVED[m.group(1)], text)
    if path.parent == ROOT / "docs" and path.suffix == ".md":
        hits += LINK.findall(text)
        text = LINK.sub(lambda m: "](" + MOVED[m.group(1)], text)
    return text, hits


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fix", action="store_true", help="rewrite the old paths in place")
    args = ap.parse_args(argv)
    found = 0
    for path in tracked_files():
        text = path.read_text()
        new, hits = rewrite(path, text)
        if not hits:
            continue
        found += len(hits)
        rel = path.relative_to(ROOT)
        print(f"{rel}: {len(hits)} old path(s): {', '.join(sorted(set(hits)))}")
        if args.fix:
            path.write_text(new)
    if found and not args.fix:
        print(f"{found} old docs path(s); --fix rewrites them")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
