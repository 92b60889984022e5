"""The C node and the Python node side by side over DDS (docs/live-control.md's table).

    PYTHONPATH=src .venv/bin/python tools/live_compare.py [--scenarios paper-sim panda-control]
        [--duration 2] [--modes lockstep free]

Runs ``amsfe live SCENARIO --controller amsfe --impl IMPL [--lockstep]`` for each scenario,
mode and implementation on a fresh ROS domain, and prints one markdown row per run: the
node's own latency (its line: sample received by the middleware -> command published,
p50 / p99 / max), the arm's encoder -> command latency through DDS (p50 / p99 / max), the
free-running arm's ticks without a new command, and how the node ended.  Also the machine
(CPU model) and the load average at the start.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

NODE = re.compile(
    r"node: latency sample received -> command published p50 (\S+) p99 (\S+) max (\S+) ms"
)
ARM = re.compile(r"encoder -> command p50 (\S+) p99 (\S+) max (\S+) ms")
STALE = re.compile(r"(\d+) late ticks, (\d+) without a new command")


def _cpu() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenarios", nargs="+", default=["paper-sim", "panda-control"])
    p.add_argument("--modes", nargs="+", default=["lockstep", "free"])
    p.add_argument("--impls", nargs="+", default=["c", "python"])
    p.add_argument("--duration", type=float, default=2.0)
    args = p.parse_args(argv)
    print(f"machine: {_cpu()}, {os.cpu_count()} cores; load average at start: "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}")  # fmt: skip
    print("| scenario | mode | node | node's own latency p50 / p99 / max [ms] | "
          "encoder -> command through DDS p50 / p99 / max [ms] | ticks without a new command "
          "| end |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    domain = 40 + os.getpid() % 50
    for sc in args.scenarios:
        for mode in args.modes:
            for impl in args.impls:
                domain += 1
                env = {**os.environ, "ROS_DOMAIN_ID": str(domain),
                       "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}  # fmt: skip
                cmd = [sys.executable, "-m", "amsfe_sym", "live", sc, "--controller", "amsfe",
                       "--duration", f"{args.duration:g}", "--impl", impl,
                       "--command-timeout", "60", "--encoder-timeout", "5"]  # fmt: skip
                if mode == "lockstep":
                    cmd.append("--lockstep")
                t0 = time.monotonic()
                out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
                text = out.stdout + out.stderr
                node = NODE.search(text)
                arm = ARM.search(text)
                stale = STALE.search(text)
                ends = [ln[len("node: "):] for ln in text.splitlines()
                        if ln.startswith(("node: done", "node: hold"))]  # fmt: skip
                end = (ends[0].split(";")[0] if ends else f"exit {out.returncode}")[:90]
                row = [
                    sc,
                    mode,
                    impl,
                    " / ".join(node.groups()) if node else "-",
                    " / ".join(arm.groups()) if arm else "-",
                    stale.group(2) if stale else "-",
                    f"{end} ({time.monotonic() - t0:.0f} s wall)",
                ]
                print("| " + " | ".join(row) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
