"""Section 4 of ``amsfe bench``: one estimator tick three ways, plus the control law.

The same recorded inputs (u and encoder samples of a closed-loop run of the scenario) drive:

- **compiled**: ``amsfe_est_tick`` of the library's C runtime, timed per tick in pure C
  (``bench/c/tick_timer.c``: no Python in the loop);
- **python**: the reference estimator's ``step`` (:mod:`amsfe_sym.estimation`, numpy over the
  compiled model functions), timed per tick with ``perf_counter_ns``;
- **baseline**: :class:`BaselineEkf`, what a user writes without this toolkit: Pinocchio
  (``computeABADerivatives``: qdd, its derivatives and M^-1 in one pass) for a semi-implicit
  Euler step of the flexible-joint model (:class:`amsfe_sym.apps.reference.PinocchioModel`; no
  d/dtheta column in A), numpy for ``A P A^T + Gamma Qw Gamma^T`` and a Joseph-form encoder
  update.

A tick is predict (eqs. 13-14) + encoder update (15-17) with no camera frame (frames arrive
every ``l`` ticks).  The frames' own cost (**late frame**: ``amsfe_est_camera_frame`` of each
recorded frame, delivered after its tick in a second pure-C run) is timed apart, per frame;
for oosm a frame ``d`` steps late is the eq. 23 accumulation over its lag, the A1 update and
the linearised backward map (one LU solve, no model call).  The control law
(``control_amsfe``, the cascade the AMSFE controller runs) is timed alone in pure C and added
to the compiled tick.  Medians and 99th percentiles over the ticks [us]; no figure is asserted.
"""

from __future__ import annotations

import math
import statistics
import struct
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.apps.bench.timing import run_checked

__all__ = [
    "BaselineEkf",
    "CallCost",
    "TickInputs",
    "TickStats",
    "bench_tick",
    "build_tick_timer",
    "compiled_tick",
    "python_tick",
    "record_tick_inputs",
    "write_tick_input",
]

FloatArray = NDArray[np.float64]

_TIMER_SOURCE = Path(__file__).parent / "c" / "tick_timer.c"


@dataclass(frozen=True)
class CallCost:
    """The cost of one kind of call, over the calls timed.

    Attributes:
        median_us: Median [us].
        p99_us: 99th percentile [us].
    """

    median_us: float
    p99_us: float


@dataclass(frozen=True)
class TickStats(CallCost):
    """Per-tick cost of one route (:class:`CallCost` over the ticks); ``ticks``: ticks timed."""

    ticks: int

    @classmethod
    def from_ns(cls, ns: FloatArray) -> TickStats:
        return cls(
            round(float(np.median(ns)) / 1e3, 4),
            round(float(np.percentile(ns, 99)) / 1e3, 4),
            len(ns),
        )


@dataclass
class TickInputs:
    """The estimator of a scenario at x(0|0), P(0|0) and the recorded inputs of its run.

    Attributes:
        lib: The library.
        kwargs: ``make_estimator`` arguments (model, encoder, camera, x0, P0, config).
        u: Inputs u[k] over [k, k+1], shape ``(K, n)``.
        z: Encoder samples taken at k + 1, shape ``(K, 2n)`` (NaN rows: none).
        frames: Camera frames delivered at steps 1..K, rows (exposure step, delivery step,
            u px, v px), in delivery order (none: shape ``(0, 4)``).
    """

    lib: Any
    kwargs: dict[str, Any]
    u: FloatArray
    z: FloatArray
    frames: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))


def record_tick_inputs(sc: Any, lib: Any) -> TickInputs:
    """Run ``sc`` on ``lib`` once (:func:`amsfe_sym.sim.loop.run`) and keep its inputs."""
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.loop import run

    est = build_run(sc, lib).estimator
    kwargs = {
        "model": est.model,
        "encoder": est.encoder,
        "camera": est.camera,
        "x0": est.x.copy(),
        "P0": est.P.copy(),
        "config": est.config,
    }
    res = run(sc, lib)
    K = res.u.shape[0] - 1
    frames = np.asarray(res.frames, float).reshape(-1, 4)
    frames = frames[(frames[:, 1] >= 1) & (frames[:, 1] <= K)]
    return TickInputs(
        lib, kwargs, np.asarray(res.u[:K], float), np.asarray(res.z_enc[1 : K + 1]), frames
    )


def python_tick(name: str, inp: TickInputs) -> tuple[TickStats, FloatArray]:
    """Per-tick cost of the Python reference estimator ``name``; and its final x."""
    from amsfe_sym.estimation import make_estimator

    est = make_estimator(name, **inp.kwargs)
    return _time_ticks(est.step, inp), est.x.copy()


