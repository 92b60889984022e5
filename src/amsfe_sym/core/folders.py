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

from amsfe_sym.errors import RunFolderError, describe

__all__ = [
    "MARKER",
    "STALE_TMP_SECONDS",
    "clean_stale_tmp",
    "is_run_folder",
    "replace_dir",
    "write_folder",
]

#: A hidden temporary folder older than this is left over from a killed run [s].
STALE_TMP_SECONDS = 3600.0

#: The file every output folder of this tool holds: what ``--force`` may replace.
MARKER = ".amsfe-output"


def is_run_folder(path: Path) -> bool:
    """Whether ``path`` is an output folder this tool wrote (it holds :data:`MARKER`)."""
    return (path / MARKER).is_file()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def clean_stale_tmp(parent: Path, name: str, max_age: float = STALE_TMP_SECONDS) -> list[Path]:
    """Remove the hidden temporary folders a killed process left beside ``parent/<name>``
    (``.<name>-<pid>-*`` of a build, ``.<name>.tmp-<pid>-*`` of an output folder,
    ``.<name>.old-<pid>-*`` of a replacement): those whose process is gone, or older than
    ``max_age`` [s].

    Returns:
        The folders removed.
    """
    removed = []
    now = time.time()
    for prefix in (f".{name}-", f".{name}.tmp-", f".{name}.old-"):
        for d in parent.glob(prefix + "*"):
            pid_text = d.name[len(prefix) :].partition("-")[0]
            if not d.is_dir() or not pid_text.isdigit():  # not ours (another name)
                continue
            try:
                age = now - d.stat().st_mtime
            except OSError:
                continue
            if not _pid_alive(int(pid_text)) or age > max_age:
                shutil.rmtree(d, ignore_errors=True)
                removed.append(d)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


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


def write_folder(out: Path, fill: Callable[[Path], None], replace: bool = True) -> Path:
    """``fill(tmp)`` writes the folder's content into a hidden sibling ``tmp`` of ``out``,
    which then replaces ``out`` (an existing ``out`` is moved aside first and removed after;
    the caller decides beforehand whether it may be replaced).

    With ``replace`` off, an ``out`` that appeared meanwhile (another writer) is not
    replaced: :class:`~amsfe_sym.errors.RunFolderError`.

    Returns:
        ``out``.
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_tmp(out.parent, out.name)  # what a killed run (SIGKILL) left here
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out.parent))
    tmp.chmod(0o777 & ~_umask())  # mkdtemp's 0700 would ignore the user's umask
    try:
        fill(tmp)
        (tmp / MARKER).write_text("written by amsfe_sym; `--force` may replace this folder\n")
        if replace:
            replace_dir(tmp, out)
        else:  # rename(2) refuses a non-empty target: two writers cannot both win
            try:
                tmp.rename(out)
            except OSError as exc:
                raise RunFolderError(
                    describe(
                        f"run folder {out}",
                        "a new folder",
                        "one another process wrote meanwhile",
                        "choose another --out (nothing of this run was kept)",
                    )
                ) from exc
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
