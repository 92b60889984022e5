"""The CPU hogs of the load tests (:mod:`amsfe_sym.core.cpu_load`): they burn CPU, and none
outlives its run: killed at the end of the block, gone after their hard limit, gone when the
process that started them is SIGKILLed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from amsfe_sym.core.cpu_load import CpuHogs
from amsfe_sym.errors import ConfigError

SRC = Path(__file__).resolve().parent.parent / "src"


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, exited but not yet reaped, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def _cpu_ticks(pid: int) -> int:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])  # utime + stime [clock ticks]


def _until(cond: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return bool(cond())  # type: ignore[operator]


def test_hogs_burn_cpu_and_are_killed_at_the_end() -> None:
    with CpuHogs(2, limit_s=60) as hogs:
        pids = hogs.pids
        assert len(pids) == 2 and hogs.running() == 2
        assert _until(lambda: all(_cpu_ticks(p) > 10 for p in pids), 60.0)
    assert not any(_alive(p) for p in pids)
    assert hogs.running() == 0


def test_hogs_are_killed_when_the_block_raises() -> None:
    with pytest.raises(RuntimeError), CpuHogs(1, limit_s=60) as hogs:
        pids = hogs.pids
        raise RuntimeError("a failing test")
    assert not any(_alive(p) for p in pids)


def test_a_hog_ends_at_its_hard_limit() -> None:
    hogs = CpuHogs(1, limit_s=0.5).start()
    try:
        assert _until(lambda: hogs.procs[0].poll() is not None, 60.0)
        assert hogs.procs[0].returncode == 0
    finally:
        hogs.stop()


def test_hogs_die_with_a_killed_parent() -> None:
    """A harness SIGKILLed (no ``finally`` runs) leaves no hog behind."""
    code = (
        "import sys, time; from amsfe_sym.core.cpu_load import CpuHogs\n"
        "h = CpuHogs(2, limit_s=120).start(); print(*h.pids, flush=True); time.sleep(120)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    parent = subprocess.Popen(
        [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True
    )
    try:
        assert parent.stdout is not None
        pids = [int(p) for p in parent.stdout.readline().split()]
        assert len(pids) == 2 and all(_alive(p) for p in pids)
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=30)
        assert _until(lambda: not any(_alive(p) for p in pids), 30.0), pids
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        if parent.stdout is not None:
            parent.stdout.close()


@pytest.mark.parametrize(("count", "limit"), [(-1, 10.0), (1, 0.0), (1, 1e9)])
def test_bad_hog_options_are_one_line(count: int, limit: float) -> None:
    with pytest.raises(ConfigError) as err:
        CpuHogs(count, limit_s=limit)
    assert "\n" not in str(err.value) and "Fix" in str(err.value)
