"""Sweep files (``sweeps/*.toml``): a base scenario, axes, estimators, controllers, seeds.

A sweep file reads::

    [sweep]
    name = "camera-delay"            # optional (default: the file's stem)
    scenario = "paper-sim"           # a shipped scenario name or a .toml path
    duration = 5.0                   # [s] optional: overrides the scenario's
    estimators = ["oosm", "replay"]  # default: the scenario's estimator
    controllers = ["amsfe"]          # default: the scenario's controller
    seeds = [0, 1, 2]                # or { first = 0, count = 3 }
    set = ["filter.buffer_steps=600"]  # fixed --set overrides of every run
    runtime = "compiled"             # or "python" (the reference loop): sim.loop.run(runtime=)

    [axes]                           # every combination is run
    "camera.delay" = [0, 125, 250]               # a list, or a range:
    "camera.period" = { start = 25, stop = 250, step = 75 }   # stop included when hit
    "robot.theta.payload.true" = { start = 0.0, stop = 1.0, num = 5 }

    [report]                         # defaults of the figures and of --report
    metric = "estimation_rmse.q.rms"
    x = "camera.delay"               # one axis: line plots; x and y: heatmaps
    y = ""

Axis keys are the keys ``amsfe simulate --set`` takes (``camera.delay``, ``filter.*``,
``controller_gains.NAME.K``, ...: docs/reference/scenarios.md) plus the robot keys of
:mod:`amsfe_sym.apps.sweep.robot_axes` (``robot.theta.NAME.true``, ``robot.stiffness_error``).
Every combination's scenario is built and validated here, before anything runs, so a bad
key or value stops the sweep with one line.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from amsfe_sym.apps.sweep.robot_axes import ROBOT_PREFIX, check_robot_key
from amsfe_sym.core.toml import read_toml
from amsfe_sym.errors import ConfigError, check_known_keys, describe
from amsfe_sym.scenario import Scenario, apply_sets, load_scenario

__all__ = [
    "AxisValue",
    "Job",
    "ReportDefaults",
    "SweepSpec",
    "expand_jobs",
    "format_set_value",
    "load_sweep",
]

AxisValue = int | float | str | bool

_SWEEP_KEYS = {"name", "scenario", "duration", "estimators", "controllers", "seeds", "set"}
_SWEEP_KEYS |= {"runtime", "description"}
_TOP_KEYS = {"sweep", "axes", "report"}
_REPORT_KEYS = {"metric", "x", "y"}
#: Default metric of the figures and of ``--report``.
DEFAULT_METRIC = "tracking_rmse.q.rms"


@dataclass(frozen=True)
class ReportDefaults:
    """``[report]``: the metric and the axes of the figures (``y`` empty: line plots)."""

    metric: str = DEFAULT_METRIC
    x: str = ""
    y: str = ""


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file.

    Attributes:
        name: Label of the sweep (the file's stem unless ``name`` is given).
        scenario: The base scenario, with ``duration`` and the fixed ``set`` applied.
        axes: Axis key -> its values, in file order.
        estimators, controllers: Names run at every axis point.
        seeds: Seeds run at every point.
        sets: The fixed ``--set`` overrides (already in ``scenario``).
        runtime: ``"compiled"`` (the C loop, default) or ``"python"`` (the reference loop).
        report: Defaults of the figures and the report table.
        source: The file, if it came from one.
    """

    name: str
    scenario: Scenario
    axes: dict[str, tuple[AxisValue, ...]]
    estimators: tuple[str, ...]
    controllers: tuple[str, ...]
    seeds: tuple[int, ...]
    sets: tuple[str, ...] = ()
    runtime: str = "compiled"
    report: ReportDefaults = field(default_factory=ReportDefaults)
    description: str = ""
    source: Path | None = None

    @property
    def n_runs(self) -> int:
        """Runs in the full grid: points x estimators x controllers x seeds."""
        points = math.prod(len(v) for v in self.axes.values())
        return points * len(self.estimators) * len(self.controllers) * len(self.seeds)

    def base_hash(self) -> str:
        """Hash of what every run shares (the resolved base scenario, the fixed overrides,
        the runtime): a results folder holding rows of another base is not resumed."""
        base = self.scenario.to_dict()
        base.pop("seed", None)
        base.pop("estimator", None)
        base.pop("controller", None)
        blob = json.dumps(
            {"scenario": base, "runtime": self.runtime}, sort_keys=True, default=str
        ).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


