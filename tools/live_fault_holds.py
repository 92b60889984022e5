"""When the node's watchdogs hold after a fault of the simulated arm, in process
(docs/live-load.md, "Load tests"): ``SimArm`` + ``FaultPlan`` + ``LiveLoop.watch`` tick by
tick on a simulated clock (no middleware, no load), the node's view of the effort topic
optional (``--effort``: the torque the arm applied reaches the estimator, as over DDS).

    PYTHONPATH=src .venv/bin/python tools/live_fault_holds.py [--seeds 0,1,2]
        [--times 0.5,1.5] [--effort]

Prints, per fault time, seed and fault, the tick and reason of the hold (None: no hold in the
0.6 s after the fault).
"""

from __future__ import annotations

import argparse

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.faults import Fault, FaultPlan
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.ros.watchdog import REASON_NAMES
from amsfe_sym.scenario import load_scenario


def hold_after(scenario: str, fault: Fault, seed: int, effort: bool) -> tuple[int, str] | None:
    """(tick, reason) of the first hold of a run with ``fault``, None without one."""
    sc = load_scenario(scenario).with_overrides(duration=fault.t + 0.6, seed=seed)
    lib = library_for(sc)
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True)
    plan = FaultPlan((fault,), lib.T, lib.n)
    T = round(lib.T * 1e9)
    for k in range(arm.K):
        s = arm.sense()
        for f in s.frames:
            loop.frame(f.exposure_step * T, f.z)
        t = k * lib.T
        w = loop.watch(k * T, plan.encoders(k, s.z), None, taken=t, clock=lambda t=t: t + 1e-4)
        if w.reason != 0:
            return k, REASON_NAMES[w.reason]
        assert w.out is not None and w.out.u is not None
        applied = plan.torque(k, w.out.u)
        if effort:
            loop.applied(k * T, applied)
        arm.advance(applied)
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper-sim")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--times", default="0.5,1.0")
    ap.add_argument("--effort", action="store_true", help="the applied torque reaches the node")
    a = ap.parse_args()
    for tf in (float(x) for x in a.times.split(",")):
        for seed in (int(x) for x in a.seeds.split(",")):
            for fault in (
                Fault("encoder_frozen", tf),
                Fault("encoder_jump", tf, 0.2),
                Fault("torque_loss", tf),
            ):
                print(tf, seed, fault.label(), hold_after(a.scenario, fault, seed, a.effort))


if __name__ == "__main__":
    main()
