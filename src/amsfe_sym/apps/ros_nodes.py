"""``amsfe sim-node``, ``amsfe node`` and ``amsfe play``: the command-line side of the ROS 2
nodes of :mod:`amsfe_sym.ros` (docs/how-to/ros.md).  One ``add_*_arguments`` / ``*_from_args`` pair
per command; rclpy is imported only when a command runs.

Exit codes: 0 done; 2 bad input (one ``error:`` line); 3 (``amsfe node``) a fail-safe hold
(encoder silence, non-finite estimate, estimator failure); 130 / 143 Ctrl-C / SIGTERM (the
node publishes its hold command first; a record is written).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from amsfe_sym.apps.arguments import DURATION, SEED, number_type, options_from_args
from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "add_camera_node_arguments",
    "add_live_arguments",
    "add_node_arguments",
    "add_play_arguments",
    "add_sim_node_arguments",
    "camera_node_from_args",
    "live_from_args",
    "node_from_args",
    "play_from_args",
    "sim_node_from_args",
]

SECONDS = number_type(float, 0.0, False, "pass a time in seconds > 0, e.g. 0.5")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="paper-sim", help="scenario name or .toml")
    p.add_argument("--seed", type=SEED, default=None)
    p.add_argument("--duration", type=DURATION, default=None, help="[s] of sample time")
    p.add_argument(
        "--topic-spec",
        default=None,
        metavar="FILE",
        help="topics, joints, QoS (docs/reference/topics.md)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario field (as amsfe simulate --set)",
    )
    p.add_argument(
        "--ros-args",
        nargs=argparse.REMAINDER,
        default=[],
        help="the rest goes to ROS 2 (e.g. -p topics.encoders:=/joint_states -p qos.depth:=10)",
    )


def _impl_argument(
    p: argparse.ArgumentParser, help: str, exe: str | None = None, exe_help: str = ""
) -> None:
    """``--impl auto|c|python``: the C path on rcl, the Python reference, or the C one when
    it builds and runs this configuration (``auto``, the default); with ``exe`` (``node`` or
    ``arm``) also ``--EXE-exe FILE``, that C program built elsewhere (``exe_help``: where)."""
    p.add_argument("--impl", choices=("auto", "c", "python"), default="auto", help=help)
    if exe is not None:
        p.add_argument(
            f"--{exe}-exe",
            default=None,
            metavar="FILE",
            help=f"the C {exe} built elsewhere ({exe_help}) instead of the wheel build",
        )


def _scenario(args: argparse.Namespace, **over: Any) -> Any:
    from amsfe_sym.scenario import apply_sets, load_scenario

    sc = load_scenario(args.scenario).with_overrides(seed=args.seed, duration=args.duration, **over)
    return apply_sets(sc, args.set) if args.set else sc


def _domain() -> int | None:
    raw = os.environ.get("ROS_DOMAIN_ID")
    if raw is None or raw == "":
        return None
    if not raw.isdigit() or not 0 <= int(raw) <= 232:
        raise ConfigError(
            describe("ROS_DOMAIN_ID", "an integer in 0..232 (0..101 is safe)", repr(raw), "fix it")
        )
    return int(raw)


def add_sim_node_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe sim-node``."""
    _common(p)
    p.add_argument(
        "--lockstep", action="store_true", help="a tick advances only when its command arrived"
    )
    p.add_argument("--start-timeout", type=SECONDS, default=30.0, help="wait for a node [s]")
    p.add_argument(
        "--command-timeout", type=SECONDS, default=5.0, help="lockstep: wait for a command [s]"
    )
    p.add_argument(
        "--rate", type=SECONDS, default=1.0, help="free running: speed of the wall clock"
    )
    p.add_argument(
        "--images",
        action="store_true",
        help="publish each frame as the camera's image (/camera/image_raw) and its CameraInfo "
        "instead of the pixel topic: amsfe camera-node detects them (docs/camera.md)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KIND@T[=VALUE]",
        help="break the arm at T [s]: encoder_frozen, encoder_jump=RAD, torque_loss "
        "(docs/live-load.md)",
    )
    _impl_argument(
        p,
        "the arm in C on rcl (a real-time clock; auto: when it builds) or in Python "
        '(docs/live-load.md, "The C arm")',
        "arm",
        "cmake --build: BUILD/amsfe_arm",
    )


