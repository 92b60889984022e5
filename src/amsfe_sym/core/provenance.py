"""Where a result came from: source revision, machine and library versions.

One helper for every report (``amsfe bench``, ``amsfe study``, a run's ``summary.json``).
Versions are read from the installed distributions' metadata, so this module imports
neither CasADi nor Pinocchio.
"""

from __future__ import annotations

import os
import platform
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym import __version__

__all__ = ["cpu_name", "git_revision", "package_version", "provenance"]


def package_version(dist: str) -> str:
    """Installed version of distribution ``dist`` (e.g. ``"casadi"``, ``"pin"``) or
    ``"missing"``."""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "missing"


@lru_cache(maxsize=1)
def git_revision() -> tuple[str, bool]:
    """(short commit, dirty) of the source tree this package runs from; ``("unknown",
    False)`` outside a git checkout.  Dirty means tracked files with local changes."""
    here = Path(__file__).resolve().parent.parent  # the package folder

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=here, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()

    try:
        rev = git("rev-parse", "--short=12", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no", ".")
    except (OSError, subprocess.SubprocessError):
        return "unknown", False
    return (rev, bool(dirty)) if rev else ("unknown", False)


def cpu_name() -> str:
    """The CPU model (``/proc/cpuinfo``), else ``platform.processor()`` or the machine."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def provenance() -> dict[str, Any]:
    """The record every report carries.

    Keys: ``commit`` (``<rev>`` or ``<rev>+dirty``), ``dirty``, ``amsfe_sym`` (toolkit
    version), ``machine`` (``platform.platform()``), ``cpu``, ``cores``, ``load_average``
    (1, 5, 15 min), ``python``, ``numpy``, ``casadi``, ``pinocchio``.
    """
    rev, dirty = git_revision()
    try:
        load = [round(v, 2) for v in os.getloadavg()]
    except OSError:  # pragma: no cover - not on every platform
        load = []
    return {
        "commit": rev + ("+dirty" if dirty else ""),
        "dirty": dirty,
        "amsfe_sym": __version__,
        "machine": platform.platform(),
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "load_average": load,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "casadi": package_version("casadi"),
        "pinocchio": package_version("pin"),
    }
