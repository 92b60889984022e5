"""Free running at 1 kHz beside two CPU hogs (C node, C arm, paper-sim, 2 s), N runs: the link
tracking RMSE over the run's window against the in-process run of the same seed (the ratio),
and whether it held.  The measurement behind docs/live-load.md's "Free running under two
hogs"; tests/test_carm.py asserts the same outcome with a margin.

    PYTHONPATH=src .venv/bin/python tools/free_running_ratio.py 5
"""

import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests' DDS helpers

import numpy as np
from tests.test_live_load import _hold, _stop_arm
from tests.test_node_record import _bag
from tests.test_ros import _finish, _ros_env, _start

from amsfe_sym.codegen import library_for
from amsfe_sym.core.cpu_load import CpuHogs
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import window

sc = load_scenario("paper-sim").with_overrides(duration=2.0)
ref = run(sc, library_for(sc), runtime="compiled")
n, T = ref.lib.n, round(ref.lib.T * 1e9)
for i in range(int(sys.argv[1])):
    tmp = Path(tempfile.mkdtemp())
    env = _ros_env(tmp)
    rec = tmp / "rec"
    procs: list[Any] = []
    with CpuHogs(2, limit_s=600):
        try:
            node = _start(
                env,
                "node",
                "paper-sim",
                "--controller",
                "amsfe",
                "--duration",
                "2",
                "--record",
                str(rec),
                "--impl",
                "c",
            )
            sim = _start(
                env,
                "sim-node",
                "paper-sim",
                "--duration",
                "2",
                "--start-timeout",
                "120",
                "--impl",
                "c",
            )
            procs += [node, sim]
            code, text = _stop_arm(sim, node, 300.0)
        finally:
            _finish(procs, 60.0)
    hold = _hold(text)
    bag = _bag(rec)
    js = bag["/joint_states"]
    ks = np.array([(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec) // T for m in js])
    w = ks >= window(ref.t.size).start
    q = np.array([m.position for m in js])[w]
    got = np.sqrt(np.mean((q - ref.q_des[ks[w]]) ** 2, axis=0))
    want = np.sqrt(np.mean((ref.x_true[ks[w], :n] - ref.q_des[ks[w]]) ** 2, axis=0))
    print(
        f"run {i}: exit {code} hold {hold} rmse live {got} in-process {want} ratio {got / want}",
        flush=True,
    )
