"""One study run per task, in this process or in a pool of spawned workers."""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from amsfe_sym.apps.study.metrics import settle_time
from amsfe_sym.errors import AmsfeError
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.record import window

__all__ = ["Task", "progress_bar", "run_tasks"]


@dataclass(frozen=True)
class Task:
    variant: str
    scenario: Scenario
    lib_dir: str
    keep_series: bool
    runtime: str = "compiled"


_LIBS: dict[str, Any] = {}


#: BLAS thread pools of the workers: one thread each (set in the environment the workers
#: inherit, unless the caller set them).  Two processes with multithreaded BLAS on two cores
#: oversubscribe the machine; worse, scipy 1.17's ``scipy.linalg.solve`` on a 5x5 system took
#: ~0.9-1.9 ms with OpenBLAS threads against ~20 us with one thread on this machine.
_BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _worker_init() -> None:
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)


def _run_task(task: Task) -> dict[str, Any]:
    """One run (in a worker): the summary, the NEES and theta series, and optionally the
    error series of the figure seed."""
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    lib = _LIBS.get(task.lib_dir)
    if lib is None:
        lib = _LIBS[task.lib_dir] = ModelLibrary(task.lib_dir)
    try:
        res = run(task.scenario, lib=lib, runtime=task.runtime)
    except AmsfeError as exc:  # one diverging run must not sink the study: record it
        sc = task.scenario
        failed = {
            "variant": task.variant,
            "scenario": sc.name,
            "estimator": sc.estimator,
            "seed": sc.seed,
            "error": f"{type(exc).__name__}: {exc}",
        }
        return {"summary": failed, "failed": True}
    if res.diverged_at is not None:  # a lost arm: its series end early; count it, do not pool it
        sc = task.scenario
        return {
            "summary": {
                "variant": task.variant,
                "scenario": sc.name,
                "estimator": sc.estimator,
                "seed": sc.seed,
                "error": f"the closed loop ({sc.controller}) diverged at t = "
                f"{res.diverged_at:.3f} s",
            },
            "failed": True,
        }
    summary = summarize(res)
    L = lib.layout
    th_hat = res.x_hat[:, L["theta"]]
    th_true = res.x_true[0, L["theta"]]
    summary["variant"] = task.variant
    w = window(res.t.size)
    z = (res.x_true - res.x_hat)[w] ** 2 / np.maximum(res.P_diag[w], 1e-300)
    summary["nes_block"] = {
        b: float(np.mean(z[:, sl])) for b, sl in L.items() if sl.stop > sl.start
    }
    summary["theta_settle_s"] = [
        settle_time(res.t, th_hat[:, i], float(th_true[i])) for i in range(lib.p)
    ]
    out: dict[str, Any] = {
        "summary": summary,
        "nees": res.nees.astype(np.float64),
        "theta_hat": th_hat.astype(np.float64),
    }
    if task.keep_series:
        cols = np.r_[np.arange(L["q"].start, L["q"].stop), np.arange(L["qd"].start, L["qd"].stop)]
        out["t"] = res.t
        out["err"] = (res.x_true - res.x_hat)[:, cols]
        out["sd"] = np.sqrt(np.maximum(res.P_diag[:, cols], 0.0))
    return out


def progress_bar(total: int, enabled: bool) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="study", unit="run", mininterval=1.0)


def run_tasks(tasks: list[Task], workers: int) -> Iterator[tuple[int, dict[str, Any]]]:
    if workers <= 1 or len(tasks) <= 1:
        for i, task in enumerate(tasks):
            yield i, _run_task(task)
        return
    saved = {k: os.environ.get(k) for k in _BLAS_ENV}
    try:
        for k in _BLAS_ENV:
            os.environ.setdefault(k, "1")
        ctx = mp.get_context("spawn")
        with ctx.Pool(min(workers, len(tasks)), initializer=_worker_init) as pool:
            yield from pool.imap_unordered(_indexed, list(enumerate(tasks)))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _indexed(item: tuple[int, Task]) -> tuple[int, dict[str, Any]]:
    return item[0], _run_task(item[1])
