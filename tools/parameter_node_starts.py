"""Start and stop the C node's short-lived rclpy parameter node in many fresh processes
(docs/live-control.md, "When a C program crashes"): a CI run's ``amsfe live --impl c`` lost
its node process to SIGSEGV before the C node's first line, where the Python node reads its
ROS parameters with such a node (``ros/cnode.py``'s ``_resolved_spec``).

    PYTHONPATH=src .venv/bin/python tools/parameter_node_starts.py [--starts 400] [--hogs 1]
        [--domain 77]

Each start is a new interpreter (as ``amsfe node`` is) with faulthandler on, which imports
rclpy, starts a context on ``--domain``, creates the parameter node, reads the spec's
parameters and stops; CPU hogs run beside (``core.cpu_load.CpuHogs``).  Prints a line per
start that did not exit 0 (its code and its last output lines) and a summary; exit status 1
when any did.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from amsfe_sym.core.cpu_load import CpuHogs

ONE_START = """
import faulthandler
faulthandler.enable()
from amsfe_sym.ros.cnode import _resolved_spec
from amsfe_sym.topics.spec import TopicSpec
spec, every = _resolved_spec(TopicSpec(), ("j1", "j2"), (), {domain}, 1)
print("read", every)
"""


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=400)
    ap.add_argument("--hogs", type=int, default=1)
    ap.add_argument("--domain", type=int, default=77, help="ROS_DOMAIN_ID of every start")
    args = ap.parse_args(argv)
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    failed = 0
    with CpuHogs(args.hogs, limit_s=3600.0):
        for i in range(args.starts):
            proc = subprocess.run(
                [sys.executable, "-c", ONE_START.format(domain=args.domain)],
                env=env,
                capture_output=True,
                text=True,
                timeout=120,
            )
            if proc.returncode != 0:
                failed += 1
                tail = (proc.stderr or proc.stdout).strip().splitlines()[-8:]
                print(f"start {i}: exit {proc.returncode}", *tail, sep="\n  ", flush=True)
    print(f"{args.starts} starts, {failed} not exit 0 ({args.hogs} CPU hogs beside)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
