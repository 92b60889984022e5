"""Output folders that are complete or absent: built under a hidden sibling name and renamed
into place at the end (a run folder, a comparison, an estimate, a bag), so an error or Ctrl-C
on the way leaves nothing half-written."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from amsfe_sym.core.interrupts import DeferredSignals
from amsfe_sym.core.ledger import note_written, resolved
from amsfe_sym.errors import RunFolderError, describe

__all__ = [
    "MARKER",
    "STALE_TMP_SECONDS",
    "TMP_MARKER",
    "FolderJob",
    "clean_stale_tmp",
    "is_run_folder",
    "make_tmp",
    "mark_tmp",
    "pid_alive",
    "replace_dir",
    "write_folder",
    "write_folders",
]

#: Kept for callers that still pass an age: the clean-up no longer removes by age (a live
#: run of several hours keeps its temporaries), only by the marker below [s].
STALE_TMP_SECONDS = 3600.0

#: The file every output folder of this tool holds: what ``--force`` may replace.
MARKER = ".amsfe-output"

#: The file every temporary folder of this tool holds from the moment it exists: the pid and
#: the start time of the process that made it.  The clean-up removes a hidden sibling only
#: when it holds this file and that process is gone; a look-alike folder of the user's
#: (``.result-2024-notes``) holds no such file and is never touched.
TMP_MARKER = ".amsfe-tmp"


def is_run_folder(path: Path) -> bool:
    """Whether ``path`` is an output folder this tool wrote (it holds :data:`MARKER`)."""
    return (path / MARKER).is_file()


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (another user's too; a pid no system can have: no)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    except OverflowError:  # not a pid this system can have
        return False
    return True


def _start_time(pid: int) -> str | None:
    """The process's start time (Linux: ``/proc/<pid>/stat`` field 22, clock ticks since
    boot), which tells a reused pid from the process that wrote a marker; None elsewhere."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat.rpartition(")")[2].split()  # after the command name, which may hold spaces
    return fields[19] if len(fields) > 19 else None


def _owner_line(pid: int) -> str:
    return f"amsfe_sym temporary folder; pid {pid}; start {_start_time(pid)}\n"


def mark_tmp(folder: Path) -> Path:
    """Write :data:`TMP_MARKER` into ``folder``, naming this process: from now on a
    clean-up may remove ``folder`` once this process is gone.

    Returns:
        ``folder``.
    """
    (folder / TMP_MARKER).write_text(_owner_line(os.getpid()))
    return folder


