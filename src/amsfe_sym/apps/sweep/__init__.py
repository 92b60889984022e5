"""``amsfe sweep``: scenario grids x estimators x controllers x seeds, run on Dask.

A sweep file (:mod:`~amsfe_sym.apps.sweep.spec`) names a base scenario, its axes, estimators,
controllers and seeds; :func:`run_sweep` runs every combination (on a
``distributed.LocalCluster``, or a cluster by address) and writes ``results.parquet``
(one row per run, :func:`~amsfe_sym.apps.sweep.jobs.run_job`) and ``sweep.json``;
:mod:`~amsfe_sym.apps.sweep.report` aggregates over seeds into tables and figures.
docs/how-to/sweeps.md has the format and the findings.

May import every room before apps (it runs simulations and builds their libraries), never
the command line.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from amsfe_sym.apps.sweep.engine import SweepOptions, SweepResult, make_batches, run_sweep
    from amsfe_sym.apps.sweep.jobs import flatten, library_key, run_batch, run_job
    from amsfe_sym.apps.sweep.spec import Job, SweepSpec, expand_jobs, load_sweep, parse_sweep

#: Where each name lives: imported on first use (PEP 562), so that ``amsfe`` itself, which
#: imports the sweep command, does not pay pandas' import (~0.3 s) on every start.
_HOMES = {
    "engine": ("SweepOptions", "SweepResult", "make_batches", "run_sweep"),
    "jobs": ("flatten", "library_key", "run_batch", "run_job"),
    "spec": ("Job", "SweepSpec", "expand_jobs", "load_sweep", "parse_sweep"),
}


def __getattr__(name: str) -> Any:
    for module, names in _HOMES.items():
        if name in names:
            return getattr(importlib.import_module(f"amsfe_sym.apps.sweep.{module}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "Job",
    "SweepOptions",
    "SweepResult",
    "SweepSpec",
    "expand_jobs",
    "flatten",
    "library_key",
    "load_sweep",
    "make_batches",
    "parse_sweep",
    "run_batch",
    "run_job",
    "run_sweep",
]
