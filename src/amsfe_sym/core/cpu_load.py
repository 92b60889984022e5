"""Bounded CPU load: the project's own busy processes, for the load tests of the live nodes
(tests/test_live_load.py) and ``amsfe bench --ros`` (docs/live-load.md).

A hog is a separate Python process (``python -c``, nothing of the package imported) spinning
an integer loop at the caller's priority.  It can never outlive the run that started it:

- :class:`CpuHogs` kills every hog (SIGKILL, then waits for it) when its ``with`` block ends,
  however it ends (an assertion, Ctrl-C, SIGTERM raised as an exception);
- each hog asks the kernel to kill it when its parent dies (``PR_SET_PDEATHSIG``, Linux),
  checks every few milliseconds that its parent is still the one that started it, and exits
  by itself after ``limit_s`` seconds (the hard limit: a SIGKILL of the harness, or a hung
  test, still leaves no hog running past it).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time

from amsfe_sym.errors import ConfigError, describe

__all__ = ["HOG_SOURCE", "MAX_HOG_SECONDS", "CpuHogs"]

#: The longest a hog may be asked to live [s].
MAX_HOG_SECONDS = 3600.0

#: The program of one hog: argv[1] its hard time limit [s], argv[2] its parent's pid.
HOG_SOURCE = """
import ctypes, os, sys, time
limit, parent = float(sys.argv[1]), int(sys.argv[2])
try:  # killed by the kernel when the parent dies (Linux: PR_SET_PDEATHSIG = 1)
    ctypes.CDLL(None, use_errno=True).prctl(1, 9, 0, 0, 0)
except (OSError, AttributeError):
    pass
end = time.monotonic() + limit
x = 0
while True:
    for _ in range(20000):  # a few ms of pure interpreter work
        x = (x * 1103515245 + 12345) & 0xFFFFFFFF
    if os.getppid() != parent or time.monotonic() > end:
        sys.exit(0)
"""


class CpuHogs:
    """``count`` busy processes while the ``with`` block runs (each one core's worth of load).

    Args:
        count: How many hogs (0: none; the block runs on an idle machine).
        limit_s: Hard limit of each hog's life [s] (it exits by itself then).

    Raises:
        ConfigError: ``count`` < 0 or ``limit_s`` outside (0, :data:`MAX_HOG_SECONDS`].
    """

    def __init__(self, count: int, limit_s: float = 600.0) -> None:
        if count < 0 or count > 64:
            raise ConfigError(describe("CPU hogs", "a count in 0..64", str(count), "e.g. 2"))
        if not 0.0 < limit_s <= MAX_HOG_SECONDS:
            raise ConfigError(
                describe(
                    "CPU hogs' time limit",
                    f"a time in (0, {MAX_HOG_SECONDS:g}] s",
                    f"{limit_s:g} s",
                    "e.g. 120",
                )
            )
        self.count, self.limit_s = count, limit_s
        self.procs: list[subprocess.Popen[bytes]] = []

    @property
    def pids(self) -> list[int]:
        """The hogs' process ids."""
        return [p.pid for p in self.procs]

    def start(self) -> CpuHogs:
        """Start the hogs (the ``with`` block does)."""
        for _ in range(self.count - len(self.procs)):
            self.procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", HOG_SOURCE, repr(self.limit_s), str(os.getpid())],
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        return self

    def running(self) -> int:
        """How many hogs are still running."""
        return sum(p.poll() is None for p in self.procs)

    def stop(self) -> None:
        """Kill every hog (SIGKILL) and wait for it; safe to call twice."""
        for p in self.procs:
            if p.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(p.pid, signal.SIGKILL)
        deadline = time.monotonic() + 10.0
        for p in self.procs:
            with contextlib.suppress(subprocess.TimeoutExpired):  # a kernel that lost a kill
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
        self.procs = [p for p in self.procs if p.poll() is None]

    def __enter__(self) -> CpuHogs:
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc_info: object) -> None:  # stopped however the block ends
        self.stop()
