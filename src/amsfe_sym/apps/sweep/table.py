"""The results table of a sweep folder: ``results.parquet`` plus the parts of a sweep in
progress.

While a sweep runs, every finished batch is written at once as ``parts/part-*.parquet``
(written to a hidden file and renamed, so a part is whole or absent); at the end the parts
and the previous table are merged into ``results.parquet`` (one row per run id, the newest
row winning) and the parts removed.  An interrupted sweep leaves its parts: the next run of
the same sweep reads them and skips those runs (resume).

A file that cannot be read (a part or table damaged by a kill, a power cut or a full disk,
a truncated copy) stops the sweep with one line naming it; :func:`repair` (``amsfe sweep
--repair``) moves such files to ``damaged/`` and keeps every readable row, so the runs
whose rows were lost are run again by the next sweep.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
from pyarrow import ArrowException

from amsfe_sym.errors import RunFolderError, describe

__all__ = [
    "DAMAGED",
    "META",
    "PARTS",
    "RESULTS",
    "merge_table",
    "meta_damaged",
    "read_rows",
    "repair",
    "write_part",
]

RESULTS = "results.parquet"
PARTS = "parts"
DAMAGED = "damaged"
META = "sweep.json"


def _files(out: Path) -> list[Path]:
    """The table (if any) and the parts, oldest first."""
    files = [out / RESULTS] if (out / RESULTS).is_file() else []
    if (out / PARTS).is_dir():
        files += sorted((out / PARTS).glob("part-*.parquet"))
    return files


def _read(path: Path) -> pd.DataFrame | str:
    """The table in ``path``, or why it cannot be read (one line)."""
    try:
        df = pd.read_parquet(path)
    except (OSError, ValueError, ArrowException) as exc:  # ArrowInvalid, truncated, ...
        why = (str(exc).strip().splitlines() or [""])[0][:160]
        return f"{type(exc).__name__}: {why}"
    if "run_id" not in df.columns:
        return f"no run_id column (columns {list(df.columns)[:5]})"
    return df


def _frames(out: Path) -> list[pd.DataFrame]:
    frames = []
    for path in _files(out):
        df = _read(path)
        if isinstance(df, str):
            raise RunFolderError(
                describe(
                    f"sweep file {str(path)!r}",
                    "a readable parquet table",
                    f"a damaged file ({df})",
                    "run the same sweep again with --repair (it moves the file to "
                    f"{str(out / DAMAGED)!r} and re-runs the rows it held), or delete it",
                )
            )
        frames.append(df)
    return [f for f in frames if len(f)]


def meta_damaged(out: Path) -> bool:
    """``sweep.json`` exists but is not a JSON object (cut short by a kill or a full disk)."""
    try:
        return not isinstance(json.loads((out / META).read_text()), dict)
    except FileNotFoundError:
        return False
    except (OSError, ValueError):
        return True


def repair(out: str | os.PathLike[str]) -> list[Path]:
    """Move every unreadable table or part of the sweep folder ``out``, and an unreadable
    ``sweep.json``, to ``out/damaged/`` (nothing is deleted) and return where they went.
    The readable rows stay (as rows of the sweep being run: without its ``sweep.json`` the
    folder's base scenario cannot be checked); a damaged ``results.parquet`` is rebuilt
    from the readable parts when the sweep next merges, and the runs whose rows were lost
    are no longer "done", so the next sweep runs them again."""
    out = Path(out)
    moved = []
    meta = [out / META] if meta_damaged(out) else []
    for path in meta + _files(out):
        if path in meta or isinstance(_read(path), str):
            dest = out / DAMAGED / f"{path.name}.{time.time_ns()}"
            dest.parent.mkdir(exist_ok=True)
            path.rename(dest)
            moved.append(dest)
    return moved


def read_rows(out: str | os.PathLike[str]) -> pd.DataFrame:
    """Every row of the folder (table and parts), one per ``run_id`` (the newest wins).

    Raises:
        RunFolderError: a file of the folder cannot be read (the message names it and the
            fix, :func:`repair`).
    """
    frames = _frames(Path(out))
    if not frames:
        return pd.DataFrame({"run_id": pd.Series(dtype=str)})
    df = pd.concat(frames, ignore_index=True)
    return df.drop_duplicates("run_id", keep="last").reset_index(drop=True)


def write_part(out: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write finished rows as a new part, atomically (hidden file, then rename)."""
    parts = Path(out) / PARTS
    parts.mkdir(parents=True, exist_ok=True)
    stem = f"part-{time.time_ns():020d}-{os.getpid()}"
    tmp, final = parts / f".{stem}.parquet", parts / f"{stem}.parquet"
    pd.DataFrame(list(rows)).to_parquet(tmp, index=False)
    tmp.rename(final)
    return final


def merge_table(
    out: str | os.PathLike[str], order: Mapping[str, int], columns: Sequence[str]
) -> pd.DataFrame:
    """Merge the table and its parts into ``results.parquet`` and remove the parts.

    Args:
        out: The sweep folder.
        order: run_id -> position in the grid (rows of runs no longer in the grid go last).
        columns: Columns to put first (ids and labels); the metrics follow, sorted.

    Returns:
        The merged table.
    """
    out = Path(out)
    df = read_rows(out)
    if len(df):
        pos = df["run_id"].map(lambda r: order.get(r, len(order)))
        df = df.assign(_pos=pos).sort_values("_pos", kind="stable").drop(columns="_pos")
        first = [c for c in columns if c in df.columns]
        df = df[first + sorted(c for c in df.columns if c not in first)]
        df = df.reset_index(drop=True)
    tmp = out / f".{RESULTS}.tmp"
    df.to_parquet(tmp, index=False)
    tmp.replace(out / RESULTS)
    parts = out / PARTS
    if parts.is_dir():
        for p in parts.glob("part-*.parquet"):
            p.unlink()
        for p in parts.glob(".part-*"):
            p.unlink()
        parts.rmdir()
    return df