def make_tmp(parent: Path, prefix: str) -> Path:
    """A new hidden temporary folder ``parent/<prefix><random>``, marked as this process's
    (:func:`mark_tmp`) before anything else is written into it.  ``prefix`` should end in
    ``<pid>-`` so that :func:`clean_stale_tmp` finds it."""
    tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
    try:
        return mark_tmp(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _abandoned(folder: Path, pid: int) -> bool:
    """Whether ``folder`` is a temporary folder this tool made in process ``pid`` and that
    process is gone (dead, or its pid now names another process): only then may it go."""
    marker = folder / TMP_MARKER
    try:
        if marker.is_symlink() or not marker.is_file():
            return False
        text = marker.read_text(errors="replace")
    except OSError:
        return False
    head = "amsfe_sym temporary folder; pid "
    if not text.startswith(head):
        return False
    pid_text, _, rest = text[len(head) :].partition("; start ")
    if pid_text != str(pid):  # the name and the marker must agree
        return False
    if not pid_alive(pid):
        return True
    written = rest.strip()
    now = _start_time(pid)
    return written != "None" and now is not None and now != written  # the pid was reused


def clean_stale_tmp(parent: Path, name: str, max_age: float | None = None) -> list[Path]:
    """Remove the hidden temporary folders a killed process of this tool left beside
    ``parent/<name>`` (``.<name>-<pid>-*`` of a build, ``.<name>.tmp-<pid>-*`` of an output
    folder, ``.<name>.old-<pid>-*`` of a replacement), but only those that hold this tool's
    :data:`TMP_MARKER` naming that pid, whose process is gone.  A folder without the marker
    (a user's ``.result-2024-notes``, a temporary of an older version) is never removed,
    whatever its name or age; neither is a symbolic link.

    Args:
        parent: The folder holding ``name``.
        name: The output's name.
        max_age: Ignored (kept for callers of the former age rule).

    Returns:
        The folders removed.
    """
    del max_age
    removed = []
    for prefix in (f".{name}-", f".{name}.tmp-", f".{name}.old-"):
        for d in parent.glob(prefix + "*"):
            pid_text = d.name[len(prefix) :].partition("-")[0]
            if d.is_symlink() or not d.is_dir() or not pid_text.isdigit():
                continue
            if _abandoned(d, int(pid_text)):
                shutil.rmtree(d, ignore_errors=True)
                removed.append(d)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _move_aside(target: Path) -> Path:
    """Rename the tool's own folder ``target`` to a hidden ``.<name>.old-<pid>-<ns>`` sibling,
    marked as this process's temporary (so a kill before its removal leaves something a
    later clean-up may remove), and return that sibling."""
    old = target.with_name(f".{target.name}.old-{os.getpid()}-{time.time_ns()}")
    target.rename(old)
    with contextlib.suppress(OSError):  # unmarked, it is merely never cleaned up
        mark_tmp(old)
    return old


def replace_dir(new: Path, target: Path) -> None:
    """Move ``new`` to ``target`` replacing any old content, as atomically as rename allows
    (the old one is renamed aside first and removed after)."""
    old = None
    if target.exists():
        old = _move_aside(target)
    new.rename(target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@dataclass(frozen=True)
class FolderJob:
    """One output folder of a :func:`write_folders` group.

    Attributes:
        out: Where the folder goes.
        fill: ``fill(tmp)`` writes its content into the hidden temporary folder ``tmp``.
        replace: An existing ``out`` is replaced (the caller checked it may be, see
            :func:`amsfe_sym.core.outputs.check_output`); off: an ``out`` that appeared
            meanwhile (another writer) is refused.  Even on, only the tool's own output is
            replaced (``own``; an empty folder too): never a file or a folder of the user's.
        own: Whether an existing folder is the tool's own output (default
            :func:`is_run_folder`).
    """

    out: Path
    fill: Callable[[Path], None]
    replace: bool = True
    own: Callable[[Path], bool] | None = None


def _another_writer(out: Path) -> RunFolderError:
    return RunFolderError(
        describe(
            f"run folder {out}",
            "a new folder",
            "one another process wrote meanwhile",
            "choose another --out (nothing of this run was kept)",
        )
    )


def _not_ours(job: FolderJob) -> RunFolderError | None:
    """The error if ``job.out`` exists and is not the tool's own output (the last guard:
    whatever a caller decided, a file or a folder of the user's is never replaced)."""
    out = job.out
    if not out.exists():
        return None
    if not out.is_dir():
        found = "a file"
    elif any(out.iterdir()) and not (job.own or is_run_folder)(out):
        found = "a folder of other files (amsfe did not write it)"
    else:
        return None
    return RunFolderError(
        describe(
            f"output folder {out}",
            "a new folder or one amsfe wrote",
            found,
            "choose another path; amsfe never replaces what it did not write "
            "(nothing of this run was kept)",
        )
    )


def _commit(jobs: Sequence[FolderJob], tmps: Sequence[Path]) -> None:
    """Rename every ``tmps[i]`` to ``jobs[i].out``: all of them, or none (an error on the
    way puts back what was there before)."""
    done: list[tuple[Path, Path | None]] = []  # (out, the old folder moved aside)
    try:
        for job, tmp in zip(jobs, tmps, strict=True):
            old = None
            if job.replace and (refused := _not_ours(job)) is not None:
                raise refused
            if job.replace and job.out.exists():
                old = _move_aside(job.out)
            try:
                tmp.rename(job.out)  # rename(2) refuses a non-empty target
            except OSError as exc:
                if old is not None:
                    (old / TMP_MARKER).unlink(missing_ok=True)
                    old.rename(job.out)
                if not job.replace:
                    raise _another_writer(job.out) from exc
                raise
            done.append((job.out, old))
    except BaseException:
        for out, old in reversed(done):
            shutil.rmtree(out, ignore_errors=True)
            if old is not None:
                (old / TMP_MARKER).unlink(missing_ok=True)
                old.rename(out)
        raise
    for _, old in done:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def write_folders(jobs: Sequence[FolderJob]) -> list[Path]:
    """Write several output folders as one unit: each ``fill`` writes into a hidden sibling
    of its ``out``; only when all are filled are they renamed into place, together, with
    Ctrl-C and SIGTERM held for the renames (a run folder and its bag elsewhere: both or
    neither).  An error or interruption before leaves nothing of them, and what was there
    before untouched.  The outputs are marked written in the command's
    :func:`~amsfe_sym.core.ledger.ledger`.

    Returns:
        The ``out`` of each job, resolved.
    """

    jobs = [FolderJob(resolved(j.out), j.fill, j.replace, j.own) for j in jobs]
    tmps: list[Path] = []
    try:
        for job in jobs:
            job.out.parent.mkdir(parents=True, exist_ok=True)
            clean_stale_tmp(job.out.parent, job.out.name)  # what a killed run left here
            tmp = make_tmp(job.out.parent, f".{job.out.name}.tmp-{os.getpid()}-")
            tmp.chmod(0o777 & ~_umask())  # mkdtemp's 0700 would ignore the user's umask
            tmps.append(tmp)
            job.fill(tmp)
            (tmp / TMP_MARKER).unlink(missing_ok=True)  # what is renamed into place is output
            (tmp / MARKER).write_text("written by amsfe_sym; `--force` may replace this folder\n")
        with DeferredSignals():
            _commit(jobs, tmps)
            note_written([j.out for j in jobs])
    except BaseException:
        for tmp in tmps:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    return [j.out for j in jobs]


def write_folder(
    out: Path,
    fill: Callable[[Path], None],
    replace: bool = True,
    own: Callable[[Path], bool] | None = None,
) -> Path:
    """``fill(tmp)`` writes the folder's content into a hidden sibling ``tmp`` of ``out``,
    which then replaces ``out`` (:func:`write_folders` with one job; the caller decides
    beforehand whether it may be replaced).

    With ``replace`` off, an ``out`` that appeared meanwhile (another writer) is not
    replaced: :class:`~amsfe_sym.errors.RunFolderError`.

    Returns:
        ``out``.
    """
    write_folders([FolderJob(out, fill, replace, own)])
    return out
