"""The one rule for every path the tool writes: checked before any work starts.

Every command calls :func:`check_output` for each path it will write (``--out``, ``--bag``,
``--json``, ``--record``; figures go inside those folders) before it computes anything:

- a path is compared after :meth:`pathlib.Path.resolve` (symlinks and ``..`` followed);
- an input of the same command (the log of ``amsfe estimate``, a scenario file, another
  output of the same command) is never written, around or inside, even with ``--force``;
- a file where a folder is expected, or a folder where a file is expected, is refused;
- an existing path is replaced only with ``--force``, and only when it is the tool's own
  output (a folder holding :data:`~amsfe_sym.core.folders.MARKER`, a JSON file holding
  :data:`OWN_KEY`, or an empty folder); a folder of the user's is never replaced;
- the nearest existing ancestor must be a folder this process can write to (a parent that
  is a file, a read-only parent, ``/sys``), tried by creating and removing a probe there.

Each refusal is one :class:`~amsfe_sym.errors.RunFolderError` line (what, expected, found,
fix).  The checked paths of a command are recorded in the :func:`ledger` of the command line,
so a Ctrl-C or SIGTERM can say exactly what was kept (:func:`interrupted_note`).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

from amsfe_sym.core.folders import is_run_folder
from amsfe_sym.core.ledger import (
    Kind,
    Output,
    interrupted_note,
    ledger,
    note_written,
    record,
    resolved,
)
from amsfe_sym.errors import RunFolderError, describe

__all__ = [
    "OWN_KEY",
    "Kind",
    "Output",
    "check_output",
    "interrupted_note",
    "is_own_file",
    "ledger",
    "note_written",
    "resolved",
]

#: The key of a JSON file's top-level object that marks it as the tool's own output.
OWN_KEY = "written_by"


def is_own_file(path: Path) -> bool:
    """Whether ``path`` is a JSON file this tool wrote (its top-level object holds
    :data:`OWN_KEY`)."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and str(doc.get(OWN_KEY, "")).startswith("amsfe")


def _refuse(label: str, expected: str, found: str, fix: str) -> RunFolderError:
    return RunFolderError(describe(label, expected, found, fix))


def _relation(out: Path, other: Path, kind: Kind = "folder") -> str | None:
    if out == other:
        return "is"
    if other in out.parents:
        return "is inside"
    if out in other.parents and kind != "parent":  # (a parent folder is never replaced)
        return "holds"
    return None


def _probe(folder: Path) -> str | None:
    """Create and remove a folder in ``folder``: None if that works, else the reason."""
    try:
        probe = tempfile.mkdtemp(prefix=".amsfe-probe-", dir=folder)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    os.rmdir(probe)
    return None


def _check_parent(label: str, option: str, target: Path) -> None:
    """The nearest existing ancestor of ``target`` is a writable folder."""
    ancestor = target.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise _refuse(
            label,
            "a path under a folder",
            f"{ancestor} is a file",
            f"choose another {option} (a folder cannot be made under a file)",
        )
    why = _probe(ancestor)
    if why is not None:
        raise _refuse(
            label,
            "a path under a folder this user can write to",
            f"{ancestor} is not writable ({why})",
            f"choose another {option} under a folder you can write to",
        )


def check_output(
    path: str | os.PathLike[str],
    *,
    option: str,
    kind: Kind = "folder",
    force: bool = False,
    inputs: Sequence[str | os.PathLike[str]] = (),
    others: Sequence[Output] = (),
    own: Callable[[Path], bool] | None = None,
) -> Output:
    """Check, before any work, that the command may write ``path`` (the rules are in the
    module docstring) and record it in the current :func:`ledger`.

    Args:
        path: The path the command will write.
        option: The option that named it, for messages (``--out``, ``--bag``, ``--json``).
        kind: What is written there (:data:`Kind`).
        force: ``--force`` was given: the tool's own output there may be replaced.
        inputs: Paths the command reads (never written, around or inside).
        others: The command's other outputs, already checked (they may not overlap).
        own: Whether an existing folder is the tool's own output (default: it holds the
            marker file); ``file`` outputs use :func:`is_own_file`.

    Returns:
        The checked :class:`Output` (write to ``resolved``).

    Raises:
        RunFolderError: one line saying what is there and what to do instead.
    """
    given = Path(path)
    target = resolved(given)
    label = f"{option} {given}"
    for inp in inputs:
        rel = _relation(target, resolved(inp), kind)
        if rel is not None:
            raise _refuse(
                label,
                "a path apart from the command's inputs",
                f"it {rel} the input {inp}",
                f"choose another {option}; an input is never written, even with --force",
            )
    for o in others:
        rel = _relation(target, o.resolved)
        if rel is not None:
            raise _refuse(
                label,
                f"a path apart from {o.label}",
                f"it {rel} {o.path}",
                f"choose another {option}",
            )
    is_own = own or is_run_folder
    existed = target.exists()
    if existed and kind != "file" and not target.is_dir():
        raise _refuse(
            label,
            "a folder",
            "an existing file",
            f"choose another {option} (a file is never replaced)",
        )
    if existed and kind == "file" and target.is_dir():
        raise _refuse(
            label,
            "a file",
            "an existing folder",
            f"name a file, e.g. {option} {given / 'report.json'}",
        )
    if existed and kind == "file":
        if not is_own_file(target):
            raise _refuse(
                label,
                f"a new file or a report amsfe wrote (a JSON object with {OWN_KEY!r})",
                "a file of other content",
                f"choose another {option}; --force never replaces a file amsfe did not write",
            )
        if not force:
            raise _refuse(
                label,
                "a new file",
                "an existing file",
                f"choose another {option}, or pass --force to replace it",
            )
    if existed and kind in ("folder", "resume") and target.is_dir():
        try:
            empty = not any(target.iterdir())
        except OSError as exc:  # a folder this user cannot list: not one to replace
            raise _refuse(
                label,
                "a folder this user can read",
                f"one that cannot be listed ({exc.strerror})",
                f"choose another {option}",
            ) from exc
        if not empty and not is_own(target):
            raise _refuse(
                label,
                "a new folder or one amsfe wrote",
                "a folder of other files (amsfe did not write it)",
                f"choose another {option}; --force never replaces a folder it did not write",
            )
        if kind == "folder" and not force:
            raise _refuse(
                label,
                "a new folder",
                "an existing folder",
                f"choose another {option}, or pass --force to replace it",
            )
    if existed and kind in ("resume", "parent"):
        why = _probe(target)
        if why is not None:
            raise _refuse(
                label,
                "a folder this user can write to",
                f"one that is not writable ({why})",
                f"choose another {option}",
            )
    else:
        _check_parent(label, option, target)
    out = Output(option, given, target, kind, existed)
    record(out)
    return out
