"""What the node's record costs (docs/live-load.md, "The record"): ``NodeRecord`` fed the
ticks of a paper-sim run (five times over: 10 005 ticks), streamed to a temporary folder in
segments written by its writer thread; the time of the calls of a tick (p50, the largest:
a call that waited for the writer) and of the final write, and the segments written.

    PYTHONPATH=src .venv/bin/python tools/record_cost.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.record import SEGMENT_TICKS, NodeRecord
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.topics import TopicSpec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    lib = library_for(sc)
    res = run(sc, lib, runtime="compiled")
    out = Path(tempfile.mkdtemp()) / "rec"
    rec = NodeRecord(sc, lib, TopicSpec(), lib.manifest.joints, out)
    T = round(lib.T * 1e9)
    per = []
    t_all = time.perf_counter()
    for rep in range(a.repeat):
        for k in range(res.t.size):
            kk = rep * res.t.size + k
            t0 = time.perf_counter()
            rec.applied(kk * T, res.u[k])
            rec.truth_sent(10 * kk + 1, res.x_true[k])
            rec.encoders(kk * T, res.z_enc[k], 10 * kk + 5)
            rec.outputs(kk * T, res.x_hat[k], np.zeros(lib.N), res.x_hat[k, 4 * lib.n :], res.u[k])
            per.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    rec.write(reason="done")
    end = time.perf_counter()
    ticks = len(per)
    print(
        f"{ticks} ticks, segments of {SEGMENT_TICKS}: a tick's calls p50 "
        f"{np.median(per) * 1e6:.1f} us, max {max(per) * 1e3:.1f} ms; final write "
        f"{(end - t0) * 1e3:.0f} ms; all {(end - t_all) / ticks * 1e3:.3f} ms a tick; "
        f"{len(list(out.glob('*.mcap')))} segment files"
    )


if __name__ == "__main__":
    main()
