"""The ``amsfe`` command line: generate, check, simulate, bench, study, sweep.

Built as :func:`get_argument_parser` + :func:`main` (``main(argv)`` is what the tests call).
Every command works with no arguments, on the paper's 2-link robot or its scenario.
Errors of the toolkit print one ``error: ...`` line (expected, found, fix) and exit 2.
"""

from __future__ import annotations

import argparse
import shlex
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from amsfe_sym import __version__
from amsfe_sym.apps import ros_nodes
from amsfe_sym.apps.arguments import Parser, options_from_args
from amsfe_sym.apps.calibrate import add_arguments as add_calibrate_arguments
from amsfe_sym.apps.calibrate import from_args as calibrate_from_args
from amsfe_sym.apps.command_args import (
    add_check_arguments,
    add_generate_arguments,
    add_simulate_arguments,
)
from amsfe_sym.apps.estimate import add_arguments as add_estimate_arguments
from amsfe_sym.apps.estimate import from_args as estimate_from_args
from amsfe_sym.apps.options import (
    add_bench_arguments,
    add_study_arguments,
    add_sweep_arguments,
)
from amsfe_sym.apps.sweep.command import from_args as sweep_from_args
from amsfe_sym.core.outputs import check_output, interrupted_note, ledger
from amsfe_sym.errors import AmsfeError, ConfigError, SpecError, describe

if TYPE_CHECKING:
    from amsfe_sym.codegen.build import GenerateResult

__all__ = ["BROKEN_PIPE", "get_argument_parser", "main"]


