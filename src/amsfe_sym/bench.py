"""``amsfe bench``: what generation, one model call and one estimator tick cost.

Three sections, side by side (docs/performance.md shows the numbers and explains them):

1. **generation**: a cold ``generate(force=True)`` into a temporary folder and a cached
   second call, each in a fresh Python process as a user runs ``amsfe generate`` twice;
2. **per-call cost** of the functions a tick uses, by every route we have:
   :meth:`CompiledFunction.call_into` (the ctypes binding), pure C (a small C timing loop
   that ``dlopen`` s the same library: no Python at all), ``casadi.external`` called with
   numpy arrays, the CasADi SX Function on its virtual machine, and numeric Pinocchio +
   numpy equivalents; the binding's *overhead* is its time minus the pure C time;
3. **estimator ticks**: the closed-loop simulation (:func:`amsfe_sym.simulate.run`) with each
   of the five estimators, as wall time per tick and real-time factor.

Optionally (``--compare-cflags``) the robot's generated C is recompiled with several flag
sets to show the compile-time / call-time trade-off behind the ``-O1`` default.

Timings use :func:`time.perf_counter` over many calls after a warm-up; each figure is the
median of ``--rounds`` rounds (the minimum is in the JSON).  The machine is assumed noisy:
compare medians, never single runs, and no figure here is asserted by a test.
"""

from __future__ import annotations

import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import CodegenError, ConfigError, describe

__all__ = [
    "CALL_FUNCTIONS",
    "DEFAULT_CFLAG_SETS",
    "ESTIMATOR_NAMES",
    "TICK_FUNCTIONS",
    "CTimer",
    "Timing",
    "bench_calls",
    "bench_cflags",
    "bench_estimators",
    "bench_generation",
    "run_bench",
    "tick_compiled_us",
    "time_calls",
]

FloatArray = NDArray[np.float64]

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
ESTIMATOR_NAMES: tuple[str, ...] = ("encoders", "naive", "oosm", "replay", "cloning")
#: Flag sets of ``--compare-cflags`` when none are given.
DEFAULT_CFLAG_SETS: tuple[str, ...] = ("-O0", "-O1", "-O2", "-O3", "-Os", "-O1 -march=native")
#: Targets of the issue: cold generation (2-link, 6/7-DOF arm), cached generation [s],
#: and the binding's per-call overhead [us].
TARGETS = {"cold_2link_s": 2.0, "cold_arm_s": 20.0, "cached_s": 1.0, "overhead_us": 3.0}
#: Wall time one timing round aims for [s] (``--repeat`` caps the calls per round).
ROUND_BUDGET_S = 0.05


# ======================================================================================
# timing primitives


@dataclass(frozen=True)
class Timing:
    """Per-call time of one function by one route.

    Attributes:
        median_us: Median over rounds of the mean per-call time [us].
        min_us: Fastest round [us].
        calls: Calls per round.
        rounds: Rounds.
    """

    median_us: float
    min_us: float
    calls: int
    rounds: int

    @classmethod
    def from_rounds(cls, per_call_us: Sequence[float], calls: int) -> Timing:
        return cls(
            round(statistics.median(per_call_us), 4),
            round(min(per_call_us), 4),
            calls,
            len(per_call_us),
        )


