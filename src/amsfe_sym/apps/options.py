"""The options of ``amsfe bench``, ``amsfe study`` and ``amsfe sweep`` (the parser is
:func:`amsfe_sym.apps.cli.get_argument_parser`; ``estimate`` keeps its own in
:mod:`amsfe_sym.apps.estimate`).  Every option that names a path the command writes says
the output rule in its help (docs/reference/scenarios.md, "Output paths")."""

from __future__ import annotations

import argparse

from amsfe_sym.apps.arguments import COUNT, DURATION, JOINT_RANGE, SEED, number_type

__all__ = [
    "add_bench_arguments",
    "add_robot_library",
    "add_runtime",
    "add_set",
    "add_study_arguments",
    "add_sweep_arguments",
]


def add_robot_library(p: argparse.ArgumentParser) -> None:
    """The robot (positional, default ``paper_2link``) and ``--out``, where its generated
    library is found or built."""
    p.add_argument("robot", nargs="?", default="paper_2link")
    p.add_argument(
        "--out",
        default=None,
        help="parent folder of generated libraries (a missing library is built there; a "
        "folder of yours at <out>/<robot> is never replaced)",
    )


def add_runtime(p: argparse.ArgumentParser) -> None:
    """``--runtime``: the loop in generated C or the Python reference."""
    p.add_argument(
        "--runtime",
        choices=("compiled", "python"),
        default="compiled",
        help="compiled: the loop in generated C (default); python: the readable reference",
    )


def add_set(p: argparse.ArgumentParser) -> None:
    """``--set KEY=VALUE`` (repeatable): a scenario override."""
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario field, e.g. integrator=paper, filter.link_torque_std=2, "
        'camera.delay=0 (see docs/reference/scenarios.md; "robot" restores the robot\'s '
        "camera timing)",
    )


