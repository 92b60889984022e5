"""Section 5 of ``amsfe bench``: tick cost and generate + compile time against joints.

Deterministic arm-like serial chains of ``n`` revolute joints (axes cycling z, y, y, x, y,
x; box inertias, masses and centres of mass from ``numpy.random.default_rng(n)``, as
``tests/test_random_chains.py`` builds its chains), each with the ``rk4`` estimator model the
arm scenarios use and the defaults of a bare URDF (docs/robot-spec.md).  Per chain: a cold
``generate(force=True)`` into a temporary folder (wall time, lines of C), then the pure C
``oosm`` tick (:mod:`amsfe_sym.apps.bench.tick`'s timer) over synthetic inputs (the arm held at
its start, encoders reading it).  The growth exponent is the least-squares slope of
log(cost) against log(n), to compare with the O(N^3) of the covariance update.
"""

from __future__ import annotations

import tempfile
import time
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

__all__ = ["bench_scaling", "chain_urdf"]


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


def bench_scaling(
    joints: Sequence[int] = tuple(range(1, 13)),
    ticks: int = 500,
    integrator: str = "rk4",
    progress: bool = False,
) -> dict[str, Any]:
    """Tick cost and generate + compile time of chains of ``joints`` joints.

    Returns:
        ``{"rows": [{joints, N, c_lines, generate_s, tick_us, tick_p99_us}], "exponent_tick",
        "exponent_generate", "integrator"}`` (exponents fitted over the rows with n >= 2).
    """
    from amsfe_sym.codegen import generate
    from amsfe_sym.runtime.library import ModelLibrary

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
            t0 = time.perf_counter()
            res = generate(folder / "robot.toml", out=work / "gen", force=True)
            gen_s = time.perf_counter() - t0
            lib = ModelLibrary(res.out_dir)
            src = res.out_dir / lib.manifest.source
            with src.open() as fh:
                lines = sum(1 for _ in fh)
            stats, _ = compiled_tick(exe, "oosm", _synthetic_inputs(lib, ticks), work)
            rows.append(
                {
                    "joints": n,
                    "N": lib.N,
                    "c_lines": lines,
                    "generate_s": round(gen_s, 3),
                    "tick_us": stats.median_us,
                    "tick_p99_us": stats.p99_us,
                }
            )
            if progress:
                print(f"  chain {n}: {rows[-1]}", flush=True)
    fit = [r for r in rows if r["joints"] >= 2]
    out: dict[str, Any] = {"integrator": integrator, "rows": rows}
    if len(fit) >= 2:
        js = [r["joints"] for r in fit]
        out["exponent_tick"] = round(fit_exponent(js, [r["tick_us"] for r in fit]), 2)
        out["exponent_generate"] = round(fit_exponent(js, [r["generate_s"] for r in fit]), 2)
    return out
