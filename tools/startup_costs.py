"""The fixed costs of a Python process around ``amsfe estimate`` (docs/how-to/logs.md, "The
command, end to end"): fresh processes, the median of ``--repeat``.

- wall time from spawn to exit of ``python -c pass``, ``import numpy``, ``import
  amsfe_sym.apps.cli`` (the command line) and of the packages ``amsfe estimate --no-plots``
  loads (numpy, scipy.linalg, scipy.special, pyarrow.parquet, rosbags' writer and type
  store, mcap, zstandard, tqdm);
- the interpreter's exit with those loaded: the spawn-to-exit wall time less the child's own
  age at its last line (``/proc/self/stat``), against the same with ``os._exit(0)``;
- ``--laps LOG``: ``amsfe estimate LOG --no-plots`` in this process, each lap of its phase
  timer (``apps/estimate.py``) with the packages first imported in it.

    PYTHONPATH=src .venv/bin/python tools/startup_costs.py [--repeat 5] [--laps LOG]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

LOADED = (
    "numpy, scipy.linalg, scipy.special, pyarrow.parquet, rosbags.rosbag2, rosbags.typesys, "
    "mcap.reader, zstandard, tqdm"
)
AGE = "from amsfe_sym.apps.phases import process_age_s"


def _wall(code: str) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, out.stdout


def laps(log: str) -> None:
    """The phases of one ``amsfe estimate LOG --no-plots`` with their new packages."""
    from amsfe_sym.apps import phases
    from amsfe_sym.apps.cli import main

    seen = {m.split(".")[0] for m in sys.modules}
    lap = phases.Phases.lap

    def noted(self: phases.Phases, phase: str) -> float:
        nonlocal seen
        now = {m.split(".")[0] for m in sys.modules}
        new = sorted(m for m in now - seen if not m.startswith("_"))
        seen = now
        print(f"  lap {phase:8s} {time.perf_counter() - self.last:.3f} s  new: {new}")
        return lap(self, phase)

    phases.Phases.lap = noted  # type: ignore[method-assign]
    out = Path("/tmp/amsfe-startup-costs")
    main(["estimate", log, "--out", str(out), "--no-plots", "--force"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--laps", metavar="LOG", default=None)
    args = p.parse_args()
    if args.laps:
        laps(args.laps)
        return
    rows = {
        "python -c pass": "pass",
        "import numpy": "import numpy",
        "import amsfe_sym.apps.cli": "import amsfe_sym.apps.cli",
        "import what estimate loads": f"import {LOADED}",
    }
    print(f"load average {os.getloadavg()[0]:.2f}; median of {args.repeat} fresh processes")
    for label, code in rows.items():
        w = statistics.median(_wall(code)[0] for _ in range(args.repeat))
        print(f"  {label:28s} {w:.3f} s")
    for label, end in (("exit (normal)", ""), ("exit (os._exit)", "; os._exit(0)")):
        code = f"import os; {AGE}; import {LOADED}; print(process_age_s(), flush=True){end}"
        tails = []
        for _ in range(args.repeat):
            wall, out = _wall(code)
            tails.append(wall - float(out))
        print(f"  {label:28s} {statistics.median(tails):.3f} s after the last line")
    print(f"  load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
