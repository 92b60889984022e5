"""Time spent writing bags (docs/how-to/logs.md, "Speed"): ``amsfe estimate LOG --no-plots`` with
``write_estimate_bag`` timed, and ``amsfe simulate --controller amsfe --duration 10 --bag
--no-plots`` with the run bag's filler timed (building it + filling it), wall and CPU,
the median of ``--repeat`` runs, each in this process.  The tree timed is the one
imported: run it once per tree to compare (before / after), e.g.

    AMSFE_GENERATED_DIR=/tmp/gen PYTHONPATH=OLD/src .venv/bin/python tools/bag_write_speed.py
    AMSFE_GENERATED_DIR=/tmp/gen PYTHONPATH=NEW/src .venv/bin/python tools/bag_write_speed.py

The 10 s paper-sim log is written once into ``--out`` (default /tmp/amsfe-bag-speed).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import amsfe_sym
import amsfe_sym.logs.write as w
from amsfe_sym.apps.cli import main

SIMULATE = ["simulate", "--controller", "amsfe", "--duration", "10", "--bag", "--no-plots"]


def _quiet(args: list[str]) -> None:
    out, err = contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO())
    with out, err, contextlib.suppress(SystemExit):
        main(args)


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(start: tuple[float, float]) -> tuple[float, float]:
    return time.perf_counter() - start[0], time.process_time() - start[1]


def time_estimate_bag(root: Path) -> tuple[float, float]:
    took: list[tuple[float, float]] = []
    orig = w.write_estimate_bag

    def timed(*a: Any, **k: Any) -> Any:
        start = _clock()
        out = orig(*a, **k)
        took.append(_since(start))
        return out

    w.write_estimate_bag = timed
    try:
        shutil.rmtree(root / "est", ignore_errors=True)
        _quiet(["estimate", str(root / "run" / "bag"), "--no-plots", "--out", str(root / "est")])
    finally:
        w.write_estimate_bag = orig
    return took[0]


def time_run_bag(root: Path) -> tuple[float, float]:
    took: list[tuple[float, float]] = []
    orig = w.run_bag_filler

    def timed(*a: Any, **k: Any) -> Callable[[Path], None]:
        start = _clock()
        fill = orig(*a, **k)
        built = _since(start)

        def f(path: Path) -> None:
            start = _clock()
            fill(path)
            done = _since(start)
            took.append((built[0] + done[0], built[1] + done[1]))

        return f

    w.run_bag_filler = timed  # type: ignore[assignment]
    try:
        out = root / "run2"
        shutil.rmtree(out, ignore_errors=True)
        _quiet([*SIMULATE, "--out", str(out)])
    finally:
        w.run_bag_filler = orig
    return took[0]


def main_() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("/tmp/amsfe-bag-speed"))
    args = ap.parse_args()
    root = args.out
    root.mkdir(parents=True, exist_ok=True)
    if not (root / "run" / "bag").is_dir():
        _quiet([*SIMULATE, "--out", str(root / "run")])
    print(f"tree: {Path(amsfe_sym.__file__).parent}")
    for name, fn in (("write_estimate_bag", time_estimate_bag), ("run bag", time_run_bag)):
        runs = [fn(root) for _ in range(args.repeat)]
        wall = statistics.median(r[0] for r in runs)
        cpu = statistics.median(r[1] for r in runs)
        print(f"{name}: wall {wall:.3f} s, CPU {cpu:.3f} s (median of {args.repeat})")


if __name__ == "__main__":
    main_()
