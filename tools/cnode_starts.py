"""Start the C node and the C arm many times (issue 34's SIGSEGV at start under load):
each start a lockstep run with a fault, CPU hogs beside it, core dumps on, optionally the
AddressSanitizer + UBSan build of both programs (``--sanitize``).

    PYTHONPATH=src .venv/bin/python tools/cnode_starts.py [--starts 30] [--hogs 2]
        [--fault torque_loss@0.5] [--duration 1] [--sanitize] [--domain D] [--kill-odd]
        [--out DIR]

``--sanitize`` instruments the programs' own sources (``ros/c``), not the generated library
(its estimator, controller and watchdogs): for those, compile the library's sources with the
same flags into the sanitizer build's folder (its RPATH reaches that copy first).
``--domain D --kill-odd``: every start on one ROS_DOMAIN_ID, every odd one SIGKILLed mid-run
(the shared memory of killed participants left behind, as a test's cleanup leaves it).

The parameter files are written once by ``amsfe node`` / ``amsfe sim-node`` themselves (their
``--node-exe`` / ``--arm-exe`` is a wrapper keeping a copy), then every start runs the two
executables directly (no Python between starts: ~1 s a start instead of ~8).  Prints, per
start, the two exit codes (the node's 3: the fault's hold; the arm's 0), and for a node or arm
killed by a signal its output, the sanitizer's report and gdb's backtrace of its core.
Exit status 1 when any start ended by a signal or a sanitizer's report.
"""

from __future__ import annotations

import argparse
import os
import random
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from amsfe_sym.codegen import library_for
from amsfe_sym.core.cpu_load import CpuHogs
from amsfe_sym.ros.carm import build_arm
from amsfe_sym.ros.cnode_build import EXTRA_FLAGS_ENV, build_node
from amsfe_sym.ros.middleware import DEFAULT_RMW, LOCKSTEP_PROFILE
from amsfe_sym.scenario import load_scenario

#: The sanitizer build's flags (cnode_build's EXTRA_FLAGS_ENV).
SANITIZE = "-g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all"
#: A wrapper kept as --node-exe / --arm-exe: copies its parameter folder and argv, then runs.
WRAPPER = """#!/bin/sh
mkdir -p '{keep}'
cp -a "$(dirname "$1")/." '{keep}/'
printf '%s\\n' "$1" > '{keep}/params'
exec '{exe}' "$@"
"""


def _core_on() -> None:
    resource.setrlimit(resource.RLIMIT_CORE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    os.setsid()


def _env(domain: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("RMW_IMPLEMENTATION", DEFAULT_RMW)
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.pop("LD_BIND_NOW", None)
    env.setdefault("ASAN_OPTIONS", "detect_leaks=0:abort_on_error=1:disable_coredump=0")
    env.setdefault("UBSAN_OPTIONS", "print_stacktrace=1")
    return env


def capture(out: Path, scenario: str, fault: str, duration: float, exes: dict[str, Path]) -> None:
    """One run through ``amsfe`` with wrappers keeping each program's parameter folder."""
    env = _env(random.randint(150, 230))
    procs = []
    for role, cmd in (
        ("node", ["node", scenario, "--controller", "amsfe", "--duration", str(duration),
                  "--record", str(out / "capture-rec"), "--node-exe"]),
        ("arm", ["sim-node", scenario, "--lockstep", "--duration", str(duration), "--fault",
                 fault, "--start-timeout", "60", "--command-timeout", "30", "--arm-exe"]),
    ):  # fmt: skip
        wrap = out / f"{role}.sh"
        wrap.write_text(WRAPPER.format(keep=out / role, exe=exes[role]))
        wrap.chmod(0o755)
        log = (out / f"capture-{role}.txt").open("w")
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "amsfe_sym", *cmd, str(wrap)],
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        )
    for p in procs:
        p.wait(timeout=300)
    for role in ("node", "arm"):  # the copied parameters point to the copy
        old = str(Path((out / role / "params").read_text().strip()).parent)
        for f in (out / role).glob("*.txt"):
            f.write_text(f.read_text().replace(old, str(out / role)))


