"""Instructions per estimator tick and per late frame, before and after a change (valgrind).

    .venv/bin/python tools/tick_instructions.py --base 326b07b [--duration 5]

Wall-clock figures on these shared 2-core machines move by 10-50 % between two runs of the
same binary (docs/explanation/performance.md); an instruction count does not.  For each scenario
(paper-sim, ur5-control, panda-control; oosm), both sides' libraries are built from the same
inputs (the ``--base`` commit's package through ``git archive`` and this worktree's, each in
its own generated/ folder, as tools/kernels_before_after.py does), one closed-loop run of this
side records the inputs (u, encoder samples, camera frames), and ``apps/bench/c/tick_timer.c``
replays them on each library under ``valgrind --tool=callgrind``.  Reported per side:
instructions per ``amsfe_est_tick`` (inclusive: the model, the kernels, the glue) and per
``amsfe_est_camera_frame``, and the largest difference of the final x(k|k) between the
sides.  Writes docs/data/tick-instructions.json and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tools"))
from kernels_before_after import extract_commit  # noqa: E402  (a sibling tool)

SCENARIOS = ("paper-sim", "ur5-control", "panda-control")

#: Run inside one side's package (PYTHONPATH): build each scenario's library, print the dirs.
GEN = r"""
import json, sys
from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
print(json.dumps({name: str(library_for(load_scenario(name)).dir) for name in sys.argv[1:]}))
"""


def build_side(src: Path, gen: Path) -> dict[str, str]:
    """Each scenario's library directory, built by the package at ``src`` into ``gen``."""
    env = dict(os.environ, PYTHONPATH=str(src), AMSFE_GENERATED_DIR=str(gen))
    proc = subprocess.run(
        [sys.executable, "-c", GEN, *SCENARIOS], env=env, capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise SystemExit(f"building the libraries of {src} failed:\n{proc.stderr[-3000:]}")
    out: dict[str, str] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


def callgrind(
    cmd: list[str], out_file: Path, functions: Sequence[str]
) -> tuple[str, dict[str, int]]:
    """Run ``cmd`` under ``valgrind --tool=callgrind``: its stdout, and the inclusive
    instructions of each of ``functions`` (0 for one that never ran)."""
    proc = subprocess.run(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}", *cmd],
        capture_output=True,
        text=True,
        check=True,
    )
    ann = subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", "--threshold=100", str(out_file)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    found = {}
    for name in functions:
        m = re.search(r"^\s*([\d,]+)\s+\([^)]*\)\s+\S*:" + name + r"\b", ann, re.M)
        found[name] = int(m.group(1).replace(",", "")) if m else 0
    return proc.stdout, found


def write_report(out: Path, stem: str, report: dict[str, Any], text: str) -> None:
    """``<stem>.json`` and ``<stem>.md`` in ``out`` (made if missing, as
    tools/check_docs.py's temporary output folder is); the markdown printed too."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / f"{stem}.md").write_text(text)
    print(text)


def count(exe: Path, lib: Path, data: Path, work: Path) -> dict[str, Any]:
    """Inclusive instructions of amsfe_est_tick and amsfe_est_camera_frame over the replay."""
    cmd = [str(exe), str(lib), str(data)]
    stdout, found = callgrind(
        cmd, work / "callgrind.out", ("amsfe_est_tick", "amsfe_est_camera_frame")
    )
    lines = stdout.splitlines()
    x = np.array([float(v) for v in lines[1].split()])
    frames = int(lines[2].split()[2]) if len(lines) > 2 else 0
    return {
        "tick": found["amsfe_est_tick"],
        "frame": found["amsfe_est_camera_frame"],
        "frames": frames,
        "x": x,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="the commit before the change")
    ap.add_argument("--duration", type=float, default=5.0, help="recorded run [s]")
    ap.add_argument("--out", default=str(REPO / "docs" / "data"))
    args = ap.parse_args()
    for tool in ("valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            raise SystemExit(f"expected {tool} on PATH, found none: install valgrind and retry")
    from amsfe_sym.apps.bench.tick import build_tick_timer, record_tick_inputs, write_tick_input
    from amsfe_sym.core.provenance import cpu_name, git_revision
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import load_scenario

    t0 = time.time()
    rows: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="amsfe-instr-") as tmpname:
        tmp = Path(tmpname)
        extract_commit(args.base, tmp / "base")
        sides = {"before": tmp / "base" / "src", "after": REPO / "src"}
        libs = {k: build_side(src, tmp / f"gen-{k}") for k, src in sides.items()}
        exe = build_tick_timer(tmp)
        for name in SCENARIOS:
            lib = ModelLibrary(Path(libs["after"][name]))
            sc = load_scenario(name).with_overrides(duration=args.duration, estimator="oosm")
            data = write_tick_input(
                tmp / f"{name}.bin", "oosm", record_tick_inputs(sc, lib), frames=True
            )
            res = {}
            for k in sides:
                so = next(Path(libs[k][name]).glob("lib*.so"))
                res[k] = count(exe, so, data, tmp)
            ticks = round(args.duration / lib.T)
            rows[name] = {
                "N": lib.N,
                "ticks": ticks,
                "frames": res["after"]["frames"],
                **{f"{k}_per_tick": round(res[k]["tick"] / ticks) for k in sides},
                **{
                    f"{k}_per_frame": round(res[k]["frame"] / max(res[k]["frames"], 1))
                    for k in sides
                },
                "final_x_max_diff": float(np.max(np.abs(res["before"]["x"] - res["after"]["x"]))),
            }
            print(f"[instructions] {name}: {rows[name]}", flush=True)
    rev, dirty = git_revision()
    report = {
        "command": "tools/tick_instructions.py " + " ".join(sys.argv[1:]),
        "base": args.base,
        "after": rev + (" (dirty)" if dirty else ""),
        "machine": f"{cpu_name()}, {os.cpu_count()} CPUs",
        "seconds": round(time.time() - t0, 1),
        "rows": rows,
    }
    write_report(Path(args.out), "tick-instructions", report, markdown(report))


def markdown(r: dict[str, Any]) -> str:
    lines = [
        "# Instructions per oosm tick and per late frame (callgrind)",
        "",
        f"`{r['command']}`: before = `{r['base']}`, after = {r['after']}; {r['machine']}; "
        f"{r['seconds']} s.  Written by tools/tick_instructions.py.",
        "",
        "| scenario | N | per tick before | after | ratio | per frame before | after | ratio "
        "| final x, max difference |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, w in r["rows"].items():
        lines.append(
            f"| {name} | {w['N']} | {w['before_per_tick']:,} | {w['after_per_tick']:,} | "
            f"{w['after_per_tick'] / w['before_per_tick']:.2f} | {w['before_per_frame']:,} | "
            f"{w['after_per_frame']:,} | {w['after_per_frame'] / max(w['before_per_frame'], 1):.2f}"
            f" | {w['final_x_max_diff']:.1e} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