def _time_ticks(
    step: Callable[[FloatArray, FloatArray | None], object], inp: TickInputs
) -> TickStats:
    """Per-call cost of ``step(u, z)`` over the recorded inputs (``z`` None where missing)."""
    ns = np.empty(len(inp.u))
    for k in range(len(inp.u)):
        z = inp.z[k] if np.isfinite(inp.z[k]).all() else None
        t0 = time.perf_counter_ns()
        step(inp.u[k], z)
        ns[k] = time.perf_counter_ns() - t0
    return TickStats.from_ns(ns)


def write_tick_input(path: Path, name: str, inp: TickInputs, frames: bool = False) -> Path:
    """The input file of ``tick_timer.c`` (format in its header) for estimator ``name``; with
    ``frames``, the recorded camera frames too."""
    from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator

    est = make_compiled_estimator(name, **inp.kwargs)  # its parameter block, as validated
    p = est._params
    hdr = struct.pack(
        "8i",
        p.estimator,
        p.buffer_steps,
        p.camera_iterations,
        p.camera_period,
        p.camera_phase,
        p.camera_max_delay,
        p.max_frames_per_step,
        len(inp.u),
    )
    qw, re, rc, x0, P0 = est._arrays
    body = [np.array([p.gate_camera, p.gate_encoder]), qw, re, rc, x0, np.ravel(P0, order="F")]
    body.append(np.hstack([inp.u, inp.z]).ravel())
    data = hdr + b"".join(np.asarray(a, dtype=np.float64).tobytes() for a in body)
    if frames:
        data += struct.pack("i", len(inp.frames)) + np.asarray(inp.frames, np.float64).tobytes()
    path.write_bytes(data)
    return path


def build_tick_timer(workdir: Path) -> Path:
    """Compile ``tick_timer.c`` (``-O1``) into ``workdir``; the executable's path."""
    from amsfe_sym.apps.bench.timing import compile_program

    exe = workdir / "amsfe_tick_timer"
    return compile_program(_TIMER_SOURCE, exe, ["-ldl", "-lm"], "the C tick timer")


def _run_timer(exe: Path, name: str, inp: TickInputs, workdir: Path, frames: bool) -> list[str]:
    """The lines the C tick timer prints for estimator ``name`` over ``inp`` (the ticks, the
    final x and, with ``frames``, the frames' cost: format in ``c/tick_timer.c``)."""
    kind = "frames" if frames else "tick"
    data = write_tick_input(workdir / f"{kind}-{name}.bin", name, inp, frames=frames)
    proc = run_checked(
        [str(exe), str(inp.lib.library_path), str(data)],
        f"the C tick timer on {name}{' with frames' if frames else ''}",
        "exit code 0",
        "regenerate the library (amsfe generate --force) and retry",
    )
    return proc.stdout.split("\n")


def compiled_tick(
    exe: Path, name: str, inp: TickInputs, workdir: Path
) -> tuple[TickStats, FloatArray]:
    """Per-tick cost of ``amsfe_est_tick`` in pure C; and the final x it printed."""
    first, second = _run_timer(exe, name, inp, workdir, frames=False)[:2]
    med, p99 = (float(v) / 1e3 for v in first.split())
    x = np.array([float(v) for v in second.split()])
    return TickStats(round(med, 4), round(p99, 4), len(inp.u)), x


@dataclass(frozen=True)
class FrameStats(CallCost):
    """Cost of the camera frames of a run in pure C (``amsfe_est_camera_frame``:
    :class:`CallCost` over the frames); ``frames``: frames delivered; ``applied``: frames the
    estimator applied (the others were gated or refused)."""

    frames: int
    applied: int


def compiled_frames(exe: Path, name: str, inp: TickInputs, workdir: Path) -> FrameStats | None:
    """Per-frame cost of ``amsfe_est_camera_frame`` in pure C over the run's frames, each
    delivered after its tick (None when the run has none)."""
    if len(inp.frames) == 0:
        return None
    med, p99, count, applied = _run_timer(exe, name, inp, workdir, frames=True)[2].split()
    us = round(float(med) / 1e3, 2), round(float(p99) / 1e3, 2)
    return FrameStats(us[0], us[1], int(count), int(applied))


