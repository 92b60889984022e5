"""How the watchdogs' defaults were chosen (docs/watchdogs.md, docs/data/watchdog-bounds.json).

Three parts, each on the in-process free-running node of
:func:`amsfe_sym.ros.watchdog_runs.run_watched` (the arm on a simulated wall clock, the node
taking ``--compute`` seconds a sample):

1. ``measure``: clean runs of every scenario on the seeds ``--first-seed`` ..
   ``+ --seeds``, every bound off (inf) so each watched quantity is seen over the whole run:
   the largest value of each per scenario (the defaults are set above these);
2. ``verify``: clean runs on a disjoint block (``--verify-first-seed``) with the defaults:
   the holds (there must be none) and the largest values again;
3. ``compute``: clean runs on ``--compute-seeds`` seeds of the verify block where each
   sample takes the wall clock its processing really took here (the Python node's own
   compute time, and the lateness it causes through the queue);
4. ``cost``: the Python watchdog's own time per call (``Watchdog.sample`` and ``idle`` on
   the calls of one clean run, median of 5 passes) [us];
5. ``faults``: each fault of :data:`~amsfe_sym.ros.watchdog_runs.FAULTS` (or
   ``--fault-kinds``) at ``--fault-at`` on ``--fault-seeds`` seeds with the defaults: the
   reason and the delay from the fault (or from the node's resumption after a stall) to the
   hold [s of wall clock], and the largest ``actuation`` mismatch judged (late commands
   during a stall or a lag included).

``max_actuation`` (the ``actuation`` check, docs/watchdogs.md): the largest distance of a
reported applied torque to the nearest command the arm may have applied [fraction of u_max];
with ``actuation_error`` off (``measure``) every tick is judged and matched to its nearest.

Run:  .venv/bin/python tools/watchdog_bounds.py --out docs/data/watchdog-bounds.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.watchdog import Watchdog, WatchdogConfig
from amsfe_sym.ros.watchdog_runs import FAULTS, Fault, WatchRun, run_watched
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.watchdog import MEASURING, WatchdogBounds

OFF = MEASURING
#: The fault sizes: a 10 mrad encoder jump, a 300 ms stall (the issue's), an 80 ms lag.
SIZES = {"jump": 0.01, "stall": 0.3, "lag": 0.08}
SEEN = (
    "max_tracking",
    "max_innovation",
    "max_lateness",
    "max_late_in_window",
    "max_lag",
    "max_compute",
    "max_wall_gap",
    "max_actuation",
)


def _seen(run: WatchRun) -> dict[str, float]:
    d = dataclasses.asdict(run.seen)
    return {k: d[k] for k in SEEN} | {"true_error": run.true_error}


def _clean(name: str, part: str, sc0: Any, lib: Any, seeds: range, **kw: Any) -> dict[str, Any]:
    """Clean runs of ``sc0`` on ``seeds`` (``run_watched``'s keywords ``kw``): the largest
    watched quantities and the hold lines."""
    rows = []
    for seed in seeds:
        r = run_watched(sc0.with_overrides(seed=seed), lib, **kw)
        rows.append(_seen(r) | {"seed": seed, "hold": None if r.hold is None else r.hold.line()})
        print(name, part, rows[-1], flush=True)
    return {
        "seeds": [seeds.start, seeds.stop],
        "max": {k: max(row[k] for row in rows) for k in (*SEEN, "true_error")},
        "holds": [row["hold"] for row in rows if row["hold"] is not None],
    }


def _cost(lib: Any, events: list[Any]) -> float:
    """Median over 5 passes of the Python watchdog's mean time per call on ``events`` [us]."""
    passes = []
    for _ in range(5):
        wd = Watchdog(WatchdogConfig(lib.n, lib.N, 2 * lib.n, lib.T))
        t0 = time.perf_counter()
        for e in events:
            if e.tick is None:
                wd.idle(e.now, e.publishers)
            else:
                wd.sample(e.tick)
        passes.append((time.perf_counter() - t0) / len(events) * 1e6)
    return statistics.median(passes)


def _machine() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            if line.startswith("Model name"):
                return line.split(":", 1)[1].strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return platform.processor()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["paper-sim", "panda-control"])
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--verify-first-seed", type=int, default=1000)
    ap.add_argument("--verify-seeds", type=int, default=20)
    ap.add_argument("--fault-seeds", type=int, default=5)
    ap.add_argument("--compute-seeds", type=int, default=3)
    ap.add_argument("--fault-at", type=float, default=2.0)
    ap.add_argument("--compute", type=float, default=2e-4)
    ap.add_argument("--fault-kinds", nargs="+", default=list(FAULTS), choices=FAULTS)
    ap.add_argument(
        "--parts", nargs="+", default=["measure", "verify", "compute", "cost", "faults"]
    )
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument(
        "--merge", action="store_true", help="update the parts run here in an existing --out"
    )
    args = ap.parse_args(argv)
    command = "tools/watchdog_bounds.py " + " ".join(argv or sys.argv[1:])
    out: dict[str, Any] = {"commands": [], "scenarios": {}}
    if args.merge and args.out.is_file():
        out = json.loads(args.out.read_text())
    out["commands"].append(command)
    out |= {"machine": _machine(), "defaults": dataclasses.asdict(WatchdogBounds())}
    out["compute"] = args.compute
    for name in args.scenarios:
        sc0 = load_scenario(name)
        lib = library_for(sc0)
        res: dict[str, Any] = out["scenarios"].get(name, {})
        res |= {"T": lib.T, "duration": sc0.duration}
        if "measure" in args.parts:
            seeds = range(args.first_seed, args.first_seed + args.seeds)
            m = _clean(name, "measure", sc0, lib, seeds, bounds=OFF, compute=args.compute)
            res["measure"] = m | {"holds": len(m["holds"])}
        first = args.verify_first_seed
        if "verify" in args.parts:
            seeds = range(first, first + args.verify_seeds)
            res["verify"] = _clean(name, "verify", sc0, lib, seeds, compute=args.compute)
        if "compute" in args.parts:
            seeds = range(first, first + args.compute_seeds)
            res["compute"] = _clean(name, "compute", sc0, lib, seeds, real_compute=True)
        if "cost" in args.parts:
            events = run_watched(sc0.with_overrides(seed=first), lib).events
            res["cost_us_per_call"] = _cost(lib, events)
            res["cost_load_average"] = os.getloadavg()[0]  # the machine's, while measured
            print(name, "cost", res["cost_us_per_call"], flush=True)
        if "faults" in args.parts:
            faults: dict[str, Any] = {}
            duration = args.fault_at + 1.0
            for kind in args.fault_kinds:
                rows = []
                for seed in range(args.fault_seeds):
                    sc = sc0.with_overrides(seed=seed, duration=duration)
                    f = Fault(kind, args.fault_at, SIZES.get(kind, 0.0))
                    r = run_watched(sc, lib, f, compute=args.compute)
                    delay = None if r.hold_wall is None else r.hold_wall - r.resumed
                    rows.append(
                        {
                            "seed": seed,
                            "reason": None if r.hold is None else r.hold.name,
                            "delay": delay,
                            "true_error": r.true_error,
                            "max_actuation": r.seen.max_actuation,
                            "actuation_judged": r.seen.actuation_judged,
                        }
                    )
                    print(name, kind, rows[-1], flush=True)
                delays = [row["delay"] for row in rows if row["delay"] is not None]
                faults[kind] = {
                    "size": SIZES.get(kind, 0.0),
                    "reasons": sorted({str(row["reason"]) for row in rows}),
                    "max_delay": max(delays) if len(delays) == len(rows) else None,
                    "runs": rows,
                }
            res["faults"] = res.get("faults", {}) | faults
        out["scenarios"][name] = res
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
