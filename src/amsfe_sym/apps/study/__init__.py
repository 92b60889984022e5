"""Monte Carlo study: seeds x estimators (x scenario variants), in parallel.

``amsfe study paper-sim --seeds 20`` runs every estimator on seeds ``0 .. 19`` of one
scenario and writes to a folder:

- ``study.md``: one table per variant, mean +- std over seeds of the estimation RMSE of q, qd
  (per joint) and theta, tracking RMSE, the median cost per tick, the time-averaged NEES and
  the fraction of time steps where the across-seed average NEES lies inside its two-sided
  95 % chi-square band (see :func:`nees_band`), plus the exact command that produced it;
- ``study.json``: the same aggregates and every run's ``summary.json`` (``simulate.summarize``)
  with the study's extra per-run metrics (theta settling time);
- figures (per variant): ``errors.png`` (paper Fig. 4 analog: q and qd estimation errors per
  joint vs time, one seed, every estimator), ``theta.png`` (Fig. 5 analog: theta estimate vs
  time), ``nees.png`` (average NEES vs time with the 95 % band, every estimator).

Metrics use the window of :func:`amsfe_sym.apps.simulate.summarize`: the last 80 % of the run.

The model library of each variant is generated once in the parent process before the pool
starts; the workers only load it by path (a :class:`ModelLibrary` holds ctypes handles and
is not sent between processes).  Workers are started with ``spawn`` (no fork of a process
holding loaded libraries and BLAS threads), with one BLAS thread each (``OMP_NUM_THREADS``,
``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1 unless already set).  ``workers = 1`` runs
everything in-process, with the parent's BLAS threading.

``--set section.field=value`` overrides scenario fields (``integrator=paper``,
``filter.link_torque_std=2``, ``encoders.q_std=0.01``, ...), validated with the scenario's
own checks: an unknown key or a bad value raises :class:`~amsfe_sym.errors.ConfigError`.

Modules: ``runner`` (:func:`run_study`), ``workers`` (one run per task, the process
pool), ``metrics`` (aggregates and tables); the figures are
:func:`amsfe_sym.apps.plots.run.plot_study` and ``--set`` is :func:`amsfe_sym.scenario.apply_sets`.

May import every room before apps, never the command line.
"""

from amsfe_sym.apps.study.metrics import (
    THETA_SETTLE_REL,
    aggregate,
    format_block_table,
    format_table,
    settle_time,
)
from amsfe_sym.apps.study.runner import StudyResult, parse_estimators, run_study
from amsfe_sym.scenario import apply_sets
from amsfe_sym.sim.record import nees_band

__all__ = [
    "THETA_SETTLE_REL",
    "StudyResult",
    "aggregate",
    "apply_sets",
    "format_block_table",
    "format_table",
    "nees_band",
    "parse_estimators",
    "run_study",
    "settle_time",
]
