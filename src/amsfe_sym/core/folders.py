"""Output folders that are complete or absent: built under a hidden sibling name and renamed
into place at the end (a run folder, a comparison, an estimate, a bag), so an error or Ctrl-C
on the way leaves nothing half-written."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = ["write_folder"]


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
        old = None
        if out.exists():
            old = out.with_name(f".{out.name}.old-{os.getpid()}")
            out.rename(old)
        tmp.rename(out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
