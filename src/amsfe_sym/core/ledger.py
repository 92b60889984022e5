"""The outputs a command has checked, and what an interruption kept.

:func:`amsfe_sym.core.outputs.check_output` records each path it accepts in the
:func:`ledger` of the running command; :func:`amsfe_sym.core.folders.write_folders` marks
the folders it put in place (:func:`note_written`); the command line, on Ctrl-C or
SIGTERM, prints :func:`interrupted_note`: what was kept, what was not written.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

__all__ = ["Kind", "Output", "interrupted_note", "ledger", "note_written", "record", "resolved"]

#: What is written at a path: ``folder`` a folder written whole (a run, an estimate, a bag);
#: ``resume`` a folder the command adds to and resumes (a sweep); ``file`` one file
#: (``bench --json``); ``parent`` a folder the command writes named children into (the
#: libraries of ``generate --out``), never replaced itself.
Kind = Literal["folder", "resume", "file", "parent"]


def resolved(path: str | os.PathLike[str]) -> Path:
    """``path`` made absolute with symlinks and ``..`` resolved (as far as it exists)."""
    return Path(path).expanduser().resolve()


@dataclass
class Output:
    """A path a command will write, as :func:`amsfe_sym.core.outputs.check_output` found it.

    Attributes:
        option: The command-line option that named it (``--out``, ``--bag``, ...).
        path: The path as given (for messages).
        resolved: The same path after ``resolve()`` (what is compared and written).
        kind: What is written there (:data:`Kind`).
        existed: Something was there before (a tool output to replace or resume).
        written: The command has put it in place (set by the writers).
    """

    option: str
    path: Path
    resolved: Path
    kind: Kind
    existed: bool
    written: bool = field(default=False)

    @property
    def label(self) -> str:
        return f"{self.option} {self.path}"


_LEDGER: ContextVar[list[Output] | None] = ContextVar("amsfe_outputs", default=None)


def record(out: Output) -> None:
    """Add ``out`` to the current :func:`ledger` (once per path and option), if any."""
    book = _LEDGER.get()
    if book is not None and not any(
        o.resolved == out.resolved and o.option == out.option for o in book
    ):
        book.append(out)


@contextmanager
def ledger() -> Iterator[list[Output]]:
    """Record the outputs checked inside the block (the command line runs each command in
    one), for :func:`interrupted_note`."""
    book: list[Output] = []
    token = _LEDGER.set(book)
    try:
        yield book
    finally:
        _LEDGER.reset(token)


def note_written(paths: Sequence[Path]) -> None:
    """Mark the outputs at ``paths`` (resolved) as put in place (called by the writers)."""
    book = _LEDGER.get() or []
    done = {Path(p) for p in paths}
    for o in book:
        if o.resolved in done:
            o.written = True


def interrupted_note(book: Sequence[Output]) -> str:
    """What an interrupted command kept, in words: nothing half-written, then the outputs it
    put in place, those it did not write (an earlier one left as it was), and a resumable
    folder's finished part."""
    parts = ["nothing half-written was kept"]
    kept = [o.label for o in book if o.written and o.kind != "parent"]
    if kept:
        parts.append("kept, complete: " + ", ".join(kept))
    for kind_ in ("folder", "file"):
        missing = [o for o in book if o.kind == kind_ and not o.written]
        if missing:
            words = [
                o.label + (" (the earlier one left as it was)" if o.existed else "")
                for o in missing
            ]
            parts.append("not written: " + ", ".join(words))
    for o in book:
        if o.kind == "resume":
            parts.append(f"{o.label} keeps the runs finished so far (the same command resumes)")
    return "; ".join(parts)
