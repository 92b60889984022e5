"""``amsfe bench``: the options, the run of every section, and the printed tables."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from amsfe_sym.apps.bench.calls import CallRow, bench_calls, bench_cflags, tick_compiled_us
from amsfe_sym.apps.bench.generation import bench_generation
from amsfe_sym.apps.bench.logs import DEFAULT_LOGS, LogCase, bench_log_estimates, log_lines
from amsfe_sym.apps.bench.loop import bench_closed_loop
from amsfe_sym.apps.bench.scaling import bench_scaling
from amsfe_sym.apps.bench.tick import bench_tick
from amsfe_sym.apps.bench.ticks import ESTIMATOR_NAMES, bench_estimators, timing_scenario
from amsfe_sym.apps.bench.vision import bench_vision, vision_lines
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.provenance import provenance
from amsfe_sym.errors import ConfigError, describe

__all__ = ["DEFAULT_CFLAG_SETS", "TARGETS", "BenchOptions", "format_report", "run_bench"]

#: Flag sets of ``--compare-cflags`` when none are given.
DEFAULT_CFLAG_SETS: tuple[str, ...] = ("-O0", "-O1", "-O2", "-O3", "-Os", "-O1 -march=native")
#: The project's targets: cold generation (2-link, 6/7-DOF arm), cached generation [s],
#: and the binding's per-call overhead [us].
TARGETS = {"cold_2link_s": 2.0, "cold_arm_s": 20.0, "cached_s": 1.0, "overhead_us": 3.0}


def _fmt(v: float | None, width: int = 9, digits: int = 2) -> str:
    return f"{'-':>{width}}" if v is None else f"{v:>{width}.{digits}f}"


def machine_info() -> dict[str, Any]:
    """The report's provenance (:func:`amsfe_sym.core.provenance.provenance`) plus the C
    compiler and flags the libraries are built with."""
    from amsfe_sym.codegen import cflags, compiler

    return {**provenance(), "compiler": compiler(), "cflags": " ".join(cflags())}


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
    lines += _tick_lines(report)
    if report.get("logs"):
        lines += log_lines(report["logs"])
    if report.get("vision"):
        lines += vision_lines(report["vision"], m["cpu"])
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


def _tick_lines(report: dict[str, Any]) -> list[str]:
    """Sections 4 (one tick three ways), the closed loop and 5 (scaling with joints)."""
    lines: list[str] = []
    tick = report.get("tick")
    if tick:
        lines += [
            "",
            f"4. one estimator tick (predict + encoder update, no frame): scenario "
            f"{tick['scenario']} (library {tick['library']}), {tick['ticks']} ticks; [us]",
            f"   {'estimator':<10}{'compiled C':>12}{'p99':>9}{'python':>10}{'p99':>9}"
            f"{'baseline':>10}{'p99':>9}{'x python':>10}{'x baseline':>12}",
        ]
        for r in tick["rows"]:
            c, py, b = r["compiled"], r["python"], r.get("baseline")
            lines.append(
                f"   {r['estimator']:<10}{c['median_us']:>12.2f}{c['p99_us']:>9.2f}"
                f"{py['median_us']:>10.1f}{py['p99_us']:>9.1f}"
                f"{_fmt(b and b['median_us'], 10, 1)}{_fmt(b and b['p99_us'], 9, 1)}"
                f"{_fmt(r.get('speedup_python'), 10, 1)}{_fmt(r.get('speedup_baseline'), 12, 1)}"
            )
            if "late_frame" in r:
                f = r["late_frame"]
                lines.append(
                    f"   {r['estimator']} late frame (pure C, {f['frames']} frames, "
                    f"{f['applied']} applied): {f['median_us']:.1f} us median, "
                    f"{f['p99_us']:.1f} us p99"
                )
            if "compiled_with_law_us" in r:
                lines.append(
                    f"   {r['estimator']} tick + control_amsfe (pure C, {tick['law_us']:.2f} us): "
                    f"{r['compiled_with_law_us']:.2f} us (target <= 5 us 2-link, <= 40 us 6-DOF)"
                )
        lines.append(
            "   compiled = amsfe_est_tick in pure C; python = the reference estimator's step; "
            "baseline = Pinocchio computeABADerivatives (semi-implicit Euler) + numpy EKF"
        )
    for loop in report.get("closed_loop", []):
        lines += [
            "",
            f"closed loop: {loop['scenario']} ({loop['estimator']} + {loop['controller']}: "
            "plant substeps, sensors, estimator, controller), real-time factor "
            "= simulated / wall time",
            f"   {'runtime':<10}{'simulated [s]':>14}{'wall [s]':>10}{'us/tick':>10}"
            f"{'x real time':>13}",
        ]
        for rt in ("compiled", "python"):
            r = loop.get(rt, {})
            if "error" in r:
                lines.append(f"   {rt:<10}failed: {r['error']}")
            elif r:
                lines.append(
                    f"   {rt:<10}{r['sim_time_s']:>14.2f}{r['wall_s']:>10.3f}"
                    f"{r['us_per_tick']:>10.1f}{r['real_time_factor']:>13.1f}"
                )
        if "speedup" in loop:
            lines.append(
                f"   compiled / python: {loop['speedup']}x per tick "
                "(targets: >= 300x real time paper-sim, >= 80x ur5-control, "
                ">= 50x panda-control)"
            )
    sc = report.get("scaling")
    if sc:
        lines += _scaling_lines(sc)
    return lines


def _scaling_lines(sc: dict[str, Any]) -> list[str]:
    """Section 5: one row per chain and the Panda, then the fitted growth exponents."""
    lines = [
        "",
        f"5. scaling with joints: serial chains and the Panda, {sc['integrator']} model; "
        "generate = cold, new process; tick = oosm in pure C; numpy+pin = the numpy + "
        "Pinocchio EKF tick, x = numpy+pin / tick, ABA d = computeABADerivatives alone [us], "
        "same run",
        f"   {'robot':<8}{'n':>3}{'N':>4}{'lines of C':>11}{'gen [s]':>8}{'peak MB':>8}"
        f"{'tick':>8}{'p99':>8}{'numpy+pin':>10}{'x':>6}{'ABA d':>7}{'loop us':>9}"
        f"{'x real':>8}  loop scenario",
    ]
    for r in sc["rows"]:
        rtf = r.get("real_time_factor")
        div = f" (diverged at {r['diverged_at_s']:g} s)" if r.get("diverged_at_s") else ""
        loop = r.get("error", "")[:60] if "error" in r else r["scenario"] + div
        lines.append(
            f"   {r['robot']:<8}{r['joints']:>3}{r['N']:>4}{r['c_lines']:>11}"
            f"{r['generate_s']:>8.2f}{r['peak_mb']:>8.0f}{r['tick_us']:>8.2f}"
            f"{r['tick_p99_us']:>8.2f}{r['baseline_us']:>10.1f}{r['speedup_baseline']:>6.1f}"
            f"{r['aba_derivatives_us']:>7.2f}{_fmt(r.get('loop_us_per_tick'), 9, 1)}"
            f"{_fmt(rtf, 8, 1)}  {loop}"
        )
        dj = r.get("dynamics_jacobian")
        if dj:
            lines.append(
                f"   {'':<8}generated {dj['function']}: {dj['median_us']:.2f} us, "
                f"{dj['median_us'] / r['aba_derivatives_us']:.2f}x computeABADerivatives"
            )
    ex = sc.get("exponents")
    if ex:
        lines.append(
            "   growth exponents over the chains (log-log fit, n >= 2): "
            + ", ".join(f"{k} {v:.2f}" for k, v in ex.items())
        )
    return lines


def _tget(row: dict[str, Any], key: str, width: int = 9) -> str:
    t = row.get(key)
    return _fmt(None if t is None else t["median_us"], width)


@dataclass(frozen=True)
class BenchOptions:
    """What ``amsfe bench`` measures (the command line's options, typed).

    Attributes:
        robot: Robot name, folder or URDF.
        out: Parent folder of generated libraries (None: the default).
        repeat: Upper bound on calls per timing round.
        rounds: Timing rounds (the median is reported).
        json: Also write the report there.
        skip: Sections left out: ``generation``, ``calls``, ``estimators``, ``tick``,
            ``loop``, ``scaling``, ``logs``, ``vision``.
        duration: Simulated time per estimator [s].
        scenario: Scenario of the estimator section (None: see :func:`timing_scenario`).
        estimators: Estimators to time (None: all registered).
        compare_cflags: Flag sets to recompile with (None: no comparison; empty: the
            defaults :data:`DEFAULT_CFLAG_SETS`).
        compile_repeat: Builds per flag set (the fastest is reported).
        joints: Chain lengths of the scaling table (section 5).
        loop_duration: Simulated time of the closed-loop section [s].
        loop_scenarios: Scenarios of the closed-loop section (None: the robot's timing
            scenario, and ur5-control and panda-control for the 2-link arm).
        scaling_panda: Add the shipped Panda to the scaling table.
        scaling_loop_duration: Simulated time of each scaling row's closed loop [s].
        logs: The logs ``amsfe estimate`` is timed on (section 6; None:
            :data:`~amsfe_sym.apps.bench.logs.DEFAULT_LOGS`, a 10 s paper-sim and a 60 s
            panda-control log).
        vision_frames: Frames per pass of the camera chain's section (``vision``,
            :mod:`amsfe_sym.apps.bench.vision`).
    """

    robot: str = "paper_2link"
    out: str | None = None
    repeat: int = 20000
    rounds: int = 5
    json: str | None = None
    skip: tuple[str, ...] = ()
    duration: float = 2.0
    scenario: str | None = None
    estimators: tuple[str, ...] | None = None
    compare_cflags: tuple[str, ...] | None = None
    compile_repeat: int = 1
    joints: tuple[int, ...] = tuple(range(1, 13))
    loop_duration: float = 10.0
    loop_scenarios: tuple[str, ...] | None = None
    scaling_panda: bool = True
    scaling_loop_duration: float = 2.0
    logs: tuple[LogCase, ...] | None = None
    vision_frames: int = 150


def run_bench(opts: BenchOptions) -> int:
    """``amsfe bench``: print the tables, optionally write JSON.

    Raises:
        ConfigError: non-positive ``repeat`` or ``rounds``.
    """
    from amsfe_sym.codegen import library_for, load_library
    from amsfe_sym.load import load_robot

    repeat, rounds = opts.repeat, opts.rounds
    if repeat < 1 or rounds < 1:
        raise ConfigError(
            describe(
                "--repeat / --rounds",
                "positive integers",
                f"{repeat} / {rounds}",
                "pass e.g. --repeat 20000 --rounds 5",
            )
        )
    lib = load_library(opts.robot, out=opts.out)
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
    if "generation" not in opts.skip:
        report["generation"] = bench_generation(opts.robot)
    if "calls" not in opts.skip:
        robot = load_robot(opts.robot)
        report["calls"] = [_row_dict(r) for r in bench_calls(lib, robot, repeat, rounds)]
    if "estimators" not in opts.skip:
        sc = timing_scenario(lib, opts.duration, opts.scenario)
        sc_lib = library_for(sc)
        report["scenario"] = {
            "name": sc.name,
            "robot": sc_lib.name,
            "integrator": sc_lib.manifest.integrator,
            "duration": sc.duration,
            "seed": sc.seed,
        }
        report["estimators"] = bench_estimators(sc, opts.estimators or ESTIMATOR_NAMES, sc_lib)
        report["tick_compiled_us"] = tick_compiled_us(sc_lib, rounds)
    if "tick" not in opts.skip:
        sc = timing_scenario(lib, opts.duration, opts.scenario)
        sc_lib = library_for(sc)
        robot = load_robot(sc.robot)
        report["tick"] = {
            "scenario": sc.name,
            "library": sc_lib.name,
            **bench_tick(sc, sc_lib, robot, opts.estimators or ("oosm",), rounds),
        }
    if "loop" not in opts.skip:  # the closed loop's real-time factor, 10 s, both runtimes
        if opts.loop_scenarios:
            scs = [timing_scenario(lib, opts.loop_duration, s) for s in opts.loop_scenarios]
        else:  # the robot's, and for the paper's arm also a 6-DOF arm
            scs = [timing_scenario(lib, opts.loop_duration, opts.scenario)]
            if lib.n <= 2 and opts.scenario is None:
                for name in ("ur5-control", "panda-control"):
                    scs.append(timing_scenario(lib, opts.loop_duration, name))
        report["closed_loop"] = []
        for sc in scs:
            sc_lib = library_for(sc)
            arm = sc_lib.n > 2  # the Python loop of an arm is slow: 2 s of it, one round
            report["closed_loop"].append(
                bench_closed_loop(
                    sc,
                    sc_lib,
                    rounds=1 if arm else min(rounds, 3),
                    python_duration=min(opts.loop_duration, 2.0) if arm else None,
                )
            )
    if "scaling" not in opts.skip:
        report["scaling"] = bench_scaling(
            opts.joints,
            progress=True,
            panda=opts.scaling_panda,
            loop_duration=opts.scaling_loop_duration,
            rounds=rounds,
        )
    if "logs" not in opts.skip:  # amsfe estimate over a log, fresh processes
        import tempfile

        with tempfile.TemporaryDirectory(prefix="amsfe-bench-logs-") as tmp:
            report["logs"] = bench_log_estimates(
                opts.logs or DEFAULT_LOGS, min(rounds, 3), Path(tmp), opts.out
            )
    if "vision" not in opts.skip:  # the camera chain per frame, one core
        report["vision"] = bench_vision(opts.vision_frames, min(rounds, 3))
    if opts.compare_cflags is not None:
        report["cflags"] = bench_cflags(
            lib,
            opts.compare_cflags or DEFAULT_CFLAG_SETS,
            repeat,
            rounds,
            compile_repeat=opts.compile_repeat,
        )
    print(format_report(report))
    if opts.json:
        Path(opts.json).parent.mkdir(parents=True, exist_ok=True)
        write_json(Path(opts.json).expanduser().resolve(), report, own="amsfe bench")
        print(f"wrote {opts.json}")
    return 0


def _row_dict(row: CallRow) -> dict[str, Any]:
    return asdict(row)
