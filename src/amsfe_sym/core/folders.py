"""Output folders that are complete or absent: built under a hidden sibling name and renamed
into place at the end (a run folder, a comparison, an estimate, a bag), so an error or Ctrl-C
on the way leaves nothing half-written."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["MARKER", "is_run_folder", "replace_dir", "write_folder"]

#: The file every output folder of this tool holds: what ``--force`` may replace.
MARKER = ".amsfe-output"


def is_run_folder(path: Path) -> bool:
    """Whether ``path`` is an output folder this tool wrote (it holds :data:`MARKER`)."""
    return (path / MARKER).is_file()


def replace_dir(new: Path, target: Path) -> None:
    """Move ``new`` to ``target`` replacing any old content, as atomically as rename allows
    (the old one is renamed aside first and removed after)."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old-{os.getpid()}-{time.time_ns()}")
        target.rename(old)
    new.rename(target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_folder(out: Path, fill: Callable[[Path], None]) -> Path:
    """``fill(tmp)`` writes the folder's content into a hidden sibling ``tmp`` of ``out``,
    which then replaces ``out`` (an existing ``out`` is moved aside first and removed after;
    the caller decides beforehand whether it may be replaced).

    Returns:
        ``out``.
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out.parent))
    try:
        fill(tmp)
        (tmp / MARKER).write_text("written by amsfe_sym; `--force` may replace this folder\n")
        replace_dir(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