def sim_node_from_args(args: argparse.Namespace) -> int:
    """``amsfe sim-node`` from its parsed options."""
    from amsfe_sym.codegen import library_for
    from amsfe_sym.ros.faults import FaultPlan, parse_fault
    from amsfe_sym.ros.sim_node import SimNodeOptions, run_sim_node
    from amsfe_sym.topics import read_topic_spec

    faults = tuple(parse_fault(f) for f in args.fault)
    sc = _scenario(args)
    spec = read_topic_spec(args.topic_spec)
    lib = library_for(sc)
    opts = SimNodeOptions(
        lockstep=args.lockstep,
        spec=spec,
        start_timeout=args.start_timeout,
        command_timeout=args.command_timeout,
        rate=args.rate,
        ros_args=tuple(args.ros_args),
        domain_id=_domain(),
        images=args.images,
        faults=faults,
    )
    FaultPlan(faults, lib.T, lib.n)  # the same kind twice: refused before rclpy starts
    mode = "lockstep" if args.lockstep else "free running"
    broken = "".join(f", fault {f.label()}" for f in faults)
    impl = "c" if args.arm_exe is not None else _arm_impl(args.impl, lib, opts)
    print(
        f"sim-node: {sc.name} seed {sc.seed}, {sc.duration:g} s, {mode}{broken} ({impl} arm)",
        flush=True,
    )
    if impl == "c":
        from amsfe_sym.ros.carm import run_c_arm

        exe = None if args.arm_exe is None else Path(args.arm_exe)
        return run_c_arm(sc, lib, opts, exe=exe)
    rep = run_sim_node(sc, lib, opts)
    line = f"sim-node: {rep.ticks} ticks in {rep.wall_s:.2f} s wall, {rep.commands} commands"
    if not args.lockstep:
        line += f", {rep.late_ticks} late ticks, {rep.stale_ticks} without a new command"
    print(line, flush=True)
    print(f"sim-node: {rep.latency_line()}", flush=True)
    return 0


def _c_or_python(
    asked: str,
    why: str | None,
    build: Callable[[], object],
    what: str,
    refuse: Callable[[str], object],
) -> str:
    """``c`` or ``python`` for a program with a C twin (the arm, the node): ``--impl auto``
    runs the C ``what`` when ``why`` (its refusal of these options) is None and it builds,
    else the Python one, saying why in one line; ``--impl c`` refuses (``refuse``, one line)
    what it cannot run and raises a failed build."""
    from amsfe_sym.errors import AmsfeError

    if why is None:
        try:
            build()
        except AmsfeError as exc:
            if asked == "c":
                raise
            why = f"the C {what} did not build ({str(exc).split('. Fix:')[0]})"
    if why is None:
        return "c"
    if asked == "c":
        refuse(why)
    prog = "sim-node" if what == "arm" else what
    print(f"{prog}: the Python {what}: {why}", flush=True)
    return "python"


def _arm_impl(asked: str, lib: Any, opts: Any) -> str:
    """``c`` or ``python`` for ``amsfe sim-node`` (:func:`_c_or_python`)."""
    if asked == "python":
        return "python"
    from amsfe_sym.ros.carm import build_arm, c_arm_refusal

    def refuse(why: str) -> NoReturn:
        raise ConfigError(
            describe("amsfe sim-node --impl c", "options the C arm runs", why, "--impl python")
        )

    return _c_or_python(asked, c_arm_refusal(opts), lambda: build_arm(lib), "arm", refuse)