class BaselineEkf:
    """An EKF tick as written with Pinocchio + numpy, without this toolkit.

    Semi-implicit Euler on the flexible-joint model (:meth:`PinocchioModel.transition_step`:
    ``pin.computeABADerivatives`` + numpy assembly of x+, A, Gamma; A without the d/dtheta
    column), ``P = A P A^T + Gamma Qw Gamma^T`` (eqs. 13-14), then the encoder update in
    Joseph form (15-17) with ``np.linalg.solve``.

    Args:
        robot: The loaded robot.
        Qw: Process-noise covariance of ``w = [w_l, w_m, w_theta]``.
        R: Encoder noise covariance (2n x 2n).
        x0, P0: Initial state and covariance.
    """

    def __init__(
        self, robot: Any, Qw: FloatArray, R: FloatArray, x0: FloatArray, P0: FloatArray
    ) -> None:
        from amsfe_sym.apps.reference import PinocchioModel

        self.pm = PinocchioModel(robot, Qw)
        n, N = robot.n, robot.N
        self.Qw, self.R = Qw, R
        self.H = np.zeros((2 * n, N))
        self.H[:n, 2 * n : 3 * n] = np.eye(n)
        self.H[n:, 3 * n : 4 * n] = np.eye(n)
        self.I = np.eye(N)
        self.x, self.P = x0.copy(), P0.copy()

    def tick(self, u: FloatArray, z: FloatArray | None) -> None:
        """Predict with ``u``, then update with the encoder sample ``z`` (None: none)."""
        x, A, G = self.pm.transition_step(self.x, u)
        P = A @ self.P @ A.T + G @ self.Qw @ G.T
        P = 0.5 * (P + P.T)
        if z is not None:
            H = self.H
            PHt = P @ H.T
            S = H @ PHt + self.R
            K = np.linalg.solve(S, PHt.T).T
            x = x + K @ (z - H @ x)
            IKH = self.I - K @ H
            P = IKH @ P @ IKH.T + K @ self.R @ K.T
            P = 0.5 * (P + P.T)
        self.x, self.P = x, P


def baseline_tick(robot: Any, inp: TickInputs) -> tuple[TickStats, FloatArray]:
    """Per-tick cost of :class:`BaselineEkf` over the recorded inputs; and its final x."""
    kw = inp.kwargs
    ekf = BaselineEkf(robot, kw["model"].Qw, kw["encoder"].R, kw["x0"], kw["P0"])
    return _time_ticks(ekf.tick, inp), ekf.x.copy()


def bench_tick(
    sc: Any, lib: Any, robot: Any, estimators: tuple[str, ...] = ("oosm",), rounds: int = 5
) -> dict[str, Any]:
    """Section 4: compiled, Python and baseline tick of each estimator, and the law.

    Args:
        sc: The scenario (its run gives the inputs).
        lib: Its library.
        robot: The loaded robot of ``lib`` (the baseline's Pinocchio model), or None.
        estimators: Estimators to time.
        rounds: Rounds of the law's pure C timing.

    Returns:
        ``{"ticks", "law_us", "rows": [{estimator, compiled, python, baseline, ...}]}``.
    """
    from amsfe_sym.apps.bench.calls import _inputs, _state
    from amsfe_sym.apps.bench.timing import CTimer

    inp = record_tick_inputs(sc, lib)
    out: dict[str, Any] = {"ticks": len(inp.u), "rows": []}
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-tick-") as tmp:
        work = Path(tmp)
        exe = build_tick_timer(work)
        law = "control_amsfe"
        if law in lib.manifest.functions:
            x, u = _state(lib, np.random.default_rng(0))
            t, _ = CTimer(work).time(lib.library_path, law, _inputs(lib, law, x, u), rounds)
            out["law_us"] = t.median_us
        base = baseline_tick(robot, inp) if robot is not None else None
        for name in estimators:
            c, xc = compiled_tick(exe, name, inp, work)
            py, xp = python_tick(name, inp)
            row: dict[str, Any] = {
                "estimator": name,
                "compiled": c.__dict__,
                "python": py.__dict__,
                "max_dx_compiled_python": float(np.max(np.abs(xc - xp))),
            }
            frames = compiled_frames(exe, name, inp, work) if name != "encoders" else None
            if frames is not None:
                row["late_frame"] = frames.__dict__
            if "law_us" in out:
                row["compiled_with_law_us"] = round(c.median_us + out["law_us"], 4)
            if base is not None:
                row["baseline"] = base[0].__dict__
                row["speedup_python"] = round(py.median_us / c.median_us, 1)
                row["speedup_baseline"] = round(base[0].median_us / c.median_us, 1)
            out["rows"].append(row)
    return out


def fit_exponent(joints: list[int], values: list[float]) -> float:
    """Least-squares slope of log(value) against log(joints): the growth exponent."""
    xs = [math.log(j) for j in joints]
    ys = [math.log(v) for v in values]
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxx = sum((a - mx) ** 2 for a in xs)
    return sum((a - mx) * (b - my) for a, b in zip(xs, ys, strict=True)) / sxx