def time_calls(
    fn: Callable[..., Any],
    args: Sequence[Any],
    repeat: int,
    rounds: int,
    budget_s: float = ROUND_BUDGET_S,
) -> Timing:
    """Time ``fn(*args)``: warm up, then ``rounds`` rounds of up to ``repeat`` calls.

    A short pilot sizes the rounds so that each lasts about ``budget_s`` (a 40 us call is
    not called 20000 times per round); ``repeat`` is the upper bound.
    """
    for _ in range(3):
        fn(*args)
    t0 = time.perf_counter()
    for _ in range(10):
        fn(*args)
    pilot = max((time.perf_counter() - t0) / 10, 1e-8)
    calls = int(max(10, min(repeat, budget_s / pilot)))
    for _ in range(max(3, calls // 10)):
        fn(*args)
    per_call = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn(*args)
        per_call.append(1e6 * (time.perf_counter() - t0) / calls)
    return Timing.from_rounds(per_call, calls)


#: A C program that times one generated function without Python: it ``dlopen`` s the
#: library, reads the function's sizes from its ``*_work`` / ``*_sparsity_in`` entry points,
#: fills the inputs from the command line and calls the entry point in a tight loop.
_C_TIMER = r"""
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

typedef long long casadi_int;
typedef int (*fn_t)(const double **, double **, casadi_int *, double *, int);
typedef int (*work_t)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);
typedef casadi_int (*count_t)(void);
typedef const casadi_int *(*sp_t)(casadi_int);

static void *sym(void *h, const char *fn, const char *suffix) {
  char name[512];
  snprintf(name, sizeof name, "%s%s", fn, suffix);
  void *p = dlsym(h, name);
  if (!p) { fprintf(stderr, "missing symbol %s\n", name); exit(2); }
  return p;
}
/* non-zeros of a CasADi sparsity [nrow, ncol, colind..., row...]; dense = [nrow, ncol, 1] */
static casadi_int nnz(const casadi_int *sp) {
  return sp[2] == 1 ? sp[0] * sp[1] : sp[2 + sp[1]];
}
static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}
/* usage: timer LIB FUNCTION CALLS ROUNDS VALUES... (every input's values, column-major)
 * prints the per-call time of each round [ns] on one line, then the sum of all outputs */
int main(int argc, char **argv) {
  if (argc < 5) {
    fprintf(stderr, "usage: %s LIB FUNCTION CALLS ROUNDS VALUES...\n", argv[0]);
    return 2;
  }
  void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!h) { fprintf(stderr, "%s\n", dlerror()); return 2; }
  const char *fn = argv[2];
  long calls = atol(argv[3]), rounds = atol(argv[4]);
  fn_t f = (fn_t)sym(h, fn, "");
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  ((work_t)sym(h, fn, "_work"))(&sz_arg, &sz_res, &sz_iw, &sz_w);
  casadi_int n_in = ((count_t)sym(h, fn, "_n_in"))(), n_out = ((count_t)sym(h, fn, "_n_out"))();
  sp_t sp_in = (sp_t)sym(h, fn, "_sparsity_in"), sp_out = (sp_t)sym(h, fn, "_sparsity_out");
  const double **arg = calloc(sz_arg + 1, sizeof *arg);
  double **res = calloc(sz_res + 1, sizeof *res);
  casadi_int *iw = calloc(sz_iw + 1, sizeof *iw);
  double *w = calloc(sz_w + 1, sizeof *w);
  int k = 5;
  for (casadi_int i = 0; i < n_in; ++i) {
    casadi_int m = nnz(sp_in(i));
    double *v = calloc(m + 1, sizeof *v);
    for (casadi_int j = 0; j < m; ++j) {
      if (k >= argc) { fprintf(stderr, "too few input values\n"); return 2; }
      v[j] = strtod(argv[k++], NULL);
    }
    arg[i] = v;
  }
  if (k != argc) { fprintf(stderr, "too many input values\n"); return 2; }
  for (casadi_int i = 0; i < n_out; ++i) res[i] = calloc(nnz(sp_out(i)) + 1, sizeof(double));
  for (long c = 0; c < calls / 10 + 1; ++c) f(arg, res, iw, w, 0); /* warm up */
  for (long r = 0; r < rounds; ++r) {
    double t0 = now();
    for (long c = 0; c < calls; ++c)
      if (f(arg, res, iw, w, 0)) { fprintf(stderr, "error code\n"); return 1; }
    printf("%.3f ", 1e9 * (now() - t0) / calls);
  }
  double sum = 0;
  for (casadi_int i = 0; i < n_out; ++i)
    for (casadi_int j = 0; j < nnz(sp_out(i)); ++j) sum += res[i][j];
  printf("\n%.17g\n", sum);
  return 0;
}
"""


class CTimer:
    """The pure-C timing loop, compiled once (``-O1``) into a temporary folder.

    Args:
        workdir: Folder for the executable.
    """

    def __init__(self, workdir: Path) -> None:
        from amsfe_sym.codegen import compiler

        src = workdir / "amsfe_timer.c"
        src.write_text(_C_TIMER)
        self.exe = workdir / "amsfe_timer"
        cmd = [compiler(), "-O1", "-o", str(self.exe), str(src), "-ldl"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise CodegenError(
                describe(
                    "compiling the C timing loop",
                    "a successful build",
                    proc.stderr[-1000:],
                    "install a C compiler or set $CC",
                )
            )

    def time(
        self, library: Path, function: str, inputs: Sequence[FloatArray], rounds: int
    ) -> tuple[Timing, float]:
        """Per-call time of ``function`` in ``library`` and the sum of its outputs.

        A 1000-call pilot sizes the rounds to about :data:`ROUND_BUDGET_S` each.
        """
        values = [repr(float(v)) for a in inputs for v in np.ravel(a, order="F")]
        per_call, checksum = self._run(library, function, 1000, 1, values)
        calls = int(max(1000, min(10**8, ROUND_BUDGET_S / max(per_call[0] * 1e-6, 1e-9))))
        per_call, checksum = self._run(library, function, calls, rounds, values)
        return Timing.from_rounds(per_call, calls), checksum

    def _run(
        self, library: Path, function: str, calls: int, rounds: int, values: list[str]
    ) -> tuple[list[float], float]:
        cmd = [str(self.exe), str(library), function, str(calls), str(rounds), *values]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise CodegenError(
                describe(
                    f"C timing of {function}",
                    "exit code 0",
                    proc.stderr.strip(),
                    "regenerate the library (amsfe generate --force) and retry",
                )
            )
        lines = proc.stdout.split("\n")
        return [float(v) / 1000.0 for v in lines[0].split()], float(lines[1])


# ======================================================================================
# 1. generation

_GEN_SCRIPT = """
import json, sys, time
t0 = time.perf_counter()
from amsfe_sym.codegen import generate
t1 = time.perf_counter()
r = generate(sys.argv[1], out=sys.argv[2], force=sys.argv[3] == "1")
print(json.dumps({"import_s": t1 - t0, "seconds": r.seconds, "reused": r.reused,
                  "timings": r.timings, "out_dir": str(r.out_dir)}))
"""


def _generate_in_subprocess(robot: str, out: Path, force: bool) -> dict[str, Any]:
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _GEN_SCRIPT, robot, str(out), "1" if force else "0"],
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise CodegenError(
            describe(f"generate({robot!r})", "success", proc.stderr.strip()[-2000:], "see above")
        )
    res: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    res["process_wall_s"] = wall
    return {k: (_round(v) if isinstance(v, float) else v) for k, v in res.items()}


def bench_generation(robot: str) -> dict[str, Any]:
    """Cold (``force=True``) and cached ``generate`` of ``robot`` into a temporary folder.

    Each call runs in a fresh Python process, as ``amsfe generate`` does, so "cached"
    includes nothing the first call left in memory.  ``seconds`` is the time inside
    :func:`~amsfe_sym.codegen.generate`, ``process_wall_s`` adds interpreter start-up and
    imports.
    """
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-gen-") as tmp:
        cold = _generate_in_subprocess(robot, Path(tmp), force=True)
        cached = _generate_in_subprocess(robot, Path(tmp), force=False)
        src = Path(cold["out_dir"])
        lines = (src / f"{src.name}.c").read_text().count("\n") if src.is_dir() else 0
    cold["timings"] = {k: _round(v) for k, v in cold["timings"].items()}
    return {"cold": cold, "cached": cached, "c_lines": lines}


# ======================================================================================
# 2. per-call cost


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
    for io in lib.manifest["functions"][name]["inputs"]:
        rows, cols = io["shape"]
        a = by_name.get(io["name"], np.linspace(-0.1, 0.1, rows * cols))
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


class PinocchioModel:
    """Numeric Pinocchio + numpy equivalents of the generated functions (for comparison).

    The transition is a semi-implicit Euler step (the ``semi_implicit`` integrator) built on
    ``pin.computeABADerivatives``, which returns qdd = ABA(q, qd, tau), its derivatives and
    M^-1 in one pass; x+, A = dF/dx (without the d/dtheta column) and Gamma are assembled in
    numpy.  It is what a hand-written numeric EKF model would do, and it satisfies the
    estimator's ``TransitionModel`` protocol, so :func:`amsfe_sym.estimation.ekf.predict`
    can run on it.

    Args:
        robot: The loaded robot (:func:`amsfe_sym.load.load_robot`).
        Qw: Process-noise covariance of w = [w_l, w_m, w_theta].
    """

    def __init__(self, robot: Any, Qw: FloatArray) -> None:
        import pinocchio as pin

        self.pin = pin
        self.robot = robot
        self.n, self.p, self.N = robot.n, robot.p, robot.N
        self.T = float(robot.spec.model.T)
        self.model = robot.pin_model_at(robot.theta_true)
        self.data = self.model.createData()
        self.Ks = robot.stiffness_at(robot.theta_true)
        self.Mm, self.Fm = robot.Mm, robot.Fm
        self.Qw = Qw
        self.identity_q = self.model.nq == self.n
        self.frame = robot.tracked_frame_id
        self.offset = robot.tracked_offset
        cam = robot.camera
        self.R_cw, self.c, self.K = cam.R_cw, cam.position, cam.K
        self._A = np.zeros((self.N, self.N))
        self._G = np.zeros((self.N, 2 * self.n + self.p))

    def q_pin(self, q: FloatArray) -> FloatArray:
        return q if self.identity_q else np.asarray(self.robot.to_pin_q(q))

    def mass_matrix(self, q: FloatArray) -> FloatArray:
        return np.asarray(self.pin.crba(self.model, self.data, self.q_pin(q)))

    def transition_step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, ...]:
        """x+, A, Gamma of one semi-implicit Euler step (eqs. 1, 3, 4 in that form)."""
        n, T, Ks, Mm, Fm = self.n, self.T, self.Ks, self.Mm, self.Fm
        q, qd, qm, qmd = x[:n], x[n : 2 * n], x[2 * n : 3 * n], x[3 * n : 4 * n]
        delta = qm - q
        dq_dq, dq_dv, Minv = self.pin.computeABADerivatives(
            self.model, self.data, self.q_pin(q), qd, Ks * delta
        )
        qdd = self.data.ddq
        qmdd = (u - Fm * qmd - Ks * delta) / Mm
        qd1 = qd + T * qdd
        qmd1 = qmd + T * qmdd
        xn = np.concatenate([q + T * qd1, qd1, qm + T * qmd1, qmd1, x[4 * n :]])
        MK = Minv * Ks  # d qdd / d qm (columns scaled by Ks)
        dqd_dq = T * (dq_dq - MK)
        dqd_dqd = np.eye(n) + T * dq_dv
        dqd_dqm = T * MK
        A, G = self._A, self._G
        A[:] = 0.0
        s = slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n), slice(3 * n, 4 * n)
        A[s[1], s[0]], A[s[1], s[1]], A[s[1], s[2]] = dqd_dq, dqd_dqd, dqd_dqm
        A[s[0], s[0]] = np.eye(n) + T * dqd_dq
        A[s[0], s[1]], A[s[0], s[2]] = T * dqd_dqd, T * dqd_dqm
        A[s[3], s[0]] = np.diag(T * Ks / Mm)
        A[s[3], s[2]] = np.diag(-T * Ks / Mm)
        A[s[3], s[3]] = np.diag(1.0 - T * Fm / Mm)
        A[s[2]] = T * A[s[3]]
        A[s[2], s[2]] += np.eye(n)
        A[4 * n :, 4 * n :] = np.eye(self.p)
        G[s[1], :n] = Minv
        G[s[0], :n] = T * Minv
        G[s[3], n : 2 * n] = np.diag(1.0 / Mm)
        G[s[2], n : 2 * n] = np.diag(T / Mm)
        G[4 * n :, 2 * n :] = T * np.eye(self.p)
        return xn, A.copy(), G.copy()

    # the TransitionModel protocol (for ekf.predict)
    @property
    def nx(self) -> int:
        return self.N

    def step(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        xn, A, self._last_G = self.transition_step(x, u)
        return xn, A

    def inverse(self, x_next: FloatArray, u: FloatArray) -> FloatArray:
        raise NotImplementedError("the Pinocchio comparison model has no inverse transition")

    def process_noise(self, x: FloatArray, u: FloatArray) -> FloatArray:
        G = self._last_G
        Q: FloatArray = G @ self.Qw @ G.T
        return Q

    def camera_measure(self, q: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """Pixels y, dy/dq and depth of the tracked point (eqs. 6-8) from Pinocchio's frame
        jacobian and a numpy pinhole."""
        pin = self.pin
        J = pin.computeFrameJacobian(
            self.model, self.data, self.q_pin(q), self.frame, pin.LOCAL_WORLD_ALIGNED
        )
        oMf = self.data.oMf[self.frame]
        lever = oMf.rotation @ self.offset
        r = oMf.translation + lever
        Jr = J[:3] - _skew(lever) @ J[3:]
        pc = self.R_cw @ (r - self.c)
        fx, fy = self.K[0, 0], self.K[1, 1]
        y = np.array([fx * pc[0] / pc[2] + self.K[0, 2], fy * pc[1] / pc[2] + self.K[1, 2]])
        dy_dpc = np.array(
            [
                [fx / pc[2], 0.0, -fx * pc[0] / pc[2] ** 2],
                [0.0, fy / pc[2], -fy * pc[1] / pc[2] ** 2],
            ]
        )
        return y, dy_dpc @ self.R_cw @ Jr, float(pc[2])

    def plant_step(
        self, xp: FloatArray, u: FloatArray, tau_d: FloatArray, substeps: int
    ) -> FloatArray:
        """``substeps`` RK4 steps over T of the continuous plant on ``pin.aba``."""
        n, h = self.n, self.T / substeps
        Ks, Mm, Fm = self.Ks, self.Mm, self.Fm
        pin, model, data = self.pin, self.model, self.data

        def rhs(z: FloatArray) -> FloatArray:
            q, qd, qm, qmd = z[:n], z[n : 2 * n], z[2 * n : 3 * n], z[3 * n :]
            d = Ks * (qm - q)
            qdd = pin.aba(model, data, self.q_pin(q), qd, d + tau_d[:n])
            return np.concatenate([qd, qdd, qmd, (u + tau_d[n:] - Fm * qmd - d) / Mm])

        z = xp
        for _ in range(substeps):
            k1 = rhs(z)
            k2 = rhs(z + 0.5 * h * k1)
            k3 = rhs(z + 0.5 * h * k2)
            k4 = rhs(z + h * k3)
            z = z + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return z


def _skew(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


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
    pm: PinocchioModel,
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
        if lib.manifest["integrator"] == "semi_implicit":
            xn, A, G = pm.transition_step(*args)
            cols = slice(0, 4 * n)  # Pinocchio's A has no d/dtheta column
            row.max_diff_pinocchio = _max_diff(
                [xn, A[:, cols], G], [ref[0], ref[1][:, cols], ref[2]]
            )
        else:
            integrator = lib.manifest["integrator"]
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
        if not lib.manifest.get("camera_depends_on_theta"):
            row.max_diff_pinocchio = _max_diff([y, J, np.array([d])], ref)
    elif name == "plant_step":
        substeps = int(lib.manifest["plant_substeps"])
        pargs = (args[0], args[1], args[3], substeps)
        row.pinocchio = time_calls(pm.plant_step, pargs, repeat, rounds)
        row.pinocchio_what = f"numpy RK4 on pin.aba ({4 * substeps} calls)"
        q, qd = args[0][:n], args[0][n : 2 * n]
        core_args = (pm.model, pm.data, pm.q_pin(q), qd, np.zeros(n))
        row.pinocchio_core = time_calls(pm.pin.aba, core_args, repeat, rounds)
        row.pinocchio_core_what = "one pin.aba"
        row.max_diff_pinocchio = _max_diff([pm.plant_step(*pargs)], ref)


# ======================================================================================
# 3. estimator ticks


def timing_scenario(lib: Any, duration: float, scenario: str | None = None) -> Any:
    """The scenario the estimator section runs for the robot of ``lib``.

    ``scenario`` if given; ``paper-sim`` for ``paper_2link``; for any other robot,
    ``paper-sim``'s settings on that robot (its own integrator and camera timing) tracking a
    small sinusoid (0.2 rad, 0.5 Hz) about q = 0.3 rad per joint, the estimate starting
    0.05 rad off with theta at its true value.  The latter is a timing set-up only, not an
    estimation study: with theta starting at its spec's initial value (payload 0 kg for the
    UR5, true 2 kg) every estimator on the UR5 became overconfident and failed within 1.4 s
    under paper-sim's noise settings (docs/performance.md).
    """
    from amsfe_sym.scenario import load_scenario

    if scenario is not None:
        return load_scenario(scenario).with_overrides(duration=duration)
    base = load_scenario("paper-sim").with_overrides(duration=duration)
    if lib.name == base.robot:
        return base
    n = lib.n
    q0 = tuple(0.3 for _ in range(n))
    latency = int(lib.manifest["camera"]["delay"])
    return replace(
        base,
        name=f"bench-{lib.name}",
        robot=str(lib.manifest.get("spec") or lib.manifest["urdf"]),
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
        filter=replace(base.filter, buffer_steps=max(base.filter.buffer_steps, latency + 10)),
    )


def bench_estimators(
    sc: Any, estimators: Sequence[str] = ESTIMATOR_NAMES, lib: Any = None
) -> list[dict[str, Any]]:
    """Run ``sc`` once per estimator and report cost per tick and real-time factor.

    A run that fails (e.g. an estimator refusing an indefinite covariance) is reported with
    its error instead of timings, and the other estimators still run.
    """
    from amsfe_sym.errors import AmsfeError
    from amsfe_sym.simulate import library_for, run, summarize

    if lib is None:
        lib = library_for(sc)
    rows: list[dict[str, Any]] = []
    for est in estimators:
        try:
            res = run(sc.with_overrides(estimator=est), lib=lib)
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


#: Compiled functions every tick of :func:`amsfe_sym.simulate.run` calls once (the plant,
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


# ======================================================================================
# compiler flags


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

    src = lib.dir / lib.manifest["source"]
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
                lib.manifest["library"],
                str(src),
                "-lm",
            ]
            times = []
            for _ in range(compile_repeat):
                t0 = time.perf_counter()
                proc = subprocess.run(cmd, cwd=d, capture_output=True, text=True)
                times.append(time.perf_counter() - t0)
                if proc.returncode != 0:
                    raise CodegenError(
                        describe(
                            f"compiling with {flags!r}",
                            "success",
                            proc.stderr[-1000:],
                            "drop or correct the flag set the compiler refused",
                        )
                    )
            # this build is ours: record its own hash, as generate does
            built = file_sha256(d / lib.manifest["library"])
            manifest = {**lib.manifest, "library_sha256": built}
            (d / "manifest.json").write_text(json.dumps(manifest))
            blib = ModelLibrary(d)
            f = blib.function(function)
            t_py = time_calls(f.call_into, args, repeat, rounds)
            t_c, _ = ctimer.time(blib.library_path, function, args, rounds)
            out.append(
                {
                    "cflags": flags,
                    "compile_s": _round(min(times)),
                    "compile_s_all": [_round(t) for t in times],
                    "library_kb": round((d / lib.manifest["library"]).stat().st_size / 1024, 1),
                    "ctypes_us": t_py.median_us,
                    "pure_c_us": t_c.median_us,
                }
            )
    return out


# ======================================================================================
# report


def _round(v: float) -> float:
    return round(float(v), 4)


def _fmt(v: float | None, width: int = 9, digits: int = 2) -> str:
    return f"{'-':>{width}}" if v is None else f"{v:>{width}.{digits}f}"


def machine_info() -> dict[str, Any]:
    """CPU, cores, load and versions, for the report."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from amsfe_sym.codegen import cflags, compiler

    def version(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "missing"

    return {
        "commit": _git_commit(),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average": [round(v, 2) for v in os.getloadavg()],
        "python": platform.python_version(),
        "numpy": np.__version__,
        "casadi": version("casadi"),
        "pinocchio": version("pin"),
        "compiler": compiler(),
        "cflags": " ".join(cflags()),
    }


def _git_commit() -> str:
    """Short commit of the source tree (``+dirty`` with local changes), or ``unknown``."""
    here = Path(__file__).resolve().parent
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True
        )
        if rev.returncode != 0:
            return "unknown"
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "."],
            cwd=here,
            capture_output=True,
            text=True,
        )
        return rev.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except OSError:
        return "unknown"


def format_report(report: dict[str, Any]) -> str:
    """The human-readable tables of a :func:`run_bench` report."""
    m = report["machine"]
    lines = [
        f"amsfe bench {report['robot']}: n = {report['n']}, p = {report['p']}, "
        f"N = {report['N']}; {m['cpu']}, {m['cores']} cores, load {m['load_average'][0]}",
        f"  commit {m['commit']}; casadi {m['casadi']}, pin {m['pinocchio']}, "
        f"numpy {m['numpy']}, {m['compiler']} {m['cflags']}; medians of {report['rounds']} rounds",
    ]
    gen = report.get("generation")
    if gen:
        c, k = gen["cold"], gen["cached"]
        arm = report["n"] > 2
        target = TARGETS["cold_arm_s"] if arm else TARGETS["cold_2link_s"]
        st = ", ".join(f"{s} {v:.2f}" for s, v in c["timings"].items())
        lines += [
            "",
            f"1. generation [s] ({gen['c_lines']} lines of C)"
            "   in generate()   process wall   target",
            f"   cold (force, new process)      {c['seconds']:>12.2f} {c['process_wall_s']:>14.2f}"
            f"   < {target:g}   ({st})",
            f"   cached (second, new process)   {k['seconds']:>12.3f} {k['process_wall_s']:>14.2f}"
            f"   < {TARGETS['cached_s']:g}   (reused = {k['reused']})",
        ]
    calls = report.get("calls")
    if calls:
        lines += [
            "",
            "2. per-call cost [us]   pure C = C loop over the same library;"
            " overhead = binding - pure C",
            f"   {'function':<19}{'pure C':>9}{'binding':>9}{'overhead':>9}{'external':>9}"
            f"{'SX VM':>9}{'Pinocchio':>10}  max|diff| vs binding (ext / VM / pin)",
        ]
        for r in calls:
            diffs = " / ".join(
                "-" if v is None else f"{v:.0e}"
                for v in (r["max_diff_external"], r["max_diff_sx_vm"], r["max_diff_pinocchio"])
            )
            lines.append(
                f"   {r['function']:<19}{_tget(r, 'pure_c')}{_tget(r, 'ctypes')}"
                f"{_fmt(r['overhead_us'])}{_tget(r, 'external')}{_tget(r, 'sx_vm')}"
                f"{_tget(r, 'pinocchio', 10)}  {diffs}"
            )
        lines.append("   Pinocchio column:")
        for r in calls:
            if r["pinocchio_what"]:
                core = r["pinocchio_core"]
                extra = f"; {r['pinocchio_core_what']}: {core['median_us']:.2f} us" if core else ""
                lines.append(f"     {r['function']}: {r['pinocchio_what']}{extra}")
        for r in calls:
            lines += [f"   note ({r['function']}): {note}" for note in r["notes"]]
        over = [r["overhead_us"] for r in calls if r["overhead_us"] is not None]
        over_min = [r["overhead_min_us"] for r in calls if r["overhead_min_us"] is not None]
        if over:
            lines.append(
                f"   binding overhead: {min(over):.2f} .. {max(over):.2f} us per call from "
                f"medians, {min(over_min):.2f} .. {max(over_min):.2f} from minima "
                f"(target < {TARGETS['overhead_us']:g} us)"
            )
    est = report.get("estimators")
    if est:
        sc = report["scenario"]
        lines += [
            "",
            f"3. estimator tick: scenario {sc['name']} (library {sc['robot']}, "
            f"{sc['integrator']}), {sc['duration']:g} s "
            f"simulated, seed {sc['seed']} (plant + sensors + estimator + controller + records)",
            f"   {'estimator':<10}{'ticks':>7}{'us/tick':>10}{'wall [s]':>10}{'x real time':>13}",
        ]
        for r in est:
            if "error" in r:
                lines.append(f"   {r['estimator']:<10} failed: {r['error'][:160]}")
                continue
            lines.append(
                f"   {r['estimator']:<10}{r['ticks']:>7}{r['cost_per_tick_us']:>10.1f}"
                f"{r['wall_time_s']:>10.3f}{r['real_time_factor']:>13.1f}"
            )
        tick = report.get("tick_compiled_us")
        if tick:
            parts = " + ".join(f"{k} {v:.2f}" for k, v in tick.items() if k != "total")
            lines.append(
                f"   compiled maths per tick, pure C ({sc['robot']}): {parts} = "
                f"{tick['total']:.2f} us"
            )
    flags = report.get("cflags")
    if flags:
        lines += [
            "",
            f"compiler flags: {report['robot']}.c rebuilt per flag set; transition_step timed",
            f"   {'flags':<22}{'compile [s]':>12}{'.so [kB]':>10}{'binding [us]':>14}"
            f"{'pure C [us]':>13}",
        ]
        for r in flags:
            lines.append(
                f"   {r['cflags']:<22}{r['compile_s']:>12.2f}{r['library_kb']:>10.0f}"
                f"{r['ctypes_us']:>14.2f}{r['pure_c_us']:>13.3f}"
            )
    return "\n".join(lines)


def _tget(row: dict[str, Any], key: str, width: int = 9) -> str:
    t = row.get(key)
    return _fmt(None if t is None else t["median_us"], width)


def run_bench(args: Any) -> int:
    """``amsfe bench`` (see :mod:`amsfe_sym.cli`): print the tables, optionally write JSON."""
    from amsfe_sym.codegen import generate
    from amsfe_sym.load import load_robot
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.simulate import library_for

    robot_name = str(args.robot)
    repeat = int(args.repeat)
    rounds = int(getattr(args, "rounds", 5) or 5)
    skip = set(getattr(args, "skip", None) or ())
    if repeat < 1 or rounds < 1:
        raise ConfigError(
            describe(
                "--repeat / --rounds",
                "positive integers",
                f"{repeat} / {rounds}",
                "pass e.g. --repeat 20000 --rounds 5",
            )
        )
    res = generate(robot_name, out=getattr(args, "out", None))
    lib = ModelLibrary(res.out_dir)
    report: dict[str, Any] = {
        "robot": lib.name,
        "n": lib.n,
        "p": lib.p,
        "N": lib.N,
        "repeat": repeat,
        "rounds": rounds,
        "machine": machine_info(),
        "library": str(lib.library_path),
    }
    if "generation" not in skip:
        report["generation"] = bench_generation(robot_name)
    if "calls" not in skip:
        robot = load_robot(robot_name)
        report["calls"] = [_row_dict(r) for r in bench_calls(lib, robot, repeat, rounds)]
    if "estimators" not in skip:
        sc = timing_scenario(
            lib, float(getattr(args, "duration", 2.0)), getattr(args, "scenario", None)
        )
        names = getattr(args, "estimators", None) or ESTIMATOR_NAMES
        sc_lib = library_for(sc)
        report["scenario"] = {
            "name": sc.name,
            "robot": sc_lib.name,
            "integrator": sc_lib.manifest["integrator"],
            "duration": sc.duration,
            "seed": sc.seed,
        }
        report["estimators"] = bench_estimators(sc, names, lib=sc_lib)
        report["tick_compiled_us"] = tick_compiled_us(sc_lib, rounds)
    sets_arg = getattr(args, "compare_cflags", None)
    if sets_arg is not None:
        flag_sets = [f.strip() for f in str(sets_arg).split(",") if f.strip()]
        report["cflags"] = bench_cflags(
            lib,
            flag_sets or DEFAULT_CFLAG_SETS,
            repeat,
            rounds,
            compile_repeat=int(getattr(args, "compile_repeat", 1) or 1),
        )
    print(format_report(report))
    json_path = getattr(args, "json", None)
    if json_path:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {json_path}")
    return 0


def _row_dict(row: CallRow) -> dict[str, Any]:
    return asdict(row)