def add_bench_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe bench``."""
    add_robot_library(p)
    p.add_argument("--repeat", type=COUNT, default=20000, help="calls per timing")
    p.add_argument("--rounds", type=COUNT, default=5, help="timing rounds (median reported)")
    p.add_argument(
        "--json",
        default=None,
        metavar="FILE",
        help="also write the report as JSON; an existing FILE is refused (checked before "
        "the timings)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --json report that amsfe bench wrote (never another file)",
    )
    p.add_argument(
        "--skip",
        nargs="+",
        choices=["generation", "calls", "estimators", "tick", "loop", "scaling", "logs", "vision"],
        default=[],
        help="sections to leave out",
    )
    p.add_argument(
        "--vision-frames",
        type=COUNT,
        default=150,
        help="frames per pass of the camera chain's section (vision; default 150)",
    )
    p.add_argument(
        "--joints",
        type=JOINT_RANGE,
        default=None,
        metavar="A-B",
        help="chain lengths of the scaling table (default 1-12)",
    )
    p.add_argument(
        "--no-panda",
        action="store_true",
        help="leave the Panda (7 DOF, ~30 s of compile) out of the scaling table",
    )
    p.add_argument(
        "--scaling-loop-duration",
        type=DURATION,
        default=2.0,
        help="simulated time of each scaling row's closed loop [s]",
    )
    p.add_argument(
        "--duration", type=DURATION, default=2.0, help="simulated time per estimator [s]"
    )
    p.add_argument(
        "--loop-scenarios",
        default=None,
        metavar="A,B",
        help="scenarios of the closed-loop section (default: the robot's timing scenario, "
        "and ur5-control for the 2-link arm)",
    )
    p.add_argument(
        "--loop-duration",
        type=DURATION,
        default=10.0,
        help="simulated time of the closed-loop section [s] (default 10)",
    )
    p.add_argument("--scenario", default=None, help="scenario of the estimator section")
    p.add_argument(
        "--estimators", nargs="+", default=None, help="estimators to time (default all five)"
    )
    p.add_argument(
        "--compare-cflags",
        nargs="?",
        const="",
        default=None,
        metavar="SETS",
        help="recompile with comma-separated flag sets, e.g. --compare-cflags=-O0,-O1,'-O1 "
        "-march=native' (no value: -O0..-O3, -Os, -O1 -march=native)",
    )
    p.add_argument("--compile-repeat", type=COUNT, default=1, help="builds per flag set (min)")
    p.add_argument(
        "--logs",
        nargs="+",
        default=None,
        metavar="SCENARIO:SECONDS[:CAMERA][:threads=N]",
        help="logs amsfe estimate is timed on, simulated with --bag (default paper-sim:10 "
        "panda-control:60); CAMERA: a 30 Hz camera writing 'pixels', 'images' or 'jpeg' "
        "(e.g. paper-sim:60:images); threads=N: the image decoding threads "
        "(AMSFE_IMAGE_THREADS, 0 serial; cases of one log share it, rounds interleaved)",
    )
    p.add_argument(
        "--ros",
        action="store_true",
        help="only the live loop over DDS: sim-node + node free running, idle and under "
        "--ros-load CPU hogs, each node implementation (docs/live-load.md)",
    )
    p.add_argument(
        "--ros-scenario", default="paper-sim", help="scenario of --ros (default paper-sim)"
    )
    p.add_argument(
        "--ros-duration", type=DURATION, default=2.0, help="arm time of each --ros run [s]"
    )
    p.add_argument(
        "--ros-load",
        type=number_type(int, 0, True, "pass a count of CPU hogs, e.g. 2", 64),
        default=2,
        help="CPU hogs of the loaded --ros runs (default 2; the idle runs have none)",
    )
    p.add_argument(
        "--ros-repeat",
        type=number_type(int, 1, True, "pass a count of runs, e.g. 5", 100),
        default=1,
        help="runs of each --ros row; the report adds each row's p99 median and worst (default 1)",
    )


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe study``."""
    p.add_argument("scenario", nargs="?", default="paper-sim", help="scenario name or .toml")
    p.add_argument("--seeds", type=COUNT, default=20, help="number of seeds (default 20)")
    p.add_argument("--first-seed", type=SEED, default=0, help="first seed (default 0)")
    p.add_argument("--estimators", default="all", help="all | name,name (default all)")
    p.add_argument("--duration", type=DURATION, default=None, help="simulated time [s]")
    p.add_argument("--workers", type=COUNT, default=2, help="processes (default 2)")
    p.add_argument(
        "--out",
        default=None,
        help="study folder (default runs/study-<scenario>-<stamp>); an existing one is refused",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out study folder that amsfe wrote (never a folder of yours)",
    )
    add_set(p)
    p.add_argument(
        "--variant",
        nargs="+",
        action="append",
        default=[],
        metavar="LABEL KEY=VALUE",
        help="a named scenario variant (repeatable): --variant paper integrator=paper",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.add_argument(
        "--claims", action="store_true", help="the claim table of docs/explanation/reproduction.md"
    )
    p.add_argument(
        "--second-block",
        type=SEED,
        default=None,
        metavar="FIRST_SEED",
        help="with --claims: the same table on a second seed block from FIRST_SEED, and the "
        "claims as effect sizes stated where both blocks agree",
    )
    p.add_argument(
        "--second-seeds",
        type=COUNT,
        default=None,
        help="seeds of the second block (default --seeds)",
    )
    add_runtime(p)


def add_sweep_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe sweep``."""
    p.add_argument("spec", help="sweep file (.toml), e.g. sweeps/camera-delay.toml")
    p.add_argument(
        "--out",
        default=None,
        help="sweep folder (default runs/sweep-<name>): the same sweep there resumes; a "
        "folder of yours is refused",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)",
    )
    p.add_argument(
        "--workers",
        type=number_type(int, 0, True, "pass --workers 2 (0: no Dask, runs in this process)"),
        default=None,
        help="local worker processes (default: the cores; 0: in this process, no Dask)",
    )
    p.add_argument("--batch", type=COUNT, default=None, help="runs per task (default auto)")
    p.add_argument("--retry-errors", action="store_true", help="run the error rows again")
    p.add_argument(
        "--force",
        action="store_true",
        help="start afresh in a folder of another sweep (never in a folder of yours)",
    )
    p.add_argument(
        "--repair",
        action="store_true",
        help="move unreadable parts or table to damaged/, keep the readable rows, go on",
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="run nothing: print the table of the folder's results (and write the figures)",
    )
    p.add_argument("--metric", default=None, help="metric of the table and figures")
    p.add_argument("--x", default=None, help="axis of the line plots (default [report] x)")
    p.add_argument("--y", default=None, help="second axis: heatmaps (default [report] y)")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