def add_node_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe node``."""
    _common(p)
    p.add_argument("--estimator", default=None, help="estimator name (default the scenario's)")
    p.add_argument(
        "--controller",
        nargs="?",
        const="",
        default=None,
        help="run a controller and publish commands (no name: the scenario's)",
    )
    p.add_argument("--record", default=None, metavar="DIR", help="write a rosbag2 (MCAP) here")
    p.add_argument("--runtime", choices=("compiled", "python"), default="compiled")
    p.add_argument(
        "--encoder-timeout",
        type=SECONDS,
        default=None,
        help="encoder silence -> hold [s] (default: the topic spec's [watchdog] "
        "encoder_timeout, 0.5 s)",
    )
    p.add_argument(
        "--std-every",
        type=int,
        default=None,
        metavar="N",
        help="publish estimate_std and theta every N-th tick and on the last "
        "(default 10; 1: every tick; the record has every tick)",
    )
    p.add_argument(
        "--managed",
        action="store_true",
        help="a lifecycle node: configure, then activate before it processes samples",
    )
    p.add_argument(
        "--hold",
        choices=("gravity", "zero"),
        default="gravity",
        help="the fail-safe command: g(q_hat) or zero (docs/how-to/ros.md)",
    )
    _impl_argument(
        p,
        "the per-sample path: the C node on rcl (auto: when it builds and runs this "
        "configuration) or the Python reference (docs/live-control.md)",
        "node",
        "cmake --build: BUILD/amsfe_node; colcon: install/amsfe_node/lib/amsfe_node/amsfe_node",
    )


def node_from_args(args: argparse.Namespace) -> int:
    """``amsfe node`` from its parsed options."""
    from amsfe_sym.apps.estimate_filter import estimator_note
    from amsfe_sym.codegen import library_for
    from amsfe_sym.core.outputs import check_output
    from amsfe_sym.ros.node import NodeOptions, run_node
    from amsfe_sym.ros.outputs import DEFAULT_STD_EVERY
    from amsfe_sym.topics import read_topic_spec

    if args.std_every is not None and args.std_every < 1:
        raise ConfigError(
            describe("--std-every", "an integer >= 1", str(args.std_every), "--std-every 10")
        )
    sc = _scenario(args, estimator=args.estimator, controller=args.controller or None)
    if args.controller is not None:  # before anything is said or built
        from amsfe_sym.control import check_controller_name

        check_controller_name(sc.controller)
    record = None if args.record is None else Path(args.record)
    if record is not None:
        # before anything runs: nothing there is replaced, and no input is written over
        inputs = [p for p in (args.scenario, args.topic_spec) if p and Path(p).exists()]
        from amsfe_sym.ros.record import refuse_locked

        refuse_locked(record)  # another node's record, being written or left unfinished
        check_output(record, option="--record", kind="folder", inputs=inputs)
    spec = read_topic_spec(args.topic_spec)
    note = estimator_note(spec.effort_kind or "applied", sc.estimator)
    if note:
        print(f"node: {note}", flush=True)
    lib = library_for(sc)
    opts = NodeOptions(
        controller=args.controller is not None,
        compiled=args.runtime == "compiled",
        spec=spec,
        encoder_timeout=args.encoder_timeout,
        hold=args.hold,
        managed=args.managed,
        std_every=DEFAULT_STD_EVERY if args.std_every is None else args.std_every,
        duration=args.duration,
        record=record,
        ros_args=tuple(args.ros_args),
        domain_id=_domain(),
    )
    ctrl = f", controller {sc.controller}" if opts.controller else ""
    impl = "c" if args.node_exe is not None else _node_impl(args.impl, sc, lib, opts)
    if impl == "c":
        from amsfe_sym.ros.cnode import run_c_node

        print(f"node: {sc.name}, estimator {sc.estimator}{ctrl}; the C node", flush=True)
        exe = None if args.node_exe is None else Path(args.node_exe)
        crun = run_c_node(sc, lib, opts, say=lambda line: print(line, flush=True), exe=exe)
        if crun.record is not None:
            print(f"node: record {crun.record} (amsfe estimate {crun.record})", flush=True)
        return crun.exit_code
    wait = "configure and activate" if args.managed else "encoders"
    print(f"node: {sc.name}, estimator {sc.estimator}{ctrl}; waiting for {wait}", flush=True)
    rep = run_node(sc, lib, opts, say=lambda line: print(line, flush=True))
    if rep.record is not None:
        print(f"node: record {rep.record} (amsfe estimate {rep.record})", flush=True)
    return rep.exit_code


def _node_impl(asked: str, sc: Any, lib: Any, opts: Any) -> str:
    """``c`` or ``python`` for ``amsfe node`` (:func:`_c_or_python`)."""
    if asked == "python":
        return "python"
    from amsfe_sym.ros.cnode import build_node, c_node_refusal, refuse_c_node

    why = c_node_refusal(sc, opts.spec, opts.managed, opts.controller, opts.compiled)
    return _c_or_python(asked, why, lambda: build_node(lib), "node", refuse_c_node)


def add_play_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe play``."""
    p.add_argument("log", help="rosbag2 folder or .mcap file (amsfe simulate --bag writes one)")
    p.add_argument(
        "--rate",
        type=number_type(float, 1e-3, True, "pass e.g. --rate 1 (the recorded pace)", 1000),
        default=1.0,
        help="speed factor of the recorded pace, 0.001 to 1000",
    )
    p.add_argument(
        "--topic-spec",
        default=None,
        metavar="FILE",
        help="topics, joints, QoS (docs/reference/topics.md)",
    )
    p.add_argument("--start-timeout", type=SECONDS, default=30.0, help="wait for a node [s]")
    p.add_argument(
        "--ordered",
        action="store_true",
        help="a log time's messages acknowledged before its encoder sample (slower, exact)",
    )
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], help="the rest: ROS 2")