def _backtrace(exe: Path, folder: Path) -> str:
    cores = sorted(folder.glob("core*"))
    if not cores or shutil.which("gdb") is None:
        return f"(no core in {folder})"
    gdb = ["gdb", "-q", "-batch", "-ex", "thread apply all bt 20", str(exe), str(cores[0])]
    return subprocess.run(gdb, capture_output=True, text=True).stdout[-12000:]


def one_start(
    i: int, out: Path, exes: dict[str, Path], domain: int | None, kill_after: float | None
) -> tuple[int, int, str]:
    """One lockstep run of the two programs (both SIGKILLed after ``kill_after`` [s] when
    given, as a test's ``finally`` kills what is left: their shared memory stays behind):
    their exit codes and what to report."""
    folder = out / f"start{i:03d}"
    folder.mkdir()
    env = _env(random.randint(150, 230) if domain is None else domain)
    procs = {}
    for role in ("node", "arm"):
        e = dict(env)
        if role == "arm":
            e.setdefault("FASTDDS_DEFAULT_PROFILES_FILE", str(LOCKSTEP_PROFILE))
        params = out / role / Path((out / role / "params").read_text().strip()).name
        procs[role] = subprocess.Popen(
            [str(exes[role]), str(params)], env=e, cwd=folder, preexec_fn=_core_on,
            stdout=(folder / f"{role}.txt").open("w"), stderr=subprocess.STDOUT,
        )  # fmt: skip
    if kill_after is not None:
        time.sleep(kill_after)
        for p in procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    codes = {}
    for role in ("node", "arm"):  # the node holds; the arm then waits for a command: stopped
        try:
            codes[role] = procs[role].wait(timeout=90 if role == "node" else 10)
        except subprocess.TimeoutExpired:
            os.killpg(procs[role].pid, signal.SIGKILL)
            codes[role] = procs[role].wait()
        if role == "node" and procs["arm"].poll() is None:
            os.killpg(procs["arm"].pid, signal.SIGTERM)
    report = ""
    for role in ("node", "arm"):
        text = (folder / f"{role}.txt").read_text(errors="replace")
        if (
            (codes[role] < 0 and codes[role] != -signal.SIGKILL)
            or "ERROR: AddressSanitizer" in text
            or "runtime error:" in text
        ):
            report += f"--- {role} exit {codes[role]}:\n{text[-8000:]}\n"
            report += _backtrace(exes[role], folder) + "\n"
    return codes["node"], codes["arm"], report


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=30)
    ap.add_argument("--hogs", type=int, default=2)
    ap.add_argument("--scenario", default="paper-sim")
    ap.add_argument("--fault", default="torque_loss@0.5")
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--sanitize", action="store_true", help="AddressSanitizer + UBSan build")
    ap.add_argument("--domain", type=int, default=None, help="one ROS_DOMAIN_ID for all")
    ap.add_argument(
        "--kill-odd",
        action="store_true",
        help="SIGKILL every odd start's two programs 0.1-1.5 s after it starts",
    )
    ap.add_argument("--out", type=Path, default=None, help="folder kept (default: temporary)")
    args = ap.parse_args()
    if args.sanitize:
        os.environ[EXTRA_FLAGS_ENV] = SANITIZE
    out = args.out or Path(tempfile.mkdtemp(prefix="cnode_starts_"))
    out.mkdir(parents=True, exist_ok=True)
    sc = load_scenario(args.scenario)
    lib = library_for(sc)
    exes = {"node": build_node(lib).path, "arm": build_arm(lib).path}
    print(f"node {exes['node']}\narm {exes['arm']}\nfolder {out}", flush=True)
    capture(out, args.scenario, args.fault, args.duration, exes)
    bad = 0
    with CpuHogs(args.hogs, limit_s=3600):
        t0 = time.monotonic()
        for i in range(args.starts):
            kill = random.uniform(0.1, 1.5) if args.kill_odd and i % 2 else None
            node, arm, report = one_start(i, out, exes, args.domain, kill)
            print(f"start {i}: node exit {node}, arm exit {arm}", flush=True)
            if report:
                bad += 1
                print(report, flush=True)
        wall = time.monotonic() - t0
    print(f"{args.starts} starts in {wall:.0f} s, {bad} ended by a signal or a sanitizer's report")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
