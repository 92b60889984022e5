"""Run a sweep on Dask: a local cluster by default, or an existing one by its address.

:func:`run_sweep` expands the grid, drops the runs the folder already holds (resume),
groups the rest by library (:func:`~amsfe_sym.apps.sweep.jobs.library_key`) and cuts each group
into batches (one Dask task runs a batch, so the scheduler's per-task cost is spread over
its runs; docs/how-to/sweeps.md measures it), submits them, and writes each finished batch as a
part of the table at once (an interrupted sweep keeps what it finished).  At the end it
merges the table (``results.parquet``) and writes ``sweep.json``: the sweep, its resolved
base scenario, counts, wall time, throughput and provenance.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import time
from collections import defaultdict
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pandas as pd

from amsfe_sym.apps.sweep.jobs import KEY_COLUMNS, library_key, run_batch
from amsfe_sym.apps.sweep.spec import Job, SweepSpec, expand_jobs
from amsfe_sym.apps.sweep.table import (
    DAMAGED,
    META,
    PARTS,
    RESULTS,
    merge_table,
    meta_damaged,
    read_rows,
    write_part,
)
from amsfe_sym.core.folders import MARKER, is_run_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import Output, check_output
from amsfe_sym.core.provenance import provenance
from amsfe_sym.errors import ConfigError, RunFolderError, describe

__all__ = ["META", "SweepOptions", "SweepResult", "make_batches", "run_sweep"]

#: Batches per worker the automatic batch size aims at (enough to balance the load).
BATCHES_PER_WORKER = 4
#: Largest automatic batch [runs].
MAX_AUTO_BATCH = 32


@dataclass(frozen=True)
class SweepOptions:
    """How to run a sweep.

    Attributes:
        out: The sweep folder (``results.parquet``, ``sweep.json``, ``figures/``).
        scheduler: Address of a running Dask scheduler (``tcp://host:8786``); None starts a
            ``distributed.LocalCluster``.
        workers: Worker processes of the local cluster (None: this machine's cores; 0: no
            Dask, every run in this process, one by one).
        batch: Runs per task (None: about 4 batches per worker, at most 32 runs each).
        retry_errors: Run the error rows of the folder again (done rows are always skipped).
        force: Start afresh in a folder that holds another sweep's rows (they are removed).
        progress: Show the progress bar (runs, rate, time left).
    """

    out: Path
    scheduler: str | None = None
    workers: int | None = None
    batch: int | None = None
    retry_errors: bool = False
    force: bool = False
    progress: bool = True


@dataclass
class SweepResult:
    """What :func:`run_sweep` did.

    Attributes:
        out: The sweep folder.
        table: The merged table (every row the folder holds).
        ran: Runs this call ran.
        skipped: Runs already in the folder (resumed over).
        errors, diverged: Rows of the table with that status.
        wall_time_s: Wall time of this call's runs, cluster start included [s].
        workers: Dask workers used (0: in-process).
        batch: Runs per task.
    """

    out: Path
    table: pd.DataFrame
    ran: int
    skipped: int
    errors: int
    diverged: int
    wall_time_s: float
    workers: int
    batch: int

    @property
    def runs_per_s(self) -> float:
        """Throughput of this call [runs/s] (NaN if it ran nothing)."""
        return self.ran / self.wall_time_s if self.ran and self.wall_time_s > 0 else math.nan


def make_batches(jobs: Sequence[Job], size: int) -> list[list[Job]]:
    """``jobs`` grouped by library (grid order kept inside a group), cut into batches of at
    most ``size``: a batch never mixes libraries, so a worker loads each one once."""
    groups: dict[tuple[Any, ...], list[Job]] = defaultdict(list)
    for j in jobs:
        groups[library_key(j.scenario, j.robot)].append(j)
    return [g[i : i + size] for g in groups.values() for i in range(0, len(g), size)]


def _auto_batch(n_jobs: int, workers: int) -> int:
    per = math.ceil(n_jobs / max(1, workers * BATCHES_PER_WORKER))
    return max(1, min(MAX_AUTO_BATCH, per))


def is_sweep_folder(path: Path) -> bool:
    """Whether ``path`` is a sweep folder this tool wrote (its marker, or a sweep's files)."""
    return is_run_folder(path) or any((path / n).exists() for n in (META, RESULTS, PARTS))


def check_sweep_out(
    out: Path, force: bool = False, inputs: Sequence[str | os.PathLike[str]] = ()
) -> Output:
    """``--out`` of a sweep (:func:`amsfe_sym.core.outputs.check_output`, kind ``resume``):
    new, empty or a sweep folder (which the sweep resumes); a file, a folder of the user's
    or an input (the sweep file) is refused, with or without ``--force``."""
    return check_output(
        out, option="--out", kind="resume", force=force, inputs=inputs, own=is_sweep_folder
    )


def _check_folder(spec: SweepSpec, opts: SweepOptions) -> None:
    out = opts.out
    check_sweep_out(out, opts.force, [spec.source] if spec.source else [])
    meta = out / META
    if meta_damaged(out) and not opts.force:
        raise RunFolderError(
            describe(
                f"sweep file {str(meta)!r}",
                "the sweep's JSON record",
                "a damaged file (not JSON)",
                "run the same sweep again with --repair (it moves the file to "
                f"{str(out / DAMAGED)!r} and keeps the rows), or --force to start afresh",
            )
        )
    if not meta.is_file():
        return
    try:
        old = json.loads(meta.read_text())
    except (OSError, ValueError):
        old = {}
    if old.get("base_hash") == spec.base_hash():
        return
    if not opts.force:
        raise ConfigError(
            describe(
                f"sweep folder {str(out)!r}",
                f"rows of this sweep (base {spec.base_hash()})",
                f"rows of another base scenario or runtime (base {old.get('base_hash')})",
                "pass another --out, or --force to start afresh there",
            )
        )
    for name in (RESULTS, META):
        (out / name).unlink(missing_ok=True)
    shutil.rmtree(out / PARTS, ignore_errors=True)


@contextmanager
def _dask_client(opts: SweepOptions) -> Iterator[Any]:
    """A ``distributed.Client`` on the given scheduler, or on a new ``LocalCluster``."""
    from distributed import Client, LocalCluster

    if opts.scheduler:
        try:
            client = Client(opts.scheduler, timeout="15s")
        except (OSError, TimeoutError) as exc:
            raise ConfigError(
                describe(
                    f"--scheduler {opts.scheduler!r}",
                    "the address of a running Dask scheduler",
                    f"no answer ({type(exc).__name__})",
                    "start one (dask scheduler; dask worker ADDRESS) or drop --scheduler",
                )
            ) from exc
        try:
            yield client
        finally:
            client.close()
        return
    n = opts.workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        # the scheduler's HTTP server (health routes) starts even without a dashboard: on a
        # free port, so two sweeps on one machine do not collide on 8787
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        worker_dashboard_address=None,
        silence_logs=logging.ERROR,
    )
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def _n_workers(client: Any) -> int:
    return len(client.scheduler_info().get("workers", {}))


def _bar(total: int, desc: str, on: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="run", disable=not on, smoothing=0.1)


def run_sweep(spec: SweepSpec, opts: SweepOptions) -> SweepResult:
    """Run every run of ``spec`` that ``opts.out`` does not hold yet; merge the table.

    Raises:
        ConfigError: a folder holding another sweep (without ``force``), a scheduler that
            does not answer, or a cluster with no workers.  A failing run is not raised: it
            is a row with ``status = "error"``.
    """
    jobs = expand_jobs(spec)
    _check_folder(spec, opts)
    out = opts.out
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).touch()  # the tool's folder: a later sweep may resume it
    have = read_rows(out)
    keep = have if opts.retry_errors is False or not len(have) else have[have.status != "error"]
    done = set(keep["run_id"]) if len(keep) else set()
    todo = [j for j in jobs if j.run_id not in done]
    skipped = len(jobs) - len(todo)
    t0 = time.perf_counter()
    workers, batch = 0, opts.batch or 1
    if todo and opts.workers == 0 and not opts.scheduler:
        batch = opts.batch or len(todo)
        with _bar(len(todo), spec.name, opts.progress) as bar:
            for b in make_batches(todo, batch):
                write_part(out, run_batch(b))
                bar.update(len(b))
    elif todo:
        with _dask_client(opts) as client:
            workers = _n_workers(client)
            if workers == 0:
                client.wait_for_workers(1, timeout=30)
                workers = _n_workers(client)
            batch = opts.batch or _auto_batch(len(todo), workers)
            _run_on(client, make_batches(todo, batch), out, spec.name, opts.progress)
    wall = time.perf_counter() - t0
    labels = ["run_id", *spec.axes, *KEY_COLUMNS[1:]]
    table = merge_table(out, {j.run_id: j.index for j in jobs}, labels)
    res = SweepResult(
        out=out,
        table=table,
        ran=len(todo),
        skipped=skipped,
        errors=int((table.status == "error").sum()) if len(table) else 0,
        diverged=int((table.status == "diverged").sum()) if len(table) else 0,
        wall_time_s=wall,
        workers=workers,
        batch=batch,
    )
    _write_meta(spec, opts, res, len(jobs))
    return res


