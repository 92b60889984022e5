"""The wall time of a command's phases and the process's start-up (``amsfe estimate``'s
``timing``, docs/how-to/logs.md "The command, end to end")."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

__all__ = ["Phases", "command_startup_s", "process_age_s"]


class Phases:
    """Wall time [s] spent in each phase of the command, added up lap by lap
    (:func:`time.perf_counter`)."""

    def __init__(self) -> None:
        self.start = self.last = time.perf_counter()
        self.spent: dict[str, float] = {}

    def lap(self, phase: str) -> float:
        """Add the time since the last lap to ``phase``; the time since the start."""
        now = time.perf_counter()
        self.spent[phase] = self.spent.get(phase, 0.0) + now - self.last
        self.last = now
        return now - self.start


def process_age_s() -> float | None:
    """Seconds since this process started (Linux ``/proc/self/stat``, 10 ms resolution):
    the interpreter's start, the imports and argument parsing before a command; None
    where it cannot be read."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22: starttime
        return max(time.clock_gettime(time.CLOCK_BOOTTIME) - started, 0.0)
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def command_startup_s() -> float | None:
    """:func:`process_age_s` when this process was started as the command (``python -m
    amsfe_sym``, the ``amsfe`` script); None when ``main`` is called from Python (a test, a
    notebook: the process's age is not the command's start-up)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if getattr(spec, "name", None) == "amsfe_sym.__main__" or Path(sys.argv[0]).name == "amsfe":
        return process_age_s()
    return None
