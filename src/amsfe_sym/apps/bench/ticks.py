"""Section 3 of ``amsfe bench``: closed-loop ticks with every estimator."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from amsfe_sym.estimation.registry import ESTIMATORS
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario

__all__ = ["ESTIMATOR_NAMES", "bench_estimators", "timing_scenario"]

#: The estimators the tick section times by default: every registered one.
ESTIMATOR_NAMES: tuple[str, ...] = tuple(ESTIMATORS)


def timing_scenario(lib: ModelLibrary, duration: float, scenario: str | None = None) -> Scenario:
    """The scenario the estimator section runs for the robot of ``lib``.

    ``scenario`` if given; ``paper-sim`` for ``paper_2link``; for any other robot,
    ``paper-sim``'s settings on that robot (its own integrator and camera timing) tracking a
    small sinusoid (0.2 rad, 0.5 Hz) about q = 0.3 rad per joint, the estimate starting
    0.05 rad off with theta at its true value.  The latter is a timing set-up only, not an
    estimation study: with theta starting at its spec's initial value (payload 0 kg for the
    UR5, true 2 kg) every estimator on the UR5 became overconfident and failed within 1.4 s
    under paper-sim's noise settings (docs/explanation/performance.md).
    """
    from amsfe_sym.scenario import load_scenario

    if scenario is not None:
        return load_scenario(scenario).with_overrides(duration=duration)
    base = load_scenario("paper-sim").with_overrides(duration=duration)
    if lib.name == base.robot:
        return base
    n = lib.n
    q0 = tuple(0.3 for _ in range(n))
    delay = lib.manifest.camera.delay
    return replace(
        base,
        name=f"bench-{lib.name}",
        robot=lib.manifest.spec or lib.manifest.urdf,
        integrator="",
        trajectory={
            "kind": "sinusoid",
            "amplitude": [0.2] * n,
            "omega": [math.pi] * n,
            "phase": [0.0] * n,
            "offset": list(q0),
        },
        plant=replace(base.plant, q0=q0, qd0=(0.0,) * n),
        estimate0=replace(
            base.estimate0,
            q=tuple(v + 0.05 for v in q0),
            qd=(0.0,) * n,
            theta=tuple(float(v) for v in lib.theta_true),
        ),
        filter=replace(base.filter, buffer_steps=max(base.filter.buffer_steps, delay + 10)),
    )


def bench_estimators(
    sc: Scenario, estimators: Sequence[str], lib: ModelLibrary
) -> list[dict[str, Any]]:
    """Run ``sc`` on ``lib`` once per estimator and report cost per tick and real-time
    factor.

    A run that fails (e.g. an estimator refusing an indefinite covariance) is reported with
    its error instead of timings, and the other estimators still run.
    """
    from amsfe_sym.errors import AmsfeError
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    rows: list[dict[str, Any]] = []
    for est in estimators:
        try:
            res = run(sc.with_overrides(estimator=est), lib)
        except AmsfeError as exc:
            rows.append({"estimator": est, "error": str(exc)})
            continue
        s = summarize(res)
        rows.append(
            {
                "estimator": est,
                "ticks": s["ticks"],
                "sim_time_s": s["sim_time_s"],
                "wall_time_s": s["wall_time_s"],
                "cost_per_tick_us": s["cost_per_tick_us"],
                "real_time_factor": round(s["sim_time_s"] / max(s["wall_time_s"], 1e-9), 2),
                "frames_applied": s["counters"].get("frames_applied", 0),
            }
        )
    return rows
