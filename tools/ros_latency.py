"""Latency of ``amsfe node`` over ROS 2 (docs/how-to/ros.md, "Latency"): encoder sample published by
``amsfe sim-node`` -> estimate received, and -> command received, p50 / p99 / max, per
scenario; beside it what the node's work costs in process (the live loop's estimator +
controller per sample, no middleware), so the difference is what rclpy and DDS cost.

    PYTHONPATH=src .venv/bin/python tools/ros_latency.py [--duration 2] [--free-running]
        [--scenarios paper-sim,ur5-control,panda-control]

Lockstep (default): the arm waits for each command, so every sample meets an idle node (the
latency of one sample, no queue).  ``--free-running``: the arm on the wall clock at the
robot's rate (1 kHz): the node must keep up, or it falls behind and holds.
Each run uses ROS_DOMAIN_ID 90 (or the environment's) on localhost.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time

import numpy as np


def in_process(scenario: str, duration: float) -> tuple[float, float]:
    """p50, p99 [us] of one live-loop sample (estimator step + controller), in process."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.ros.arm import SimArm
    from amsfe_sym.ros.live import LiveLoop
    from amsfe_sym.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration=duration)
    lib = library_for(sc)
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True)
    T_ns = round(lib.T * 1e9)
    cost = np.zeros(arm.K)
    for k in range(arm.K):
        s = arm.sense()
        t0 = time.perf_counter()
        for f in s.frames:
            loop.frame(f.exposure_step * T_ns, f.z)
        out = loop.encoders(k * T_ns, s.z)
        cost[k] = time.perf_counter() - t0
        assert out is not None and out.u is not None
        if k + 1 < arm.K:
            arm.advance(out.u)
    p50, p99 = np.percentile(cost[1:], [50, 99]) * 1e6
    return float(p50), float(p99)


def over_dds(scenario: str, duration: float, free: bool) -> str:
    """The sim-node's latency line (and how the node stopped)."""
    env = dict(os.environ)
    env.setdefault("ROS_DOMAIN_ID", "90")
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    amsfe = [sys.executable, "-m", "amsfe_sym"]
    d = f"{duration:g}"
    mode = [] if free else ["--lockstep"]
    node = subprocess.Popen(
        [*amsfe, "node", scenario, "--controller", "", "--duration", d],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        sim = subprocess.run(
            [*amsfe, "sim-node", scenario, "--duration", d, *mode],
            env=env, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        node_out, _ = node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait()
    lat = re.findall(r"sim-node: (encoder -> .*)", sim.stdout)
    ticks = re.findall(r"sim-node: (\d+ ticks .*)", sim.stdout)
    stopped = re.findall(r"node: ((?:done|hold).*?)(?:;|$)", node_out, re.M)
    return " | ".join([*lat, *ticks, *(f"node {s}" for s in stopped)]) or sim.stderr[-300:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="paper-sim,ur5-control,panda-control")
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--free-running", action="store_true")
    a = ap.parse_args()
    import logging

    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    for scn in a.scenarios.split(","):
        p50, p99 = in_process(scn, a.duration)
        print(f"{scn}: in process, estimator + controller per sample p50 {p50:.0f} us, "
              f"p99 {p99:.0f} us", flush=True)  # fmt: skip
        print(f"{scn}: over DDS ({'free running' if a.free_running else 'lockstep'}): "
              f"{over_dds(scn, a.duration, a.free_running)}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
