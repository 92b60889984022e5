"""Section 5 of ``amsfe bench``: tick cost and generate + compile time against joints.

Deterministic arm-like serial chains of ``n`` revolute joints (axes cycling z, y, y, x, y,
x; box inertias, masses and centres of mass from ``numpy.random.default_rng(n)``, as
``tests/test_random_chains.py`` builds its chains), each with the ``rk4`` estimator model the
arm scenarios use and the defaults of a bare URDF (docs/reference/robot-spec.md), then the shipped
Panda (robots/panda, 7 joints).  Per row: a cold ``generate(force=True)`` in a fresh process
into a temporary folder (wall time, lines of generated C, peak memory of the process and its
compiler; the compile prints a progress line every few seconds), the pure C ``oosm`` tick
(:mod:`amsfe_sym.apps.bench.tick`'s timer) over synthetic inputs (the arm held at its start,
encoders reading it) and, on the same inputs, the numpy + Pinocchio EKF tick
(:class:`~amsfe_sym.apps.bench.tick.BaselineEkf`), Pinocchio's ``computeABADerivatives`` alone,
and the compiled closed loop (the chains: :func:`~amsfe_sym.apps.bench.ticks.timing_scenario`;
the Panda: ``panda-control``).  Growth exponents are least-squares slopes of log(cost)
against log(n) over the chains, to compare with the O(N^3) of the covariance update.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.bench.tick import (
    TickInputs,
    build_tick_timer,
    compiled_tick,
    fit_exponent,
)

__all__ = ["aba_derivatives_us", "bench_row", "bench_scaling", "chain_urdf"]


#: Joint axes along the chain, as on a 6-DOF arm (base yaw, shoulder and elbow pitch, wrist).
_AXES = ((0, 0, 1), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0))


def chain_urdf(n: int, seed: int | None = None) -> str:
    """A serial arm-like chain of ``n`` revolute joints as URDF text, the same for the same
    seed (default: ``n``): axes cycling as :data:`_AXES`, links along x, box inertias with
    seeded masses, sizes and centres of mass (tests/test_random_chains.py draws the axes and
    placements at random too, which makes far denser expressions than a real arm's)."""
    rng = np.random.default_rng(n if seed is None else seed)
    parts = ['<robot name="chain">', '<link name="l0"/>']
    for i in range(1, n + 1):
        m = rng.uniform(0.5, 5.0)
        dims = rng.uniform(0.05, 0.4, 3)  # a box: principal moments satisfy the triangle law
        moments = m / 12.0 * np.array([dims[1] ** 2 + dims[2] ** 2, dims[0] ** 2 + dims[2] ** 2])
        moments = np.append(moments, m / 12.0 * (dims[0] ** 2 + dims[1] ** 2))
        com = rng.uniform(-0.1, 0.1, 3)
        parts.append(
            f'<link name="l{i}"><inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/>'
            f'<mass value="{m}"/><inertia ixx="{moments[0]}" ixy="0" ixz="0" '
            f'iyy="{moments[1]}" iyz="0" izz="{moments[2]}"/></inertial></link>'
        )
        axis = _AXES[(i - 1) % len(_AXES)]
        xyz = np.array([0.0, 0.0, 0.1]) if i == 1 else np.array([rng.uniform(0.1, 0.4), 0, 0])
        parts.append(
            f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
            f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
            f'<axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
            '<limit lower="-3" upper="3" effort="100" velocity="5"/></joint>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


def _synthetic_inputs(lib: Any, ticks: int) -> TickInputs:
    """oosm at rest: x0 with q = qm = 0.1, P0 diagonal, u = 0, encoders reading x0."""
    from amsfe_sym.estimation import FilterConfig
    from amsfe_sym.runtime.models import (
        CameraMeasurement,
        CompiledTransition,
        EncoderMeasurement,
        noise_covariance,
    )

    n, N = lib.n, lib.N
    x0 = np.concatenate([np.full(n, 0.1), np.zeros(n), np.full(n, 0.1), np.zeros(n)])
    x0 = np.concatenate([x0, lib.theta_true])
    P0 = np.diag(
        np.r_[np.full(n, 1e-4), np.full(n, 1e-2), np.full(2 * n, 1e-6), np.full(N - 4 * n, 1e-2)]
    )
    kwargs = {
        "model": CompiledTransition(lib, noise_covariance(lib, 0.1, 0.1, 0.01)),
        "encoder": EncoderMeasurement(lib, 1e-8, 1e-4),
        "camera": CameraMeasurement(lib, 1.0),
        "x0": x0,
        "P0": P0,
        "config": FilterConfig(buffer_steps=50),
    }
    z = np.tile(np.r_[x0[2 * n : 3 * n], x0[3 * n : 4 * n]], (ticks, 1))
    return TickInputs(lib, kwargs, np.zeros((ticks, n)), z)


#: Generated functions that compute the forward dynamics' jacobian on their own, timed next to
#: Pinocchio's ``computeABADerivatives`` when the library has one (the first found).
DYNAMICS_JACOBIAN_FUNCTIONS = ("dynamics_jacobian", "forward_dynamics_jacobian", "rk4_stage")

#: The row quantities whose growth with the joints is fitted (log-log slope over n >= 2).
FITTED = (
    "c_lines",
    "generate_s",
    "peak_mb",
    "tick_us",
    "tick_p99_us",
    "baseline_us",
    "aba_derivatives_us",
    "loop_us_per_tick",
)


def aba_derivatives_us(robot: Any, rounds: int = 5) -> float:
    """Median time of one ``pin.computeABADerivatives`` at a seeded random state [us]."""
    import pinocchio as pin

    from amsfe_sym.apps.bench.timing import time_calls

    model = robot.pin_model_at(robot.theta_true)
    data = model.createData()
    rng = np.random.default_rng(0)
    q = pin.randomConfiguration(model) if model.nq != model.nv else rng.uniform(-1, 1, model.nq)
    v, tau = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
    t = time_calls(pin.computeABADerivatives, (model, data, q, v, tau), 20000, rounds)
    return round(t.median_us, 4)


def _dynamics_jacobian_us(lib: Any, work: Path, rounds: int) -> dict[str, Any] | None:
    """Pure C time of the library's own dynamics-jacobian function, if it has one."""
    from amsfe_sym.apps.bench.calls import _inputs, _state
    from amsfe_sym.apps.bench.timing import CTimer

    for name in DYNAMICS_JACOBIAN_FUNCTIONS:
        if name in lib.manifest.functions:
            x, u = _state(lib, np.random.default_rng(0))
            t, _ = CTimer(work).time(lib.library_path, name, _inputs(lib, name, x, u), rounds)
            return {"function": name, "median_us": t.median_us}
    return None


def _closed_loop(lib: Any, scenario: str | None, duration: float) -> dict[str, Any]:
    """The compiled closed loop of ``scenario`` (None: :func:`timing_scenario`'s) on ``lib``."""
    from amsfe_sym.apps.bench.ticks import timing_scenario
    from amsfe_sym.errors import AmsfeError
    from amsfe_sym.sim.loop import run

    sc = timing_scenario(lib, duration, scenario)
    try:
        res = run(sc, lib, runtime="compiled")
    except AmsfeError as exc:
        return {"scenario": sc.name, "error": str(exc)[:200]}
    sim = res.t.size * lib.T
    return {
        "scenario": sc.name,
        "loop_us_per_tick": round(1e6 * res.wall_time_s / res.t.size, 2),
        "real_time_factor": round(sim / max(res.wall_time_s, 1e-12), 1),
        "diverged_at_s": res.diverged_at,
    }


def bench_row(
    label: str,
    spec: Path,
    work: Path,
    exe: Path,
    ticks: int,
    scenario: str | None = None,
    loop_duration: float = 2.0,
    rounds: int = 5,
    progress: bool = False,
) -> dict[str, Any]:
    """One row of the scaling table: cold generate + compile of ``spec`` in a fresh process
    (lines of C, seconds, peak memory), the pure C oosm tick, the numpy + Pinocchio EKF tick
    and ``computeABADerivatives`` on the same robot, and the compiled closed loop."""
    from amsfe_sym.apps.bench.generation import _generate_in_subprocess
    from amsfe_sym.apps.bench.tick import baseline_tick
    from amsfe_sym.load import load_robot
    from amsfe_sym.runtime.library import ModelLibrary

    if progress:
        print(f"  {label}: generate + compile (cold, new process) ...", flush=True)
    gen = _generate_in_subprocess(str(spec), work / "gen", force=True, progress=progress)
    lib = ModelLibrary(Path(gen["out_dir"]))
    lines = 0
    for src in sorted(lib.dir.glob("*.c")):  # the generated C (one file today)
        with src.open() as fh:
            lines += sum(1 for _ in fh)
    inp = _synthetic_inputs(lib, ticks)
    stats, _ = compiled_tick(exe, "oosm", inp, work)
    robot = load_robot(spec)
    base, _ = baseline_tick(robot, inp)
    row: dict[str, Any] = {
        "robot": label,
        "joints": lib.n,
        "N": lib.N,
        "c_lines": lines,
        "generate_s": round(gen["seconds"], 3),
        "peak_mb": round(gen["peak_mb"], 1),
        "tick_us": stats.median_us,
        "tick_p99_us": stats.p99_us,
        "baseline_us": base.median_us,
        "baseline_p99_us": base.p99_us,
        "aba_derivatives_us": aba_derivatives_us(robot, rounds),
        "dynamics_jacobian": _dynamics_jacobian_us(lib, work, rounds),
    }
    row["speedup_baseline"] = round(row["baseline_us"] / row["tick_us"], 2)
    row.update(_closed_loop(lib, scenario, loop_duration))
    if progress:
        print(f"  {label}: {row}", flush=True)
    return row


def bench_scaling(
    joints: Sequence[int] = tuple(range(1, 13)),
    ticks: int = 500,
    integrator: str = "rk4",
    progress: bool = False,
    panda: bool = True,
    loop_duration: float = 2.0,
    rounds: int = 5,
) -> dict[str, Any]:
    """The scaling table: chains of ``joints`` joints, then (``panda``) the shipped Panda.

    Returns:
        ``{"rows": [bench_row(...)], "exponents": {quantity: slope}, "integrator"}``; the
        exponents are fitted over the chain rows with n >= 2 (:data:`FITTED`), the Panda row
        is reported beside them, not fitted.
    """
    from amsfe_sym.load.spec import robots_dir

    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-scaling-") as tmp:
        work = Path(tmp)
        exe = build_tick_timer(work)
        for n in joints:
            folder = work / f"chain{n}"
            folder.mkdir()
            (folder / "chain.urdf").write_text(chain_urdf(n))
            (folder / "robot.toml").write_text(
                f'name = "chain{n}"\nurdf = "chain.urdf"\n[model]\nintegrator = "{integrator}"\n'
            )
            rows.append(
                bench_row(
                    f"chain{n}",
                    folder / "robot.toml",
                    work,
                    exe,
                    ticks,
                    None,
                    loop_duration,
                    rounds,
                    progress,
                )
            )
        if panda:
            spec = robots_dir() / "panda" / "robot.toml"
            rows.append(
                bench_row(
                    "panda",
                    spec,
                    work,
                    exe,
                    ticks,
                    "panda-control",
                    loop_duration,
                    rounds,
                    progress,
                )
            )
    fit = [r for r in rows if r["robot"].startswith("chain") and r["joints"] >= 2]
    out: dict[str, Any] = {"integrator": integrator, "rows": rows, "exponents": {}}
    if len(fit) >= 2:
        js = [r["joints"] for r in fit]
        for key in FITTED:
            vals = [float(r[key]) for r in fit if isinstance(r.get(key), int | float)]
            if len(vals) == len(fit) and min(vals) > 0:
                out["exponents"][key] = round(fit_exponent(js, vals), 2)
    return out
