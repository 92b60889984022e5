"""Free running at 1 kHz beside two CPU hogs (C node, C arm, paper-sim, 2 s), N runs: the link
tracking RMSE over the run's window against the in-process run of the same seed (the ratio),
and whether it held.  The measurement behind docs/live-load.md's free-running rows; the run
and the RMSE are tests/test_live_load.py's (``free_running_run``, ``free_running_rmse``),
whose test asserts the outcome with a margin.

    PYTHONPATH=src .venv/bin/python tools/free_running_ratio.py 5
"""

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests' DDS helpers

from tests.test_live_load import _hold, free_running_rmse, free_running_run

C = ["--impl", "c"]
for i in range(int(sys.argv[1])):
    code, text, bag, _ = free_running_run(Path(tempfile.mkdtemp()), C, C)
    got, want, _, _ = free_running_rmse(bag)
    print(f"run {i}: exit {code} hold {_hold(text)} rmse live {got} in-process {want} "
          f"ratio {got / want}", flush=True)  # fmt: skip
