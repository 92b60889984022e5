"""Output folders are complete or absent, and two writers cannot both win (issue 20)."""

from __future__ import annotations

from pathlib import Path

import pytest

from amsfe_sym.core.folders import MARKER, is_run_folder, write_folder
from amsfe_sym.errors import RunFolderError


def test_a_folder_that_appears_meanwhile_is_not_replaced(tmp_path: Path) -> None:
    out = tmp_path / "run"

    def fill(tmp: Path) -> None:
        (tmp / "summary.json").write_text("mine")
        out.mkdir()  # another process finished its run into the same new folder
        (out / "summary.json").write_text("theirs")

    with pytest.raises(RunFolderError, match="another process"):
        write_folder(out, fill, replace=False)
    assert (out / "summary.json").read_text() == "theirs"  # their run is kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # and nothing of ours


def test_complete_or_absent(tmp_path: Path) -> None:
    out = tmp_path / "run"
    write_folder(out, lambda tmp: (tmp / "a.txt").write_text("1"))
    assert is_run_folder(out) and (out / MARKER).is_file()

    def broken(tmp: Path) -> None:
        (tmp / "b.txt").write_text("2")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_folder(out, broken)
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "a.txt"]  # the old one, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_file_or_a_folder_of_the_users_is_never_replaced_even_when_asked(
    tmp_path: Path,
) -> None:
    """The last guard, below every caller's check (issue 25): ``replace=True`` replaces
    only the tool's own output or an empty folder."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("months of work")
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    for target in (mine, notes):
        with pytest.raises(RunFolderError, match="never replaces what it did not write"):
            write_folder(target, lambda tmp: (tmp / "a.txt").write_text("1"), replace=True)
    assert (mine / "thesis.tex").read_text() == "months of work"
    assert notes.read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "notes.txt"]
    empty = tmp_path / "empty"
    empty.mkdir()
    write_folder(empty, lambda tmp: (tmp / "a.txt").write_text("1"), replace=True)
    assert is_run_folder(empty)
