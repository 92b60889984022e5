"""Check the documented numbers against their commands (docs/data/claims-registry.toml).

    .venv/bin/python tools/check_docs.py --stored            # fast: the text vs the stored outputs
    .venv/bin/python tools/check_docs.py claims-paper-sim --first-seed 5200
    .venv/bin/python tools/check_docs.py --all --first-seed 5200 --seeds 100
    .venv/bin/python tools/check_docs.py claims-paper-sim --fresh /tmp/out/claims.json
    .venv/bin/python tools/check_docs.py --first-seed 13000 --keep /tmp/b13000  # keep outputs

Without ``--stored`` it re-runs the named sources' commands (default: every source not
marked costly; ``--all`` adds the costly ones) on the seed block ``--first-seed`` (default:
the block the stored output was made on) into a temporary folder, and prints every number
that moved beyond its registered interval. ``--fresh FILE`` compares an output made
elsewhere instead of running. Exit status 1 when any number moved or is missing from its
text. The fast mode is tests/test_docs_numbers.py.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

from amsfe_sym.apps.docs_numbers import Moved, Source, check_text, compare, load_registry
from amsfe_sym.errors import AmsfeError

ROOT = Path(__file__).resolve().parent.parent


def _argv(command: str) -> list[str]:
    words = shlex.split(command)
    if words[0] in ("amsfe", ".venv/bin/amsfe"):
        return [sys.executable, "-m", "amsfe_sym", *words[1:]]
    if words[0].endswith("python") or words[0].endswith("python3"):
        return [sys.executable, *words[1:]]
    return words


def _rerun(
    src: Source, first_seed: int | None, seeds: int | None, workers: int, keep: Path | None
) -> object:
    with tempfile.TemporaryDirectory(prefix="check-docs-") as tmp:
        out = (keep / src.name) if keep is not None else Path(tmp) / "out"
        cmd = src.command_for(
            src.first_seed if first_seed is None or src.fixed_seed else first_seed,
            src.seeds if seeds is None else seeds,
            str(out),
        )
        argv = _argv(cmd)
        if "--workers" not in argv and argv[1:4] == ["-m", "amsfe_sym", "study"]:
            argv += ["--workers", str(workers)]
        print(f"running: {cmd}", flush=True)
        if src.output == "-":  # the output is the command's standard output
            text = subprocess.run(argv, cwd=ROOT, check=True, capture_output=True, text=True).stdout
            if keep is not None:
                out.mkdir(parents=True, exist_ok=True)
                (out / "stdout.txt").write_text(text)
            return text
        subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        if src.post:
            post = src.post.format(out=str(out))
            print(f"then: {post}", flush=True)
            subprocess.run(_argv(post), cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        return json.loads((out / src.output if src.output else out).read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sources", nargs="*", help="registry sources to re-run (default: not costly)")
    ap.add_argument("--stored", action="store_true", help="only the text vs the stored outputs")
    ap.add_argument("--all", action="store_true", help="the costly sources too")
    ap.add_argument("--first-seed", type=int, default=None, help="the seed block's first seed")
    ap.add_argument("--seeds", type=int, default=None, help="how many seeds (default: stored)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--fresh", type=Path, default=None, help="an output to compare, not run")
    ap.add_argument("--keep", type=Path, default=None, help="keep each fresh output in KEEP/SOURCE")
    ap.add_argument("--list", action="store_true", help="print the sources and their commands")
    args = ap.parse_args(argv)
    reg = load_registry(ROOT)
    if args.list:
        for s in reg.sources.values():
            n = sum(x.source == s.name for x in reg.numbers)
            b = sum(x.source == s.name for x in reg.blocks)
            cost = " (costly)" if s.costly else ""
            print(f"{s.name}{cost}: {n} numbers, {b} tables; {s.command}")
        return 0
    unknown = [s for s in args.sources if s not in reg.sources]
    if unknown:
        print(f"check_docs: unknown source {unknown}; known: {sorted(reg.sources)}")
        return 2
    moved: list[Moved] = check_text(reg)
    for m in moved:
        print(m.line(), flush=True)
    failed = 0
    if not args.stored:
        names = args.sources or [s.name for s in reg.sources.values() if args.all or not s.costly]
        if args.fresh is not None and len(names) != 1:
            print("check_docs: --fresh compares one source; name it")
            return 2
        for name in names:
            src = reg.sources[name]
            if args.fresh is not None:
                text = args.fresh.read_text()
                fresh = text if src.output == "-" else json.loads(text)
            elif src.by_hand:
                print(f"{name}: not re-run here: {src.by_hand}", flush=True)
                continue
            else:
                try:
                    fresh = _rerun(src, args.first_seed, args.seeds, args.workers, args.keep)
                except subprocess.CalledProcessError as e:  # one line; the others still run
                    print(f"{name}: its command failed (exit {e.returncode}): {e.cmd}")
                    failed += 1
                    continue
            found = compare(reg, name, fresh)
            print(f"{name}: {len(found)} moved", flush=True)
            for m in found:
                print(f"  {m.line()}", flush=True)
            moved += found
    total = len(reg.numbers) + len(reg.blocks)
    print(f"{total} registered entries, {len(moved)} outside their interval or missing")
    if failed:
        print(f"{failed} source(s) whose command failed: not compared")
    return 1 if moved or failed else 0


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except AmsfeError as e:  # a bad registry entry or stored output: one line, exit 2
        print(f"check_docs: {e}", file=sys.stderr)
        raise SystemExit(2) from None