@dataclass(frozen=True)
class Job:
    """One run of a sweep: what a worker needs to run it on its own machine.

    Attributes:
        run_id: Stable id of the run (hash of its labels): resume skips ids already done.
        index: Position in the sweep's grid (rows are sorted by it).
        labels: Axis values, ``seed``, ``estimator``, ``controller`` (the table's key
            columns).
        scenario: The run's scenario (axes, seed, estimator and controller applied).
        robot: The ``robot.*`` axis values of this run (empty: the scenario's robot as is).
        runtime: Passed to ``run(..., runtime=...)``.
    """

    run_id: str
    index: int
    labels: dict[str, AxisValue]
    scenario: Scenario
    robot: dict[str, float] = field(default_factory=dict)
    runtime: str = "compiled"


def _bad(where: str, expected: str, found: Any, fix: str) -> ConfigError:
    return ConfigError(describe(where, expected, repr(found), fix))


def _range(where: str, r: Mapping[str, Any]) -> tuple[AxisValue, ...]:
    """``{start, stop, step}`` (stop included when a step lands on it) or ``{start, stop,
    num}`` (evenly spaced, both ends included).  Integers stay integers with an integer step."""
    keys = set(r)
    if keys not in ({"start", "stop", "step"}, {"start", "stop", "num"}):
        raise _bad(
            where,
            "{start, stop, step} or {start, stop, num}",
            dict(r),
            "write e.g. { start = 0, stop = 500, step = 100 }",
        )
    nums = {k: v for k, v in r.items()}
    for k, v in nums.items():
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise _bad(f"{where}.{k}", "a finite number", v, "write a number without quotes")
    start, stop = nums["start"], nums["stop"]
    if "num" in nums:
        num = nums["num"]
        if not isinstance(num, int) or num < 1:
            raise _bad(f"{where}.num", "an integer >= 1", num, "write num = 5")
        if num == 1:
            return (start,)
        values = [start + (stop - start) * i / (num - 1) for i in range(num)]
        if all(isinstance(x, int) for x in (start, stop)) and all(
            float(v).is_integer() for v in values
        ):
            return tuple(int(v) for v in values)
        return tuple(float(v) for v in values)
    step = nums["step"]
    if step == 0 or (stop - start) * step < 0:
        raise _bad(
            f"{where}.step",
            "a non-zero step towards stop",
            step,
            "give step the sign of stop - start",
        )
    count = math.floor((stop - start) / step + 1e-9) + 1
    if count > 100_000:
        raise _bad(where, "at most 100000 values", count, "use a larger step")
    if all(isinstance(x, int) for x in (start, stop, step)):
        return tuple(int(start + i * step) for i in range(count))
    return tuple(float(start + i * step) for i in range(count))


def _axis_values(key: str, raw: Any) -> tuple[AxisValue, ...]:
    where = f"[axes] {key!r}"
    if isinstance(raw, Mapping):
        values = _range(where, raw)
    elif isinstance(raw, list):
        values = tuple(raw)
    else:
        raise _bad(where, "a list or a range table", raw, "write e.g. [0, 125, 250]")
    if not values:
        raise _bad(where, "at least one value", raw, "give the axis one value or more")
    if any(isinstance(v, list | dict) for v in values):
        raise _bad(where, "numbers, strings or booleans", raw, "one value per entry")
    kinds = {
        "number" if isinstance(v, int | float) and not isinstance(v, bool) else type(v).__name__
        for v in values
    }
    if len(kinds) > 1:
        raise _bad(
            where,
            "values of one kind (a table column has one type)",
            raw,
            "write all values as numbers, or all as strings",
        )
    if kinds == {"number"} and not all(isinstance(v, int) for v in values):
        values = tuple(float(v) for v in values)  # 0 and 0.5 in one axis: floats
    if len(set(values)) != len(values):
        raise _bad(where, "distinct values", raw, "remove the repeated values")
    return values


