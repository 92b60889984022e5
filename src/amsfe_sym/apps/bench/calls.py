"""Section 2 of ``amsfe bench``: the per-call cost of generated functions by every route
(binding, pure C, ``casadi.external``, SX VM, Pinocchio), the compiled maths of one tick,
and the compiler-flag comparison."""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.bench.timing import CTimer, Timing, round4, run_checked, time_calls
from amsfe_sym.arrays import FloatArray
from amsfe_sym.core.jsonfile import to_json

__all__ = [
    "CALL_FUNCTIONS",
    "TICK_FUNCTIONS",
    "CallRow",
    "bench_calls",
    "bench_cflags",
    "tick_compiled_us",
]


#: Functions timed per call, in table order (``camera`` is the near-empty one that shows
#: the binding's fixed overhead; ``plant_step`` is the simulated truth, once per tick).
CALL_FUNCTIONS: tuple[str, ...] = (
    "transition_step",
    "transition_inverse",
    "camera_measure",
    "mass_matrix",
    "camera",
    "plant_step",
)


def _inputs(lib: Any, name: str, x: FloatArray, u: FloatArray) -> list[FloatArray]:
    """Arguments of function ``name`` at the state ``x`` and input ``u``, by input name."""
    L = lib.layout
    n = lib.n
    by_name = {
        "x": x,
        "x_next": x,
        "u": u,
        "q": x[L["q"]],
        "qd": x[L["qd"]],
        "theta": x[L["theta"]],
        "xp": x[: 4 * n],
        "tau_d": np.linspace(-0.05, 0.05, 2 * n),
    }
    out = []
    for io in lib.manifest.functions[name].inputs:
        rows, cols = io.shape
        a = by_name.get(io.name, np.linspace(-0.1, 0.1, rows * cols))
        out.append(np.array(a, dtype=float).reshape(rows) if cols == 1 else a)
    return out


