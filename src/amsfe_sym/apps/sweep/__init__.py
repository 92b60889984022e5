"""``amsfe sweep``: scenario grids x estimators x controllers x seeds, run on Dask.

A sweep file (:mod:`~amsfe_sym.apps.sweep.spec`) names a base scenario, its axes, estimators,
controllers and seeds; :func:`run_sweep` runs every combination (on a
``distributed.LocalCluster``, or a cluster by address) and writes ``results.parquet``
(one row per run, :func:`~amsfe_sym.apps.sweep.jobs.run_job`) and ``sweep.json``;
:mod:`~amsfe_sym.apps.sweep.report` aggregates over seeds into tables and figures.
docs/sweeps.md has the format and the findings.

May import every room before apps (it runs simulations and builds their libraries), never
the command line.
"""

from amsfe_sym.apps.sweep.engine import SweepOptions, SweepResult, make_batches, run_sweep
from amsfe_sym.apps.sweep.jobs import flatten, library_key, run_batch, run_job
from amsfe_sym.apps.sweep.spec import Job, SweepSpec, expand_jobs, load_sweep, parse_sweep

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
