"""The clean-up of a killed run's temporaries removes only what this tool marked as its own
(issue 37 item 1): a user's folder that merely looks like a temporary (``.result-2024-notes``
beside ``--out runs/x/result``) is never touched, whatever its age, by any command."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.core.folders import (
    TMP_MARKER,
    clean_stale_tmp,
    is_run_folder,
    make_tmp,
    write_folder,
)

DEAD_PID = 999_999_999  # no such process (above any pid_max)


def _user_folder(path: Path) -> Path:
    """A folder of the user's with a look-alike name, old, holding work."""
    path.mkdir(parents=True)
    (path / "notes.md").write_text("months of work")
    hour_ago = time.time() - 7 * 24 * 3600
    os.utime(path, (hour_ago, hour_ago))
    return path


def _look_alikes(parent: Path, name: str) -> list[Path]:
    """Every shape of hidden sibling the clean-up looks at, none of them the tool's."""
    return [
        _user_folder(parent / f".{name}-2024-notes"),  # the probe's case: digits after the name
        _user_folder(parent / f".{name}-{DEAD_PID}-draft"),  # a dead pid, but no marker
        _user_folder(parent / f".{name}.tmp-{DEAD_PID}-x"),
        _user_folder(parent / f".{name}.old-{DEAD_PID}-1"),
    ]


def _intact(folders: list[Path]) -> None:
    for d in folders:
        assert (d / "notes.md").read_text() == "months of work", d


def _marked_by(folder: Path, pid: int, start: str = "1") -> Path:
    """What a (killed) process ``pid`` of this tool left: the folder with its marker."""
    folder.mkdir()
    (folder / TMP_MARKER).write_text(f"amsfe_sym temporary folder; pid {pid}; start {start}\n")
    (folder / "timeseries.csv").write_text("half")
    return folder


def test_only_marked_temporaries_of_a_gone_process_are_removed(tmp_path: Path) -> None:
    users = _look_alikes(tmp_path, "result")
    killed = _marked_by(tmp_path / f".result.tmp-{DEAD_PID}-abc", DEAD_PID)
    other_pid = _marked_by(tmp_path / f".result.tmp-{DEAD_PID}-def", DEAD_PID + 1)  # disagrees
    live = make_tmp(tmp_path, f".result.tmp-{os.getpid()}-")  # this process: running
    link = tmp_path / f".result.old-{DEAD_PID}-link"
    link.symlink_to(users[0], target_is_directory=True)
    removed = clean_stale_tmp(tmp_path, "result")
    assert removed == [killed]
    assert not killed.exists()
    assert other_pid.is_dir() and live.is_dir() and link.is_symlink()
    _intact(users)


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs /proc start times")
def test_a_reused_pid_does_not_keep_a_dead_runs_temporary(tmp_path: Path) -> None:
    """The marker holds the process's start time: the same pid with another start time is
    another process (the pid was reused), so the folder is the dead run's."""
    reused = _marked_by(tmp_path / f".result.tmp-{os.getpid()}-a", os.getpid(), start="0")
    assert clean_stale_tmp(tmp_path, "result") == [reused]


def test_an_age_never_removes_a_running_process_temporary(tmp_path: Path) -> None:
    """A live run of several hours keeps its temporaries (the former rule removed anything
    older than an hour)."""
    live = make_tmp(tmp_path, f".result.tmp-{os.getpid()}-")
    week_ago = time.time() - 7 * 24 * 3600
    os.utime(live, (week_ago, week_ago))
    assert clean_stale_tmp(tmp_path, "result") == []
    assert live.is_dir()


def test_write_folder_leaves_look_alikes_and_no_marker_in_its_output(tmp_path: Path) -> None:
    users = _look_alikes(tmp_path, "result")
    out = tmp_path / "result"
    write_folder(out, lambda tmp: (tmp / "a.txt").write_text("1"))
    write_folder(out, lambda tmp: (tmp / "a.txt").write_text("2"))  # a replacement
    assert is_run_folder(out) and not (out / TMP_MARKER).exists()
    assert (out / "a.txt").read_text() == "2"
    _intact(users)
    assert len(list(tmp_path.iterdir())) == 1 + len(users)  # nothing of ours left beside


RUN = ["simulate", "--controller", "amsfe", "--duration", "0.05", "--no-progress", "--no-plots"]


@pytest.mark.slow
def test_every_command_leaves_a_users_look_alike_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The probe's case and its relatives: look-alike folders of the user's beside every
    output path of generate, simulate (run folder and bag), estimate and study."""
    monkeypatch.chdir(tmp_path)
    runs = tmp_path / "runs" / "x"
    users = [
        *_look_alikes(tmp_path / "gen", "paper_2link"),
        *_look_alikes(runs, "run"),
        *_look_alikes(runs, "bag"),
        *_look_alikes(runs, "result"),
        *_look_alikes(runs, "study"),
    ]
    assert main(["generate", "paper_2link", "--out", "gen"]) == 0
    assert main([*RUN, "--out", "runs/x/run", "--bag", "runs/x/bag"]) == 0
    assert main(["estimate", "runs/x/bag", "--no-plots", "--out", "runs/x/result"]) == 0
    assert main(["study", "--seeds", "1", "--duration", "0.05", "--out", "runs/x/study"]) == 0
    # and again over the outputs (replacements go through the same clean-up)
    assert main([*RUN, "--out", "runs/x/run", "--bag", "runs/x/bag", "--force"]) == 0
    assert main(["estimate", "runs/x/bag", "--no-plots", "--out", "runs/x/result", "--force"]) == 0
    capsys.readouterr()
    _intact(users)
    for out in ("runs/x/run", "runs/x/bag", "runs/x/result", "gen/paper_2link"):
        assert not (tmp_path / out / TMP_MARKER).exists(), out
