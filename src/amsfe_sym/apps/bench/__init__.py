"""``amsfe bench``: what generation, one model call and one estimator tick cost.

Three main sections, side by side (docs/explanation/performance.md shows the numbers and explains
them):

1. **generation**: a cold ``generate(force=True)`` into a temporary folder and a cached
   second call, each in a fresh Python process as a user runs ``amsfe generate`` twice;
2. **per-call cost** of the functions a tick uses, by every route we have:
   :meth:`CompiledFunction.call_into` (the ctypes binding), pure C (a small C timing loop
   that ``dlopen`` s the same library: no Python at all), ``casadi.external`` called with
   numpy arrays, the CasADi SX Function on its virtual machine, and numeric Pinocchio +
   numpy equivalents; the binding's *overhead* is its time minus the pure C time;
3. **estimator ticks**: the closed-loop simulation (:func:`amsfe_sym.sim.loop.run`) with each
   registered estimator, as wall time per tick and real-time factor;

and further sections (``--skip`` leaves any out): one tick three ways, the closed loop,
scaling with joints, ``amsfe estimate`` over recorded logs in fresh processes
(``logs``, :mod:`amsfe_sym.apps.bench.logs`; docs/how-to/logs.md, "The command, end to end"),
and the camera chain's decoding + detection per frame (``vision``,
:mod:`amsfe_sym.apps.bench.vision`; docs/camera.md, "Speed").

Optionally (``--compare-cflags``) the robot's generated C is recompiled with several flag
sets to show the compile-time / call-time trade-off behind the ``-O1`` default.

Timings use :func:`time.perf_counter` over many calls after a warm-up; each figure is the
median of ``--rounds`` rounds (the minimum is in the JSON).  The machine is assumed noisy:
compare medians, never single runs, and no figure here is asserted by a test.

Modules: ``timing`` (primitives), ``generation``, ``calls`` (per-call cost, tick maths,
compiler flags), ``ticks`` (estimators), ``report`` (options, run, tables).  The Pinocchio
comparison model is :class:`amsfe_sym.apps.reference.PinocchioModel`.

May import every room before apps (and apps.reference), never the command line.
"""

from amsfe_sym.apps.bench.calls import (
    CALL_FUNCTIONS,
    TICK_FUNCTIONS,
    CallRow,
    _inputs,
    _state,
    bench_calls,
    bench_cflags,
    tick_compiled_us,
)
from amsfe_sym.apps.bench.generation import bench_generation
from amsfe_sym.apps.bench.report import (
    DEFAULT_CFLAG_SETS,
    TARGETS,
    BenchOptions,
    format_report,
    run_bench,
)
from amsfe_sym.apps.bench.ticks import ESTIMATOR_NAMES, bench_estimators, timing_scenario
from amsfe_sym.apps.bench.timing import CTimer, Timing, time_calls

__all__ = [
    "CALL_FUNCTIONS",
    "DEFAULT_CFLAG_SETS",
    "ESTIMATOR_NAMES",
    "TARGETS",
    "TICK_FUNCTIONS",
    "BenchOptions",
    "CTimer",
    "CallRow",
    "Timing",
    "_inputs",
    "_state",
    "bench_calls",
    "bench_cflags",
    "bench_estimators",
    "bench_generation",
    "format_report",
    "run_bench",
    "tick_compiled_us",
    "time_calls",
    "timing_scenario",
]