def _state(lib: Any, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """A random state (theta at its true value) and input of ``lib``'s robot."""
    n = lib.n
    x = np.concatenate([rng.uniform(-1.0, 1.0, 4 * n), lib.theta_true])
    x[lib.layout["qm"]] = x[lib.layout["q"]] + rng.uniform(-0.01, 0.01, n)
    return x, rng.uniform(-1.0, 1.0, n)


def _as_arrays(out: Any, shapes: Sequence[tuple[int, ...]]) -> list[FloatArray]:
    outs = out if isinstance(out, (tuple, list)) else [out]
    return [
        np.asarray(o, dtype=float).reshape(s, order="F") for o, s in zip(outs, shapes, strict=True)
    ]


def _max_diff(a: Sequence[FloatArray], b: Sequence[FloatArray]) -> float:
    return float(max(np.max(np.abs(p - q), initial=0.0) for p, q in zip(a, b, strict=True)))


@dataclass
class CallRow:
    """Per-call cost of one function by every route [us] (None: no such route).

    ``overhead_us`` is the binding's time minus the pure C time; ``max_diff_*`` compare
    each route's outputs with the binding's at the same arguments.
    """

    function: str
    ctypes: Timing | None = None
    pure_c: Timing | None = None
    external: Timing | None = None
    sx_vm: Timing | None = None
    pinocchio: Timing | None = None
    pinocchio_what: str = ""
    pinocchio_core: Timing | None = None
    pinocchio_core_what: str = ""
    overhead_us: float | None = None
    overhead_min_us: float | None = None
    max_diff_external: float | None = None
    max_diff_sx_vm: float | None = None
    max_diff_pinocchio: float | None = None
    notes: list[str] = field(default_factory=list)


def bench_calls(
    lib: Any,
    robot: Any,
    repeat: int,
    rounds: int,
    functions: Sequence[str] = CALL_FUNCTIONS,
    workdir: Path | None = None,
    seed: int = 0,
) -> list[CallRow]:
    """Per-call cost of ``functions`` by every route (see :class:`CallRow`).

    Args:
        lib: The :class:`~amsfe_sym.runtime.library.ModelLibrary`.
        robot: The loaded robot (for the SX Functions and Pinocchio), or None to skip both.
        repeat: Upper bound on calls per round.
        rounds: Rounds per timing (median reported).
        functions: Names to time.
        workdir: Where to build the C timing loop (default: a temporary folder).
        seed: Seed of the random state.
    """
    from amsfe_sym.apps.reference import PinocchioModel
    from amsfe_sym.estimation import ekf
    from amsfe_sym.runtime.models import CompiledTransition, noise_covariance

    rng = np.random.default_rng(seed)
    x, u = _state(lib, rng)
    n = lib.n
    sx: dict[str, Any] = {}
    pm: PinocchioModel | None = None
    Qw = noise_covariance(lib, 0.1, 0.1, 0.05)
    if robot is not None:
        from amsfe_sym.symbolic.model import build_functions

        sx = build_functions(robot).functions
        pm = PinocchioModel(robot, Qw)
    rows: list[CallRow] = []
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-c-") as tmp:
        ctimer = CTimer(workdir or Path(tmp))
        for name in functions:
            row = CallRow(name)
            f = lib.function(name)
            args = _inputs(lib, name, x, u)
            ref = list(f(*args))
            shapes = [r.shape for r in ref]
            row.ctypes = time_calls(f.call_into, args, repeat, rounds)
            row.pure_c, checksum = ctimer.time(lib.library_path, name, args, rounds)
            if not math.isclose(
                checksum, float(sum(np.sum(r) for r in ref)), rel_tol=1e-9, abs_tol=1e-9
            ):
                row.notes.append("pure C outputs differ from the binding's")
            row.overhead_us = round(row.ctypes.median_us - row.pure_c.median_us, 4)
            row.overhead_min_us = round(row.ctypes.min_us - row.pure_c.min_us, 4)
            ext = lib.external(name)
            row.max_diff_external = _max_diff(_as_arrays(ext(*args), shapes), ref)
            row.external = time_calls(ext, args, repeat, rounds)
            if name in sx:
                row.max_diff_sx_vm = _max_diff(_as_arrays(sx[name](*args), shapes), ref)
                row.sx_vm = time_calls(sx[name], args, repeat, rounds)
            if pm is not None:
                _pinocchio_row(row, pm, lib, args, ref, repeat, rounds)
            rows.append(row)
        # the estimator's EKF predict (eqs. 13-14) on the compiled model and on Pinocchio
        P = np.diag(rng.uniform(0.01, 0.1, lib.N))
        row = CallRow("ekf_predict")
        cmodel = CompiledTransition(lib, Qw)
        row.ctypes = time_calls(ekf.predict, (cmodel, x, P, u), repeat, rounds)
        row.notes.append("ekf.predict: transition_step + A P A^T + Gamma Qw Gamma^T in numpy")
        if pm is not None:
            row.pinocchio = time_calls(ekf.predict, (pm, x, P, u), repeat, rounds)
            row.pinocchio_what = "ekf.predict on the Pinocchio transition"
            if robot.spec.model.integrator == "semi_implicit":
                a, b = ekf.predict(cmodel, x, P, u), ekf.predict(pm, x, P, u)
                cols = slice(0, 4 * n)
                row.max_diff_pinocchio = _max_diff([a.x, a.A[:, cols]], [b.x, b.A[:, cols]])
        rows.append(row)
    return rows


def _pinocchio_row(
    row: CallRow,
    pm: Any,
    lib: Any,
    args: list[FloatArray],
    ref: list[FloatArray],
    repeat: int,
    rounds: int,
) -> None:
    n = lib.n
    name = row.function
    if name == "mass_matrix":
        row.pinocchio = time_calls(pm.mass_matrix, args[:1], repeat, rounds)
        row.pinocchio_what = "pin.crba"
        row.max_diff_pinocchio = _max_diff([pm.mass_matrix(args[0])], ref)
    elif name == "transition_step":
        row.pinocchio = time_calls(pm.transition_step, args, repeat, rounds)
        row.pinocchio_what = "pin.computeABADerivatives + numpy (semi-implicit Euler)"
        q, qd = args[0][:n], args[0][n : 2 * n]
        core_args = (pm.model, pm.data, pm.q_pin(q), qd, np.zeros(n))
        row.pinocchio_core = time_calls(pm.pin.computeABADerivatives, core_args, repeat, rounds)
        row.pinocchio_core_what = "pin.computeABADerivatives alone"
        if lib.manifest.integrator == "semi_implicit":
            xn, A, G = pm.transition_step(*args)
            cols = slice(0, 4 * n)  # Pinocchio's A has no d/dtheta column
            row.max_diff_pinocchio = _max_diff(
                [xn, A[:, cols], G], [ref[0], ref[1][:, cols], ref[2]]
            )
        else:
            integrator = lib.manifest.integrator
            row.notes.append(
                f"Pinocchio row is a semi-implicit step; the robot uses {integrator!r}"
            )
    elif name == "camera_measure":
        row.pinocchio = time_calls(pm.camera_measure, args[:1], repeat, rounds)
        row.pinocchio_what = "pin.computeFrameJacobian + numpy pinhole"
        core_args = (pm.model, pm.data, pm.q_pin(args[0]), pm.frame, pm.pin.LOCAL_WORLD_ALIGNED)
        row.pinocchio_core = time_calls(pm.pin.computeFrameJacobian, core_args, repeat, rounds)
        row.pinocchio_core_what = "pin.computeFrameJacobian alone"
        y, J, d = pm.camera_measure(args[0])
        if not lib.manifest.camera_depends_on_theta:
            row.max_diff_pinocchio = _max_diff([y, J, np.array([d])], ref)
    elif name == "plant_step":
        substeps = lib.manifest.plant_substeps
        pargs = (args[0], args[1], args[3], substeps)
        row.pinocchio = time_calls(pm.plant_step, pargs, repeat, rounds)
        row.pinocchio_what = f"numpy RK4 on pin.aba ({4 * substeps} calls)"
        q, qd = args[0][:n], args[0][n : 2 * n]
        core_args = (pm.model, pm.data, pm.q_pin(q), qd, np.zeros(n))
        row.pinocchio_core = time_calls(pm.pin.aba, core_args, repeat, rounds)
        row.pinocchio_core_what = "one pin.aba"
        row.max_diff_pinocchio = _max_diff([pm.plant_step(*pargs)], ref)


#: Compiled functions every tick of :func:`amsfe_sym.sim.loop.run` calls once (the plant,
#: the EKF predict, the ``truth-ct`` controller's M and b); the camera's functions run once
#: per frame and are left out.
TICK_FUNCTIONS: tuple[str, ...] = ("plant_step", "transition_step", "mass_matrix", "bias")


def tick_compiled_us(lib: Any, rounds: int, seed: int = 0) -> dict[str, float]:
    """Pure C time [us] of each of :data:`TICK_FUNCTIONS` in ``lib`` and their ``total``."""
    x, u = _state(lib, np.random.default_rng(seed))
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-c-") as tmp:
        ctimer = CTimer(Path(tmp))
        for name in TICK_FUNCTIONS:
            t, _ = ctimer.time(lib.library_path, name, _inputs(lib, name, x, u), rounds)
            out[name] = t.median_us
    out["total"] = round(sum(out.values()), 4)
    return out


def bench_cflags(
    lib: Any,
    flag_sets: Sequence[str],
    repeat: int,
    rounds: int,
    compile_repeat: int = 1,
    function: str = "transition_step",
) -> list[dict[str, Any]]:
    """Recompile ``lib``'s generated C with each flag set and time ``function``.

    Each build goes to its own temporary folder with a copy of the manifest, is loaded
    with :class:`~amsfe_sym.runtime.library.ModelLibrary` and timed through the binding and
    in pure C.  Compile time is the fastest of ``compile_repeat`` builds.
    """
    from amsfe_sym.codegen import compiler
    from amsfe_sym.runtime.library import ModelLibrary, file_sha256

    src = lib.dir / lib.manifest.source
    rng = np.random.default_rng(1)
    x, u = _state(lib, rng)
    args = _inputs(lib, function, x, u)
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-cflags-") as tmp:
        ctimer = CTimer(Path(tmp))
        for i, flags in enumerate(flag_sets):
            d = Path(tmp) / f"build{i}"
            d.mkdir()
            cmd = [
                compiler(),
                *flags.split(),
                "-fPIC",
                "-shared",
                "-o",
                lib.manifest.library,
                str(src),
                "-lm",
            ]
            times = []
            for _ in range(compile_repeat):
                t0 = time.perf_counter()
                run_checked(
                    cmd,
                    f"compiling with {flags!r}",
                    "success",
                    "drop or correct the flag set the compiler refused",
                    cwd=d,
                )
                times.append(time.perf_counter() - t0)
            # this build is ours: record its own hash, as generate does
            manifest = json.loads((lib.dir / "manifest.json").read_text())
            manifest["library_sha256"] = file_sha256(d / lib.manifest.library)
            (d / "manifest.json").write_text(to_json(manifest))
            blib = ModelLibrary(d)
            f = blib.function(function)
            t_py = time_calls(f.call_into, args, repeat, rounds)
            t_c, _ = ctimer.time(blib.library_path, function, args, rounds)
            out.append(
                {
                    "cflags": flags,
                    "compile_s": round4(min(times)),
                    "compile_s_all": [round4(t) for t in times],
                    "library_kb": round((d / lib.manifest.library).stat().st_size / 1024, 1),
                    "ctypes_us": t_py.median_us,
                    "pure_c_us": t_c.median_us,
                }
            )
    return out
