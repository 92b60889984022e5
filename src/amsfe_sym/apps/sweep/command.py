"""``amsfe sweep`` from its parsed command-line options (the parser is in
:mod:`amsfe_sym.apps.cli`)."""

from __future__ import annotations

import argparse

from amsfe_sym.errors import ConfigError, describe

__all__ = ["from_args"]


def from_args(args: argparse.Namespace) -> int:
    """``amsfe sweep``: run the sweep (or, with ``--report``, only read its folder), then
    print the seed table of the chosen metric and write the figures."""
    from pathlib import Path

    from amsfe_sym.apps.sweep import SweepOptions, load_sweep, run_sweep
    from amsfe_sym.apps.sweep.report import format_report, write_figures
    from amsfe_sym.apps.sweep.table import read_rows, repair

    spec = load_sweep(args.spec)
    out = Path(args.out) if args.out else Path("runs") / f"sweep-{spec.name}"
    metric = args.metric or spec.report.metric
    x = spec.report.x if args.x is None else args.x
    y = spec.report.y if args.y is None else args.y
    for flag, axis in (("--x", x), ("--y", y)):
        if axis and axis not in spec.axes:
            raise ConfigError(
                describe(flag, f"an axis of the sweep {list(spec.axes)}", repr(axis), "name one")
            )
    if not args.report:  # before --repair moves anything
        from amsfe_sym.apps.sweep.engine import check_sweep_out

        check_sweep_out(out, args.force, [spec.source] if spec.source else [])
    if args.repair and out.is_dir():
        for path in repair(out):
            print(f"set aside (unreadable, its runs will be run again): {path}")
    if args.report:
        table = read_rows(out) if out.is_dir() else None
        if table is None or not len(table):
            raise ConfigError(
                describe(
                    f"--report on {str(out)!r}",
                    "a sweep folder with results",
                    "no rows",
                    f"run amsfe sweep {args.spec} first (or pass its --out)",
                )
            )
    else:
        res = run_sweep(
            spec,
            SweepOptions(
                out=out,
                scheduler=args.scheduler,
                workers=args.workers,
                batch=args.batch,
                retry_errors=args.retry_errors,
                force=args.force,
                progress=not args.no_progress,
            ),
        )
        table = res.table
        rate = f", {res.runs_per_s:.2f} runs/s" if res.ran else ""
        print(
            f"sweep {spec.name}: {res.ran} runs in {res.wall_time_s:.1f} s{rate} "
            f"({res.workers} workers, batches of {res.batch}); {res.skipped} already done; "
            f"{res.errors} errors, {res.diverged} diverged"
        )
    axes = [a for a in (x, y) if a]
    print(format_report(table, metric, axes))
    if not args.no_plots and axes:
        for path in write_figures(table, metric, x, y, out / "figures"):
            print(f"figure: {path}")
    print(f"sweep folder: {out} (results.parquet, sweep.json)")
    return 0
