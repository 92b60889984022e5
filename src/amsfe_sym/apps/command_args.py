"""The arguments of ``amsfe generate``, ``check`` and ``simulate`` (the command line's
parser is :func:`amsfe_sym.apps.cli.get_argument_parser`)."""

from __future__ import annotations

import argparse

from amsfe_sym.apps.arguments import (
    DURATION,
    SAMPLES,
    SEED,
    lock_arg,
    number_type,
)
from amsfe_sym.apps.options import add_robot_library, add_runtime, add_set
from amsfe_sym.core.values import SUBSTEPS_MAX

__all__ = ["add_check_arguments", "add_generate_arguments", "add_simulate_arguments"]


def add_generate_arguments(g: argparse.ArgumentParser) -> None:
    """The arguments of ``amsfe generate``."""
    g.add_argument("robot", nargs="?", default="paper_2link", help="robot name, folder or URDF")
    g.add_argument(
        "--out",
        default=None,
        help="parent folder of the libraries (default: generated/); a file or a folder of "
        "yours at <out>/<robot> is never replaced",
    )
    g.add_argument(
        "--lock",
        nargs="+",
        type=lock_arg,
        default=[],
        metavar="JOINT[=VALUE]",
        help="hold joints fixed (value in rad or m, default 0)",
    )
    g.add_argument("--force", action="store_true", help="rebuild even if the cache matches")
    g.add_argument("--cflags", default=None, help="extra compiler flags (quoted)")
    g.add_argument(
        "--period",
        type=number_type(float, 0.0, False, "pass the log's sampling interval, e.g. 0.0333"),
        default=None,
        metavar="T",
        help="generate at this sampling interval [s] instead of the robot's T, as a library of "
        "its own (<robot>_T<us>us...), model_substeps chosen from the joint modes",
    )
    g.add_argument(
        "--substeps",
        type=number_type(
            int, 1, True, "pass --substeps 4, or omit it to choose from the modes", SUBSTEPS_MAX
        ),
        default=None,
        metavar="K",
        help="rk4 model steps per T (with --period; default: from the joint modes)",
    )


def add_check_arguments(c: argparse.ArgumentParser) -> None:
    """The arguments of ``amsfe check``."""
    add_robot_library(c)
    c.add_argument("--lock", nargs="+", type=lock_arg, default=[], metavar="JOINT[=VALUE]")
    c.add_argument("--samples", type=SAMPLES, default=50, help="random states (default 50)")
    c.add_argument("--seed", type=SEED, default=0)
    c.add_argument("--cflags", default=None, help="extra compiler flags (quoted)")


def add_simulate_arguments(s: argparse.ArgumentParser) -> None:
    """The arguments of ``amsfe simulate``."""
    s.add_argument("scenario", nargs="?", default="paper-sim", help="scenario name or .toml")
    s.add_argument(
        "--estimator", default=None, help="estimator name (an unknown name lists the known ones)"
    )
    s.add_argument(
        "--controller",
        default=None,
        help="one controller (default: the scenario's compare list, else its controller)",
    )
    s.add_argument(
        "--compare",
        default=None,
        metavar="A,B,...",
        help="controllers to compare on one seed (default: the scenario's compare list)",
    )
    s.add_argument("--seed", type=SEED, default=None)
    s.add_argument("--duration", type=DURATION, default=None, help="simulated time [s]")
    s.add_argument(
        "--out",
        default=None,
        help="run folder (default runs/<scenario>-<stamp>); an existing one is refused "
        "(docs/reference/scenarios.md, 'Output paths')",
    )
    s.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    s.add_argument("--no-plots", action="store_true", help="skip the figures")
    s.add_argument(
        "--all-plots",
        action="store_true",
        help="also an arm's sliding-variable and torque figures (drawn by default for the "
        "paper's 1- and 2-link arms)",
    )
    s.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out (and --bag) that amsfe wrote; never a folder of "
        "yours, never an input",
    )
    add_runtime(s)
    s.add_argument(
        "--bag",
        nargs="?",
        const="",
        default=None,
        metavar="DIR",
        help="also write the run as a rosbag2 in MCAP (default <run folder>/bag; "
        "docs/how-to/logs.md); "
        "DIR elsewhere is written together with the run folder, both or neither, and follows "
        "the --out rules",
    )
    s.add_argument(
        "--images",
        nargs="?",
        const="mono8",
        default=None,
        choices=("mono8", "jpeg", "png"),
        help="with --bag: the camera's frames are images of the marker (default mono8; or jpeg, "
        "png compressed) with its CameraInfo, instead of its pixel topic (docs/camera.md)",
    )
    add_set(s)
