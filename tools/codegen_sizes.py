"""Size and build time of generated libraries (docs/explanation/codegen.md, "Structure kept through
generation"): lines of C per library and of its largest functions, generate + compile wall
time cold (a fresh output folder, in a new process), the compile's peak memory, and the rk4
step's C time (generated ``transition_step`` vs the chained ``transition_step_chain``).

Run it once per source tree to compare two versions on the same machine, e.g.::

    PYTHONPATH=src .venv/bin/python tools/codegen_sizes.py --label after \\
        --out docs/data/codegen-sizes.json

Robots: the paper's 2-link arm and the UR5 with the rk4 model, the Franka Panda of
example-robot-data (fingers locked, rk4), and the arm-like chains of ``amsfe bench``
(7 and 12 joints).  Nothing here is asserted by a test: the machine and its load move
the times (the JSON records both).
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_GEN = r"""
import json, sys
from dataclasses import replace
from importlib import metadata
from amsfe_sym.codegen import generate
from amsfe_sym.load.spec import load_spec
robot, out = sys.argv[1], sys.argv[2]
if robot == "panda-erd":
    path = metadata.distribution("example-robot-data").locate_file(
        "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf")
    spec = load_spec(str(path)).with_locked({"panda_finger_joint1": 0.02,
                                             "panda_finger_joint2": 0.02})
    spec = replace(spec, name="panda_erd")
else:
    spec = load_spec(robot)
spec = replace(spec, model=replace(spec.model, integrator="rk4"))
r = generate(spec, out=out, force=True)
print(json.dumps({"dir": str(r.out_dir), "timings": r.timings}))
"""


def _functions(c_file: Path) -> dict[str, int]:
    lines = c_file.read_text().split("\n")
    starts = [
        (i, m.group(1))
        for i, line in enumerate(lines)
        if (m := re.match(r"^/\* ([A-Za-z0-9_]+):\(", line))
    ]
    ends = [i for i, _ in starts[1:]] + [len(lines)]
    return {name: end - i for (i, name), end in zip(starts, ends, strict=True)}


def measure(robot: str, workdir: Path) -> dict[str, object]:
    """Generate ``robot`` cold in a new process and measure the library."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _GEN, robot, str(workdir)],
        capture_output=True,
        text=True,
        check=True,
    )
    wall = time.perf_counter() - t0
    peak_mb = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) / 1024
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    out = Path(res["dir"])
    c_files = sorted(out.glob("*.c"))
    total = sum(p.read_text().count("\n") for p in c_files)
    fns = _functions(out / f"{out.name}.c")
    top = dict(sorted(fns.items(), key=lambda kv: -kv[1])[:8])
    return {
        "robot": robot,
        "lines_of_c": total,
        "largest_functions": top,
        "generate_compile_s": round(wall, 2),
        "timings_s": {k: round(v, 2) for k, v in res["timings"].items()},
        "peak_child_rss_mb": round(peak_mb, 1),
        "step_us": _step_times(out),
    }


def _step_times(out: Path) -> dict[str, float]:
    import numpy as np

    from amsfe_sym.apps.bench.timing import CTimer
    from amsfe_sym.runtime.library import ModelLibrary

    lib = ModelLibrary(out)
    rng = np.random.default_rng(0)
    x, u = rng.uniform(-0.5, 0.5, lib.N), rng.uniform(-1.0, 1.0, lib.n)
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        timer = CTimer(Path(tmp))
        for name in ("transition_step", "transition_step_chain"):
            if name in lib.manifest.functions:
                t, _ = timer.time(lib.library_path, name, [x, u], 5)
                times[name] = round(t.median_us, 2)
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--label", default="current", help="name of this source tree's column")
    ap.add_argument("--out", type=Path, default=None, help="JSON file to add the column to")
    ap.add_argument(
        "--robots",
        default="paper_2link,ur5,panda-erd,chain7,chain12",
        help="comma-separated: shipped names, panda-erd, chainN",
    )
    args = ap.parse_args(argv)
    from amsfe_sym.apps.bench.scaling import chain_urdf

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for robot in args.robots.split(","):
            name = robot
            if robot.startswith("chain"):
                urdf = Path(tmp) / f"{robot}.urdf"
                urdf.write_text(chain_urdf(int(robot[5:])))
                name = str(urdf)
            row = measure(name, Path(tmp) / "gen")
            row["robot"] = robot
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.out:
        data = json.loads(args.out.read_text()) if args.out.is_file() else {}
        data[args.label] = {"machine": _machine(), "rows": rows}
        args.out.write_text(json.dumps(data, indent=2) + "\n")
    return 0


def _machine() -> dict[str, object]:
    import os
    import platform

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load": os.getloadavg(),
        "python": platform.python_version(),
    }


if __name__ == "__main__":
    sys.exit(main())
