"""Instructions per tick of the compiled closed loop, and where they go (valgrind callgrind).

    .venv/bin/python tools/loop_instructions.py [--duration 2] [paper-sim ur5-control ...]

The real-time factor of ``amsfe bench`` moves by 1.5-2x on these shared virtual machines
(the same binary, minutes apart); an instruction count does not.  For each scenario (default
paper-sim, ur5-control, panda-control, their own estimator and controller), one Python
process runs ``run(sc, lib, runtime="compiled")`` for ``--duration`` simulated seconds under
``valgrind --tool=callgrind``, and the inclusive instructions of the C functions are read
off: everything the loop's ctypes call ran (``ffi_call``: ``amsfe_sim_run`` and the few
set-up calls), the estimator's tick (``amsfe_est_tick``) and late frames
(``amsfe_est_camera_frame``), the truth plant (``plant_step``, all its substeps) and the
controller (``amsfe_ctrl_torque``).  Divided by the ticks: instructions per tick.  With
``--wall``, the compiled loop is also timed outside valgrind (median of 3 runs of 10 s) to
give this machine's nanoseconds per instruction at that moment.  Writes
docs/data/loop-instructions.json and .md.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tools"))
from tick_instructions import callgrind, write_report  # noqa: E402  (a sibling tool)

SCENARIOS = ("paper-sim", "ur5-control", "panda-control")
PARTS = {
    "loop": "ffi_call",
    "estimator_tick": "amsfe_est_tick",
    "late_frames": "amsfe_est_camera_frame",
    "plant": "plant_step",
    "controller": "amsfe_ctrl_torque",
}

RUN = r"""
import sys
from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
sc = load_scenario(sys.argv[1]).with_overrides(duration=float(sys.argv[2]))
lib = library_for(sc)
if sys.argv[3] == "run":
    res = run(sc, lib, runtime="compiled")
    print(res.t.size, res.wall_time_s)
"""


def _python(*args: str) -> list[str]:
    return [sys.executable, "-c", RUN, *args]


def count(name: str, duration: float, work: Path) -> dict[str, Any]:
    """Inclusive instructions of :data:`PARTS` over one compiled run of ``name``."""
    subprocess.run(_python(name, str(duration), "build"), check=True)  # outside valgrind
    stdout, found = callgrind(
        _python(name, str(duration), "run"), work / f"{name}.callgrind", list(PARTS.values())
    )
    ticks = int(stdout.split()[0])
    row: dict[str, Any] = {"ticks": ticks}
    for key, fn in PARTS.items():
        row[key] = round(found[fn] / ticks)
    row["other"] = row["loop"] - sum(row[k] for k in PARTS if k != "loop")
    return row


def wall(name: str) -> float:
    """Median wall time per tick [us] of 3 compiled 10 s runs, outside valgrind."""
    per = []
    for _ in range(3):
        out = subprocess.run(
            _python(name, "10", "run"), capture_output=True, text=True, check=True
        ).stdout.split()
        per.append(1e6 * float(out[1]) / int(out[0]))
    return statistics.median(per)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--duration", type=float, default=2.0, help="simulated time under valgrind")
    ap.add_argument("--wall", action="store_true", help="also time the loop outside valgrind")
    ap.add_argument("--out", default=str(REPO / "docs" / "data"))
    args = ap.parse_args()
    if shutil.which("valgrind") is None:
        raise SystemExit("expected valgrind on PATH, found none: install valgrind and retry")
    from amsfe_sym.core.provenance import cpu_name, git_revision

    t0 = time.time()
    rows = {}
    with tempfile.TemporaryDirectory(prefix="amsfe-loop-instr-") as tmp:
        for name in args.scenarios:
            rows[name] = count(name, args.duration, Path(tmp))
            if args.wall:
                us = wall(name)
                rows[name]["wall_us_per_tick"] = round(us, 2)
                rows[name]["ns_per_instruction"] = round(1e3 * us / rows[name]["loop"], 4)
            print(f"[loop-instructions] {name}: {rows[name]}", flush=True)
    rev, dirty = git_revision()
    report = {
        "command": "tools/loop_instructions.py " + " ".join(sys.argv[1:]),
        "commit": rev + (" (dirty)" if dirty else ""),
        "machine": f"{cpu_name()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}",
        "seconds": round(time.time() - t0, 1),
        "rows": rows,
    }
    write_report(Path(args.out), "loop-instructions", report, markdown(report))


def markdown(r: dict[str, Any]) -> str:
    """The table of a report."""
    lines = [
        "# Instructions per tick of the compiled closed loop (callgrind)",
        "",
        f"`{r['command']}` at {r['commit']}; {r['machine']}; {r['seconds']} s.  Written by "
        "tools/loop_instructions.py.  Inclusive instructions per tick; `other`: encoders, "
        "camera, disturbance, records, NEES.",
        "",
        "| scenario | loop | estimator tick | late frames | plant | controller | other "
        "| wall [us/tick] | ns per instruction |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, w in r["rows"].items():
        lines.append(
            f"| {name} | {w['loop']:,} | {w['estimator_tick']:,} | {w['late_frames']:,} | "
            f"{w['plant']:,} | {w['controller']:,} | {w['other']:,} | "
            f"{w.get('wall_us_per_tick', '-')} | {w.get('ns_per_instruction', '-')} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
