"""The results table of a sweep folder: ``results.parquet`` plus the parts of a sweep in
progress.

While a sweep runs, every finished batch is written at once as ``parts/part-*.parquet``
(written to a hidden file and renamed, so a part is whole or absent); at the end the parts
and the previous table are merged into ``results.parquet`` (one row per run id, the newest
row winning) and the parts removed.  An interrupted sweep leaves its parts: the next run of
the same sweep reads them and skips those runs (resume).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

__all__ = ["PARTS", "RESULTS", "merge_table", "read_rows", "write_part"]

RESULTS = "results.parquet"
PARTS = "parts"


def _frames(out: Path) -> list[pd.DataFrame]:
    frames = []
    if (out / RESULTS).is_file():
        frames.append(pd.read_parquet(out / RESULTS))
    parts = sorted((out / PARTS).glob("part-*.parquet")) if (out / PARTS).is_dir() else []
    frames += [pd.read_parquet(p) for p in parts]
    return [f for f in frames if len(f)]


def read_rows(out: str | os.PathLike[str]) -> pd.DataFrame:
    """Every row of the folder (table and parts), one per ``run_id`` (the newest wins)."""
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
