"""The ``innovation`` check's window means on logs of every effort kind (issue 34;
docs/watchdogs.md "The innovation bound per effort kind", docs/data/watchdog-innovation.json).

Each scenario's simulated runs, logged as an arm of each effort kind logs them (applied;
joint_torque with motor or link positions; none), played into the node's loop
(:func:`amsfe_sym.ros.watchdog_logs.play_watched`, every bound off): the largest window mean
of NIS / dimension on clean logs (seeds ``--first-seed`` ..), and for each fault of
:data:`~amsfe_sym.ros.watchdog_logs.LOG_FAULTS` at ``--fault-at`` (seeds 0 ..
``--fault-seeds``) the delay from the fault to the first window mean past each candidate
bound [s of log time] (``failed``: the estimator failed there, a ``covariance`` hold).

Run:  .venv/bin/python tools/watchdog_innovation.py --out docs/data/watchdog-innovation.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.watchdog_logs import LOG_FAULTS, play_watched
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.watchdog import MEASURING

OFF = MEASURING
#: (effort kind, encoders' positions) of the logs.
KINDS = (
    ("applied", "motor"),
    ("joint_torque", "motor"),
    ("joint_torque", "link"),
    ("none", "motor"),
)
CANDIDATES = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["paper-sim", "panda-control"])
    ap.add_argument("--first-seed", type=int, default=2000)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--fault-seeds", type=int, default=3)
    ap.add_argument("--fault-at", type=float, default=1.0)
    ap.add_argument("--jump", type=float, default=0.01, help="the jump [rad]")
    ap.add_argument("--faults", nargs="+", default=list(LOG_FAULTS), choices=LOG_FAULTS)
    ap.add_argument("--parts", nargs="+", default=["clean", "faults"])
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    command = "tools/watchdog_innovation.py " + " ".join(argv or sys.argv[1:])
    out: dict[str, Any] = {"commands": [], "candidates": list(CANDIDATES), "scenarios": {}}
    if args.out.is_file():  # merge
        out = json.loads(args.out.read_text())
    out["commands"].append(command)
    for name in args.scenarios:
        sc0 = load_scenario(name).with_overrides(duration=args.duration)
        lib = library_for(sc0)
        res: dict[str, Any] = out["scenarios"].setdefault(name, {})
        for kind, positions in KINDS:
            key = f"{kind}-{positions}"
            row: dict[str, Any] = res.setdefault(key, {})
            if "clean" in args.parts:
                seeds = range(args.first_seed, args.first_seed + args.seeds)
                peaks = []
                for seed in seeds:
                    p = play_watched(sc0.with_overrides(seed=seed), lib, kind, positions,
                                     bounds=OFF)  # fmt: skip
                    peaks.append(float(np.nanmax(p.means)))
                    print(name, key, seed, peaks[-1], flush=True)
                row["clean"] = {"seeds": [seeds.start, seeds.stop], "duration": args.duration,
                                "max": max(peaks), "per_seed": peaks}  # fmt: skip
            if "faults" in args.parts:
                faults: dict[str, Any] = row.setdefault("faults", {})
                for fault in args.faults:
                    if fault.startswith("torque") and kind == "none":
                        continue
                    runs = []
                    for seed in range(args.fault_seeds):
                        sc = sc0.with_overrides(seed=seed, duration=args.fault_at + 0.5)
                        p = play_watched(sc, lib, kind, positions, fault, args.fault_at,
                                         size=args.jump, bounds=OFF)  # fmt: skip
                        k0 = round(args.fault_at / p.T)
                        after = p.means[k0:]
                        delays = {}
                        for b in CANDIDATES:
                            hit = np.flatnonzero(after > b)
                            delays[str(b)] = None if hit.size == 0 else float(hit[0] * p.T)
                        failed = None if p.hold is None else p.hold.name
                        runs.append({"seed": seed, "max_after": float(np.nanmax(after)),
                                     "delay": delays, "held": failed,
                                     "held_after": None if p.hold_t is None
                                     else p.hold_t - args.fault_at})  # fmt: skip
                        print(name, key, fault, runs[-1], flush=True)
                    label = fault if fault != "jump" else f"jump {args.jump:g}"
                    faults[label] = runs
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