def _names(where: str, raw: Any, default: str) -> tuple[str, ...]:
    if raw is None:
        return (default,)
    if isinstance(raw, str):
        raw = [raw]
    if not isinstance(raw, list) or not raw or not all(isinstance(v, str) for v in raw):
        raise _bad(where, "a non-empty list of names", raw, 'write e.g. ["oosm", "replay"]')
    if len(set(raw)) != len(raw):
        raise _bad(where, "distinct names", raw, "remove the repeated names")
    return tuple(raw)


def _seeds(raw: Any) -> tuple[int, ...]:
    if raw is None:
        return (0,)
    if isinstance(raw, Mapping) and set(raw) == {"first", "count"}:
        first, count = raw["first"], raw["count"]
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (first, count)) or (
            first < 0 or count < 1
        ):
            raise _bad(
                "[sweep] seeds",
                "first >= 0 and count >= 1",
                dict(raw),
                "write seeds = { first = 0, count = 5 }",
            )
        return tuple(range(first, first + count))
    ok = (
        isinstance(raw, list)
        and raw
        and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in raw)
    )
    if not ok:
        raise _bad(
            "[sweep] seeds",
            "a list of integers >= 0 or {first, count}",
            raw,
            "write seeds = [0, 1, 2]",
        )
    if len(set(raw)) != len(raw):
        raise _bad("[sweep] seeds", "distinct seeds", raw, "remove the repeated seeds")
    return tuple(raw)


def load_sweep(path: str | os.PathLike[str]) -> SweepSpec:
    """Parse and check a sweep file; build and validate the scenario of every grid point.

    Raises:
        ConfigError: unknown keys, bad values, an axis key ``--set`` does not know, or a
            value a scenario refuses.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(
            describe(
                f"sweep file {str(path)!r}",
                "a .toml file",
                "no such file",
                "pass a path such as sweeps/camera-delay.toml",
            )
        )
    return parse_sweep(read_toml(p, ConfigError), p)


def parse_sweep(data: Mapping[str, Any], path: Path | None = None) -> SweepSpec:
    """A :class:`SweepSpec` from parsed TOML (``path`` resolves a relative scenario path)."""
    where = str(path) if path else "sweep"
    for table, allowed in (
        (data, _TOP_KEYS),
        (data.get("sweep", {}), _SWEEP_KEYS),
        (data.get("report", {}), _REPORT_KEYS),
    ):
        if not isinstance(table, Mapping):
            raise _bad(
                where, "tables [sweep], [axes], [report]", table, "see docs/how-to/sweeps.md"
            )
        check_known_keys(where, table, allowed, "remove or rename them (docs/how-to/sweeps.md)")
    sw = dict(data.get("sweep", {}))
    scenario_ref = sw.get("scenario", "paper-sim")
    if not isinstance(scenario_ref, str):
        raise _bad(
            f"{where}: [sweep] scenario",
            "a scenario name or path",
            scenario_ref,
            'write scenario = "paper-sim"',
        )
    if path is not None and scenario_ref.endswith(".toml"):
        rel = path.parent / scenario_ref
        if not Path(scenario_ref).is_absolute() and rel.is_file():
            scenario_ref = str(rel)
    sc = load_scenario(scenario_ref)
    sets = sw.get("set", [])
    if not isinstance(sets, list) or not all(isinstance(s, str) for s in sets):
        raise _bad(
            f"{where}: [sweep] set",
            "a list of KEY=VALUE strings",
            sets,
            'write set = ["filter.buffer_steps=600"]',
        )
    duration = sw.get("duration")
    if duration is not None:
        if isinstance(duration, bool) or not isinstance(duration, int | float):
            raise _bad(
                f"{where}: [sweep] duration", "a number [s]", duration, "write duration = 5.0"
            )
        sets = [f"duration={float(duration)!r}", *sets]
    if sets:
        sc = apply_sets(sc, sets)
    runtime = sw.get("runtime", "compiled")
    if runtime not in ("python", "compiled"):
        raise _bad(
            f"{where}: [sweep] runtime",
            "python | compiled",
            runtime,
            'write runtime = "compiled" or "python"',
        )
    axes_raw = data.get("axes", {})
    if not isinstance(axes_raw, Mapping):
        raise _bad(
            f"{where}: [axes]", "a table of axis = values", axes_raw, "see docs/how-to/sweeps.md"
        )
    axes = {str(k): _axis_values(str(k), v) for k, v in axes_raw.items()}
    for key, values in axes.items():
        if key.startswith(ROBOT_PREFIX):
            check_robot_key(key, sc)
        elif key not in ("seed", "estimator", "controller"):
            for v in values:  # each value alone: an unknown key or a bad value stops here
                apply_sets(sc, [f"{key}={format_set_value(v)}"])
        elif key in ("seed", "estimator", "controller"):
            raise _bad(
                f"[axes] {key!r}", "a scenario key", key, f"list them in [sweep] {key}s instead"
            )
    report_raw = dict(data.get("report", {}))
    report = ReportDefaults(
        metric=str(report_raw.get("metric", DEFAULT_METRIC)),
        x=str(report_raw.get("x", next(iter(axes), ""))),
        y=str(report_raw.get("y", "")),
    )
    for k in ("x", "y"):
        v = getattr(report, k)
        if v and v not in axes:
            raise _bad(
                f"{where}: [report] {k}",
                f"one of the axes {list(axes)}",
                v,
                "name an axis of [axes]",
            )
    name = sw.get("name", path.stem if path else "sweep")
    spec = SweepSpec(
        name=str(name),
        scenario=sc,
        axes=axes,
        estimators=_names(f"{where}: [sweep] estimators", sw.get("estimators"), sc.estimator),
        controllers=_names(f"{where}: [sweep] controllers", sw.get("controllers"), sc.controller),
        seeds=_seeds(sw.get("seeds")),
        sets=tuple(sets),
        runtime=str(runtime),
        report=report,
        description=str(sw.get("description", "")),
        source=path,
    )
    _check_names(spec)
    return spec


def _check_names(spec: SweepSpec) -> None:
    from amsfe_sym.control import CONTROLLERS
    from amsfe_sym.estimation import ESTIMATORS

    for kind, names, known in (
        ("estimators", spec.estimators, tuple(ESTIMATORS)),
        ("controllers", spec.controllers, tuple(CONTROLLERS)),
    ):
        bad = [n for n in names if n not in known]
        if bad:
            raise _bad(
                f"[sweep] {kind}",
                f"names among {list(known)}",
                bad,
                "use the names of docs/reference/scenarios.md",
            )


def format_set_value(v: AxisValue) -> str:
    """``v`` as the VALUE of a ``--set KEY=VALUE`` (a TOML literal)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    return json.dumps(v)