def get_argument_parser() -> argparse.ArgumentParser:
    """The argument parser of ``amsfe``."""
    parser = Parser(
        prog="amsfe",
        description="Code-generated elastic-joint robot models, multirate sensor fusion, DTSMC.",
    )
    parser.add_argument(
        "--version",
        action="version",
        version=f"amsfe {__version__} (amsfe_sym, Python {sys.version.split()[0]})",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name, command in _commands().items():
        command.add_arguments(sub.add_parser(name, help=command.help))
    return parser


@dataclass(frozen=True)
class _Command:
    """One ``amsfe`` command: its ``-h`` line, its options and what runs it (exit code)."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def _commands() -> dict[str, _Command]:
    """The commands of ``amsfe``, in ``-h`` order."""
    return {
        "generate": _Command(
            "URDF/robot -> generated/<name>/ (C, library, manifest)",
            add_generate_arguments,
            _generate,
        ),
        "check": _Command(
            "every generated function vs Pinocchio / finite differences",
            add_check_arguments,
            _check,
        ),
        "simulate": _Command(
            "run a scenario: plant, sensors, estimator, controller",
            add_simulate_arguments,
            _simulate,
        ),
        "estimate": _Command(
            "an estimator over a recorded rosbag2 / MCAP log",
            add_estimate_arguments,
            estimate_from_args,
        ),
        "calibrate": _Command(
            "camera pose, marker offset and time offset from a log (docs/calibrate.md)",
            add_calibrate_arguments,
            calibrate_from_args,
        ),
        "sim-node": _Command(
            "the simulated arm on ROS 2",
            ros_nodes.add_sim_node_arguments,
            ros_nodes.sim_node_from_args,
        ),
        "node": _Command(
            "estimator/controller on ROS 2",
            ros_nodes.add_node_arguments,
            ros_nodes.node_from_args,
        ),
        "play": _Command(
            "a log's sensor topics on ROS 2",
            ros_nodes.add_play_arguments,
            ros_nodes.play_from_args,
        ),
        "camera-node": _Command(
            "images -> the marker's pixel topic, live (ROS 2)",
            ros_nodes.add_camera_node_arguments,
            ros_nodes.camera_node_from_args,
        ),
        "live": _Command(
            "sim-node + node of a scenario in one command (ROS 2)",
            ros_nodes.add_live_arguments,
            ros_nodes.live_from_args,
        ),
        "bench": _Command(
            "timings: generation, per-call cost, estimator ticks",
            add_bench_arguments,
            _bench,
        ),
        "study": _Command(
            "Monte Carlo over seeds x estimators: tables, NEES, figures",
            add_study_arguments,
            _study,
        ),
        "sweep": _Command(
            "scenario grid x estimators x controllers x seeds on Dask (docs/how-to/sweeps.md)",
            add_sweep_arguments,
            sweep_from_args,
        ),
    }


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the process is, so every ``finally`` and temporary-folder
    cleanup runs as for Ctrl-C."""


def _terminated(signum: int, frame: object) -> None:
    raise Terminated


#: The exit status of a command whose stdout was closed under it (``amsfe ... | head``):
#: 128 + SIGPIPE, as a shell reports a process its broken pipe killed.
BROKEN_PIPE = 141


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``amsfe`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit code.
    SIGTERM is handled like Ctrl-C while it runs (exit 143, nothing half-written kept)."""
    try:
        previous = signal.signal(signal.SIGTERM, _terminated)
    except ValueError:  # not the main thread: leave signals alone
        return _main(argv)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _main(argv: Sequence[str] | None) -> int:
    try:
        args = get_argument_parser().parse_args(argv)
    except SystemExit as exc:  # bad arguments (one line, exit 2) or -h (exit 0)
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    commands = {name: command.run for name, command in _commands().items()}
    with ledger() as book:
        try:
            if args.command in commands:
                return commands[args.command](args)
        except AmsfeError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:
            how = "SIGTERM" if isinstance(exc, Terminated) else "Ctrl-C"
            print(
                f"interrupted: amsfe {args.command} stopped by {how}; {interrupted_note(book)}",
                file=sys.stderr,
            )
            return 143 if isinstance(exc, Terminated) else 130
        except BrokenPipeError:  # the reader of stdout went away (``amsfe ... | head``)
            print(
                f"stopped: amsfe {args.command}'s output was closed (broken pipe); "
                f"{interrupted_note(book)}",
                file=sys.stderr,
            )
            return BROKEN_PIPE
    raise SpecError(
        describe(
            "command",
            "|".join(commands),
            args.command,
            "run amsfe -h for the commands",
        )
    )


def _generate(args: argparse.Namespace) -> int:
    from amsfe_sym.codegen import generate
    from amsfe_sym.codegen.modes import robot_source, spec_at_period, warn_stiff
    from amsfe_sym.load.spec import load_spec

    if args.out:
        check_output(args.out, option="--out", kind="parent")
    extra = args.cflags.split() if args.cflags else None
    spec = load_spec(args.robot).with_locked(dict(args.lock))
    source = robot_source(spec)
    if args.substeps is not None and args.period is None:
        args.period = spec.model.T  # --substeps alone: the robot's T, other substeps
    if args.period is not None:
        spec = spec_at_period(spec, args.period, args.substeps)
    res = generate(spec, out=args.out, extra_cflags=extra, force=args.force, progress=True)
    if res.reused:  # a build says it before compiling
        import json

        from amsfe_sym.codegen.build import lowered_stiffness

        raw = json.loads(res.manifest_path.read_text())
        for line in lowered_stiffness(spec, raw["actuators"]["Ks"], raw["joints"]):
            print(line, file=sys.stderr)
        warn_stiff(res.stiff(), source, res.modes)
    print(f"{res.out_dir}: {_generate_state(res)}")
    if args.period is not None:
        m = spec.model
        print(
            f"  T = {m.T:.6g} s, integrator {m.integrator}, model_substeps {m.model_substeps}, "
            f"camera period {spec.camera.period} / delay {spec.camera.delay} steps"
        )
    if res.timings:
        print("  " + ", ".join(f"{k} {v:.2f} s" for k, v in res.timings.items()))
    return 0


def _generate_state(res: GenerateResult) -> str:
    """What ``generate`` did, in how long, and the command's time (start-up and imports
    included: seconds, where a cache hit's own check is a few ms)."""
    from amsfe_sym.apps.phases import command_startup_s, process_age_s

    state = "up to date (cached)" if res.reused else "generated"
    line = f"{state} in {res.seconds:.2f} s"
    if command_startup_s() is not None and (age := process_age_s()) is not None:
        line += f"; the command took {age:.1f} s (start-up and imports included)"
    return line


def _check(args: argparse.Namespace) -> int:
    from amsfe_sym.apps.check import format_table, run_checks
    from amsfe_sym.codegen import cached_library, generate
    from amsfe_sym.load import load_robot
    from amsfe_sym.runtime.library import ModelLibrary

    if args.out:
        check_output(args.out, option="--out", kind="parent")
    lock = dict(args.lock)
    extra = shlex.split(args.cflags) if args.cflags else None
    # the checks cover the model functions: reuse the full library if it is built, else build
    # the model part only (the control laws are checked against numpy in the test suite)
    kw = {"out": args.out, "lock": lock, "extra_cflags": extra}
    res = cached_library(args.robot, **kw) or generate(
        args.robot, progress=True, parts=("model",), **kw
    )
    robot = load_robot(args.robot, lock=lock)
    results = run_checks(robot, ModelLibrary(res.out_dir), samples=args.samples, seed=args.seed)
    print(
        f"{robot.name}: n = {robot.n}, p = {robot.p}, {args.samples} random states, "
        f"seed {args.seed}, library {res.library_path}"
    )
    print(format_table(results))
    failed = [r.function for r in results if not r.passed]
    if failed:
        for r in results:
            for where in r.failed_at:
                print(f"{r.function} failed at {where}")
        print(f"FAILED: {', '.join(failed)}")
        return 1
    print(f"all {len(results)} functions pass")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    """``amsfe simulate``: load the scenario, apply the overrides, generate its library, run,
    write the run folder and print the headline numbers (:mod:`amsfe_sym.apps.simulate`)."""
    import time
    from dataclasses import replace
    from datetime import datetime, timezone

    from amsfe_sym.apps.phases import command_startup_s
    from amsfe_sym.apps.simulate import (
        BAG_IN_RUN,
        SimulateOptions,
        check_outputs,
        simulate_comparison,
        simulate_one,
    )
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import apply_sets, load_scenario

    t0 = time.perf_counter()
    startup = command_startup_s() or 0.0
    sc = load_scenario(args.scenario).with_overrides(
        estimator=args.estimator,
        controller=args.controller,
        seed=args.seed,
        duration=args.duration,
    )
    if args.set:
        sc = apply_sets(sc, args.set)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    compare = tuple(args.compare.split(",")) if args.compare else sc.compare
    options = SimulateOptions(
        plots=not args.no_plots,
        all_plots=args.all_plots,
        force=args.force,
        progress=not args.no_progress,
        runtime=args.runtime,
        bag=None if args.bag is None else Path(args.bag) if args.bag else BAG_IN_RUN,
        inputs=_input_files(args.scenario),
        images=args.images,
    )
    one = not (compare and args.controller is None)  # else: the paper's comparison
    name = f"{sc.name}-{sc.estimator}-{stamp}" if one else f"{sc.name}-{stamp}"
    out = Path(args.out) if args.out else Path("runs") / name
    check_outputs(out, options)  # before the library is generated and the run
    lib = library_for(sc, progress=options.progress)  # a first run compiles: say so
    options = replace(options, started_s=startup + time.perf_counter() - t0)
    if one:
        simulate_one(sc, lib, out, options)
    else:
        simulate_comparison(sc, lib, compare, out, options)
    return 0


def _input_files(*names: str | None) -> tuple[Path, ...]:
    """The arguments that name existing files or folders (a scenario or robot may also be
    a shipped name): the inputs an output may not be, hold or lie inside."""
    return tuple(Path(n) for n in names if n and Path(n).exists())


def _bench_ros(args: argparse.Namespace) -> int:
    """``amsfe bench --ros`` (:mod:`amsfe_sym.apps.bench.ros`)."""
    from amsfe_sym.apps.bench.ros import (
        bench_ros,
        format_ros_report,
        machine_name,
        ros_report_json,
    )

    loads = (0, args.ros_load) if args.ros_load else (0,)
    rows = bench_ros(args.ros_scenario, args.ros_duration, loads, repeat=args.ros_repeat)
    machine = machine_name()
    print(format_ros_report(rows, machine))
    if args.json:
        from amsfe_sym.core.jsonfile import write_json

        write_json(Path(args.json), ros_report_json(rows, machine), 1, own="amsfe bench --ros")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from amsfe_sym.apps.bench import BenchOptions, run_bench
    from amsfe_sym.apps.bench.logs import log_case

    if args.out:
        check_output(args.out, option="--out", kind="parent")
    if args.json:
        check_output(
            args.json,
            option="--json",
            kind="file",
            force=args.force,
            inputs=_input_files(args.robot),
        )
    if args.ros:
        return _bench_ros(args)
    sets = args.compare_cflags
    given = {
        "robot": str(args.robot),
        "skip": tuple(args.skip),
        "estimators": tuple(args.estimators) if args.estimators else None,
        "compare_cflags": None
        if sets is None
        else tuple(f.strip() for f in str(sets).split(",") if f.strip()),
        "joints": args.joints or tuple(range(1, 13)),
        "loop_scenarios": tuple(args.loop_scenarios.split(",")) if args.loop_scenarios else None,
        "scaling_panda": not args.no_panda,
        "logs": tuple(log_case(x) for x in args.logs) if args.logs else None,
    }
    return run_bench(options_from_args(BenchOptions, args, **given))


def _parse_variant(items: Sequence[str]) -> tuple[str, list[str]]:
    label, *sets = items
    if "=" in label or not label:
        raise ConfigError(
            describe(
                "--variant",
                "LABEL KEY=VALUE [KEY=VALUE ...]",
                repr(" ".join(items)),
                "start with a label, e.g. --variant paper integrator=paper",
            )
        )
    return label, list(sets)


def _study(args: argparse.Namespace) -> int:
    from amsfe_sym.apps.study import run_study

    inputs = _input_files(args.scenario)
    if args.claims:  # the claim table of docs/explanation/reproduction.md on these seeds
        from amsfe_sym.apps.study.claims import (
            format_claims,
            is_claims_folder,
            run_claims,
            write_claims,
        )

        if args.out:
            check_output(
                args.out, option="--out", force=args.force, inputs=inputs, own=is_claims_folder
            )
        t = run_claims(
            args.scenario, args.first_seed, args.seeds, args.duration, args.workers, args.set
        )
        if args.second_block is not None:
            t.second = run_claims(
                args.scenario,
                args.second_block,
                args.second_seeds or args.seeds,
                args.duration,
                args.workers,
                args.set,
            )
        print(format_claims(t))
        if args.out:
            write_claims(t, Path(args.out), force=args.force)
        return 0
    variants = dict(_parse_variant(v) for v in (args.variant or [])) or None
    res = run_study(
        args.scenario,
        seeds=args.seeds,
        estimators=args.estimators,
        duration=args.duration,
        workers=args.workers,
        out=args.out,
        sets=list(args.set or []),
        variants=variants,
        first_seed=args.first_seed,
        progress=not args.no_progress,
        runtime=args.runtime,
        force=args.force,
        inputs=inputs,
    )
    print(res.table)
    print(f"study folder: {res.out} (study.md, study.json, {len(res.figures)} figures)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