def _run_on(client: Any, batches: list[list[Job]], out: Path, name: str, progress: bool) -> None:
    from distributed import as_completed

    futures = [client.submit(run_batch, b, pure=False) for b in batches]
    sizes = {f.key: len(b) for f, b in zip(futures, batches, strict=True)}
    with _bar(sum(sizes.values()), name, progress) as bar:
        try:
            for fut in as_completed(futures):
                write_part(out, fut.result())
                bar.update(sizes[fut.key])
        finally:
            client.cancel(futures)


def _write_meta(spec: SweepSpec, opts: SweepOptions, res: SweepResult, n_jobs: int) -> None:
    path = res.out / META
    try:
        sessions = json.loads(path.read_text()).get("sessions", [])
    except (OSError, ValueError):
        sessions = []
    engine = (
        f"dask scheduler {opts.scheduler}"
        if opts.scheduler
        else "in-process"
        if res.workers == 0
        else "distributed.LocalCluster"
    )
    sessions.append(
        {
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "ran": res.ran,
            "skipped": res.skipped,
            "wall_time_s": round(res.wall_time_s, 3),
            "runs_per_s": None if math.isnan(res.runs_per_s) else round(res.runs_per_s, 3),
            "engine": engine,
            "workers": res.workers,
            "batch": res.batch,
        }
    )
    meta = {
        "name": spec.name,
        "description": spec.description,
        "source": str(spec.source) if spec.source else None,
        "base_hash": spec.base_hash(),
        "axes": {k: list(v) for k, v in spec.axes.items()},
        "estimators": list(spec.estimators),
        "controllers": list(spec.controllers),
        "seeds": list(spec.seeds),
        "set": list(spec.sets),
        "runtime": spec.runtime,
        "runs_in_grid": n_jobs,
        "rows": len(res.table),
        "errors": res.errors,
        "diverged": res.diverged,
        "sessions": sessions,
        "scenario": spec.scenario.to_dict(),
        "provenance": provenance(),
    }
    write_json(path, meta, default=str)