def run_id(labels: Mapping[str, AxisValue]) -> str:
    """Stable id of a run from its labels (axis values, seed, estimator, controller)."""
    blob = json.dumps(dict(labels), sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def expand_jobs(spec: SweepSpec) -> list[Job]:
    """Every run of the grid, in a fixed order (axes, then estimator, controller, seed).

    Each point's scenario is built with ``apply_sets`` (so it is validated here, before
    anything runs); the ``robot.*`` values travel with the job and give the run's library.

    Raises:
        ConfigError: a value the scenario refuses.
    """
    keys = list(spec.axes)
    jobs: list[Job] = []
    for point in itertools.product(*(spec.axes[k] for k in keys)):
        values = dict(zip(keys, point, strict=True))
        sets = [
            f"{k}={format_set_value(v)}"
            for k, v in values.items()
            if not k.startswith(ROBOT_PREFIX)
        ]
        try:
            sc_point = apply_sets(spec.scenario, sets) if sets else spec.scenario
        except ConfigError as exc:
            raise ConfigError(f"[axes] point {values}: {exc}") from exc
        robot = {k: float(v) for k, v in values.items() if k.startswith(ROBOT_PREFIX)}
        for est, ctrl, seed in itertools.product(spec.estimators, spec.controllers, spec.seeds):
            labels: dict[str, AxisValue] = {
                **values,
                "estimator": est,
                "controller": ctrl,
                "seed": seed,
            }
            sc = sc_point.with_overrides(estimator=est, controller=ctrl, seed=seed)
            jobs.append(Job(run_id(labels), len(jobs), labels, sc, robot, spec.runtime))
    return jobs
