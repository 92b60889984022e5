"""One run of a sweep, as a worker runs it: the single place a sweep calls the simulator.

:func:`run_job` takes a :class:`~amsfe_sym.apps.sweep.spec.Job` and returns its table row: the
labels (axis values, seed, estimator, controller), ``status`` (``ok``, ``diverged`` or
``error``), ``error`` (the message of a run that raised) and every summary metric of
:func:`amsfe_sym.sim.record.summarize`, flattened to scalar columns (:func:`flatten`).

The library of a run is built or loaded on the worker's own machine from the job's
scenario (and its ``robot.*`` values), once per process and library key
(:func:`library_key`); :func:`amsfe_sym.codegen.generate` holds a file lock, so worker
processes on one machine build each library once and share it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from amsfe_sym.apps.sweep.spec import Job

if TYPE_CHECKING:
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import Scenario

__all__ = ["KEY_COLUMNS", "flatten", "library_key", "run_batch", "run_job"]

#: Columns every row has besides the axes: the run's id, labels, status and error.
KEY_COLUMNS = ("run_id", "estimator", "controller", "seed", "status", "error")

#: Per-process cache of loaded libraries (a Dask worker process keeps its own).
_LIBS: dict[tuple[Any, ...], ModelLibrary] = {}

#: Summary entries that become columns (the others are labels or constants of the sweep).
_METRICS = (
    "ticks",
    "sim_time_s",
    "wall_time_s",
    "cost_per_tick_us",
    "estimation_rmse",
    "tracking_rmse",
    "theta_final",
    "nees_mean",
    "diverged_at_s",
    "control",
    "counters",
)


def library_key(sc: Scenario, robot: Mapping[str, float]) -> tuple[Any, ...]:
    """What decides a run's library: the robot, the integrator, the ``robot.*`` values and
    (conservatively: a library may size its buffers by them) the camera period and delay.
    Runs with one key share one library; the engine batches by it."""
    return (
        sc.robot,
        sc.integrator,
        sc.camera.period,
        sc.camera.delay,
        tuple(sorted(robot.items())),
    )


def _library(sc: Scenario, robot: Mapping[str, float]) -> ModelLibrary:
    key = library_key(sc, robot)
    if key not in _LIBS:
        from amsfe_sym.codegen import library_for

        if robot:
            from amsfe_sym.apps.sweep.robot_axes import derive_spec
            from amsfe_sym.load.spec import load_spec

            _LIBS[key] = library_for(sc, robot=derive_spec(load_spec(sc.robot), robot))
        else:
            _LIBS[key] = library_for(sc)
    return _LIBS[key]


def flatten(summary: Mapping[str, Any]) -> dict[str, float]:
    """The metric columns of a ``summary.json``.

    Nested tables join their keys with dots (``control.u_rms``, ``counters.frames_applied``);
    a list of per-joint (or per-parameter) values becomes ``KEY.1``, ``KEY.2``, ... and, for
    RMS-like keys (names with ``rms``), ``KEY.rms`` = the root mean square over its entries
    (the RMSE over all joints), for ``max`` keys ``KEY.max``.  ``theta_final`` keeps its
    ``estimate``; None becomes NaN.
    """
    out: dict[str, float] = {}

    def put(key: str, v: Any) -> None:
        if isinstance(v, Mapping):
            for k, w in v.items():
                if key == "theta_final" and k != "estimate":
                    continue
                put(f"{key}.{k}", w)
        elif isinstance(v, list | tuple):
            vals = [float("nan") if w is None else float(w) for w in v]
            for i, w in enumerate(vals):
                out[f"{key}.{i + 1}"] = w
            if vals and "rms" in key:
                out[f"{key}.rms"] = math.sqrt(sum(w * w for w in vals) / len(vals))
            if vals and "max" in key:
                out[f"{key}.max"] = max(vals)
        elif v is None:
            out[key] = float("nan")
        elif isinstance(v, bool):
            out[key] = float(v)
        elif isinstance(v, int | float):
            out[key] = v

    for k in _METRICS:
        if k in summary:
            put(k, summary[k])
    return out


def run_job(job: Job) -> dict[str, Any]:
    """Run one job and return its row (an exception becomes an ``error`` row, never lost).

    Returns:
        ``run_id``, the labels, ``status`` (``ok``; ``diverged``: the closed loop lost the
        arm and the run stopped, its metrics cover the run up to there; ``error``), ``error``
        (``"Type: message"`` or ``""``) and the metrics of :func:`flatten`.
    """
    row: dict[str, Any] = {"run_id": job.run_id, **job.labels, "status": "ok", "error": ""}
    try:
        from amsfe_sym.sim.loop import run
        from amsfe_sym.sim.record import summarize

        lib = _library(job.scenario, job.robot)
        summary = summarize(run(job.scenario, lib, runtime=job.runtime))
    except Exception as exc:  # a failing run is a row with its error, not a lost sweep
        row.update(status="error", error=f"{type(exc).__name__}: {exc}".strip())
        return row
    row.update(flatten(summary))
    if summary.get("diverged_at_s") is not None:
        row["status"] = "diverged"
    return row


def run_batch(jobs: Sequence[Job]) -> list[dict[str, Any]]:
    """:func:`run_job` of each job, in order (what one Dask task runs).

    The toolkit's warnings (a refused camera frame, a diverged loop) are held back while it
    runs: thousands of runs would flood the terminal, and the table counts them
    (``counters.refused_*``, ``status``)."""
    logger = logging.getLogger("amsfe_sym")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        return [run_job(j) for j in jobs]
    finally:
        logger.setLevel(level)
