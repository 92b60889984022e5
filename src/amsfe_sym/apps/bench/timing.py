"""Timing primitives of ``amsfe bench``: Python-side call timing and a pure-C timing loop."""

from __future__ import annotations

import statistics
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import CodegenError, describe

__all__ = [
    "ROUND_BUDGET_S",
    "CTimer",
    "Timing",
    "compile_program",
    "round4",
    "run_checked",
    "time_calls",
]

#: The fix when a timing program fails on a library.
_REGENERATE = "regenerate the library (amsfe generate --force) and retry"

FloatArray = NDArray[np.float64]

#: Wall time one timing round aims for [s] (``--repeat`` caps the calls per round).
ROUND_BUDGET_S = 0.05


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


def run_checked(
    cmd: Sequence[str], what: str, expected: str, fix: str, cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``cmd`` (text output captured); a non-zero exit raises :class:`CodegenError`
    naming ``what``, the ``expected`` outcome, the tail of stderr and the ``fix``."""
    proc = subprocess.run(list(cmd), cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise CodegenError(describe(what, expected, proc.stderr.strip()[-2000:], fix))
    return proc


def compile_program(source: Path, exe: Path, libs: Sequence[str], what: str) -> Path:
    """Compile the C program ``source`` (``-O1``) into ``exe`` with ``libs`` (e.g. ``-ldl``).

    Raises:
        CodegenError: the compiler failed (its message says why).
    """
    from amsfe_sym.codegen import compiler

    cmd = [compiler(), "-O1", "-o", str(exe), str(source), *libs]
    run_checked(cmd, f"compiling {what}", "a successful build", "install a C compiler or set $CC")
    return exe


class CTimer:
    """The pure-C timing loop, compiled once (``-O1``) into a temporary folder.

    Args:
        workdir: Folder for the executable.
    """

    def __init__(self, workdir: Path) -> None:
        src = workdir / "amsfe_timer.c"
        src.write_text(_C_TIMER)
        self.exe = compile_program(src, workdir / "amsfe_timer", ["-ldl"], "the C timing loop")

    def time(
        self,
        library: Path,
        function: str,
        inputs: Sequence[FloatArray],
        rounds: int,
        min_calls: int = 1000,
    ) -> tuple[Timing, float]:
        """Per-call time of ``function`` in ``library`` and the sum of its outputs.

        A ``min_calls``-call pilot sizes the rounds to about :data:`ROUND_BUDGET_S` each
        (at least ``min_calls`` calls; lower it for functions of milliseconds).
        """
        values = [repr(float(v)) for a in inputs for v in np.ravel(a, order="F")]
        per_call, checksum = self._run(library, function, min_calls, 1, values)
        budget = ROUND_BUDGET_S / max(per_call[0] * 1e-6, 1e-9)
        calls = int(max(min_calls, min(10**8, budget)))
        per_call, checksum = self._run(library, function, calls, rounds, values)
        return Timing.from_rounds(per_call, calls), checksum

    def _run(
        self, library: Path, function: str, calls: int, rounds: int, values: list[str]
    ) -> tuple[list[float], float]:
        cmd = [str(self.exe), str(library), function, str(calls), str(rounds), *values]
        proc = run_checked(cmd, f"C timing of {function}", "exit code 0", _REGENERATE)
        lines = proc.stdout.split("\n")
        return [float(v) / 1000.0 for v in lines[0].split()], float(lines[1])


def round4(v: float) -> float:
    """``v`` rounded to 4 decimals (the reports' precision)."""
    return round(float(v), 4)