def play_from_args(args: argparse.Namespace) -> int:
    """``amsfe play LOG`` from its parsed options."""
    from amsfe_sym.ros.play import PlayOptions, play_log
    from amsfe_sym.topics import read_topic_spec

    opts = PlayOptions(
        rate=args.rate,
        spec=read_topic_spec(args.topic_spec),
        start_timeout=args.start_timeout,
        ros_args=tuple(args.ros_args),
        domain_id=_domain(),
        ordered=args.ordered,
    )
    rep = play_log(Path(args.log), opts)
    sent = ", ".join(f"{t} {c}" for t, c in rep.messages.items())
    print(f"play: {rep.log_s:.2f} s of log in {rep.wall_s:.2f} s wall: {sent}", flush=True)
    return 0


def add_camera_node_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe camera-node`` (docs/camera.md, "Live")."""
    p.add_argument(
        "--topic-spec",
        default=None,
        metavar="FILE",
        help="[marker], the pixel topic it publishes ([topics] camera) and QoS",
    )
    p.add_argument("--image", default="/camera/image_raw", help="the image topic")
    p.add_argument("--info", default="/camera/camera_info", help="its CameraInfo topic")
    p.add_argument("--compressed", action="store_true", help="the image topic is a CompressedImage")
    p.add_argument("--duration", type=SECONDS, default=None, help="stop after this long [s]")
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], help="the rest: ROS 2")


def camera_node_from_args(args: argparse.Namespace) -> int:
    """``amsfe camera-node`` from its parsed options."""
    from amsfe_sym.ros.camera_node import CameraNodeOptions, run_camera_node
    from amsfe_sym.topics import read_topic_spec

    opts = CameraNodeOptions(
        spec=read_topic_spec(args.topic_spec),
        image=args.image,
        info=args.info,
        compressed=args.compressed or args.image.endswith("/compressed"),
        duration=args.duration,
        ros_args=tuple(args.ros_args),
        domain_id=_domain(),
    )
    run_camera_node(opts, say=lambda line: print(line, flush=True))
    return 0


def add_live_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe live`` (the arm and the node in one command)."""
    p.add_argument("scenario", nargs="?", default="paper-sim", help="scenario name or .toml")
    p.add_argument(
        "--controller", default="", help="the node's controller (default the scenario's)"
    )
    p.add_argument("--lockstep", action="store_true", help="the arm waits for each command (exact)")
    p.add_argument("--duration", type=DURATION, default=None, help="[s] of sample time")
    p.add_argument("--seed", type=SEED, default=None)
    p.add_argument(
        "--rate", type=SECONDS, default=1.0, help="free running: speed of the arm's clock"
    )
    _impl_argument(p, "the node's per-sample path, as amsfe node --impl")
    p.add_argument("--record", default=None, metavar="DIR", help="the node's record")
    p.add_argument("--topic-spec", default=None, metavar="FILE")
    p.add_argument(
        "--encoder-timeout", type=SECONDS, default=None, help="the node's encoder silence [s]"
    )
    p.add_argument(
        "--command-timeout",
        type=SECONDS,
        default=None,
        help="the arm's wait for the node and for a lockstep command [s]",
    )
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], help="to both nodes")


def live_from_args(args: argparse.Namespace) -> int:
    """``amsfe live`` from its parsed options (ros/pair.py); ``--record`` is checked as
    ``amsfe node`` checks it, before either process starts."""
    from amsfe_sym.core.outputs import check_output
    from amsfe_sym.ros.pair import PairOptions, run_pair

    if args.record is not None:
        inputs = [p for p in (args.scenario, args.topic_spec) if p and Path(p).exists()]
        check_output(Path(args.record), option="--record", kind="folder", inputs=inputs)

    given = {"controller": args.controller or None, "ros_args": tuple(args.ros_args)}
    return run_pair(options_from_args(PairOptions, args, **given))
