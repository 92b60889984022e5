"""``amsfe calibrate LOG --robot ROBOT``: the camera's pose in the base, the marker's offset on
its link and the camera's time offset from a recording with camera frames and encoders, in
one batch (docs/calibrate.md; the method: :mod:`amsfe_sym.calibration`).

The log is read as ``amsfe estimate`` reads it (the same topics, topic spec and checks).  It
prints each parameter with its linearised 95 % interval, the per-frame reprojection error,
the frames dropped and why, what the motion could not determine, and writes a folder with the
calibrated ``robot.toml`` (``amsfe generate`` accepts it), ``topics.toml`` (the topic spec
with the camera's ``[camera] time_offset``, when it was fitted), ``calibration.json``,
``residuals.csv`` and ``residuals.png``.  Bad input: one line, nothing written.
"""

from __future__ import annotations

import argparse
import math
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output

if TYPE_CHECKING:  # (OpenCV, Pinocchio and scipy are imported when the command runs)
    from amsfe_sym.calibration import Calibration
    from amsfe_sym.calibration.intervals import ErrorModel
    from amsfe_sym.load.types import Robot

__all__ = [
    "CORNER_CAUTION",
    "CalibrateOptions",
    "add_arguments",
    "calibrate_command",
    "corner_caution",
    "default_out",
    "from_args",
    "report_lines",
]


@dataclass(frozen=True)
class CalibrateOptions:
    """How ``amsfe calibrate`` runs.

    Attributes:
        log_spec: Topic spec TOML (topics, joint names, effort kind), or None.
        pixel_std: Expected pixel noise [px]: the robust loss's scale before it is measured.
        max_offset: Largest |time offset| the initial scan tries [s].
        fit_time_offset: False holds the time offset at 0.
        corners: Fit the marker's 4 corners when the log has them (an image topic); False:
            the tracked point only.
        plots: Draw the figure.
        force: Replace an existing output folder that amsfe wrote.
    """

    log_spec: str | None = None
    pixel_std: float = 1.0
    max_offset: float = 0.2
    fit_time_offset: bool = True
    corners: bool = False
    plots: bool = True
    force: bool = False


def default_out(log_path: Path) -> Path:
    """``runs/calibrate-<log name>-<UTC time>``."""
    from datetime import datetime, timezone

    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"calibrate-{log_path.stem}-{stamp}"


def calibrate_command(
    log_path: Path, robot: str, out: Path, options: CalibrateOptions | None = None
) -> tuple[Calibration, Robot]:
    """Calibrate from ``log_path`` with ``robot`` (a shipped name or a ``robot.toml``) and
    write the folder ``out`` (module docstring); prints the report.

    Raises:
        LogError: the log cannot be read, has no usable frames, or its motion cannot determine
            the camera pose (one line; nothing written).
        SpecError, RunFolderError: a bad robot; an ``out`` that exists (without ``force``)
            or is an input.
    """
    from amsfe_sym.calibration import calibrate, link_angles, observations
    from amsfe_sym.calibration.spec_out import calibrated_spec, calibrated_topic_spec
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load import load_robot
    from amsfe_sym.load.spec import load_spec
    from amsfe_sym.logs.read import plan_log, read_log
    from amsfe_sym.logs.spec import read_log_spec

    opts = options or CalibrateOptions()
    log_spec = opts.log_spec
    inputs = [p for p in (log_path, log_spec) if p and Path(p).exists()]
    if log_path.is_file() and (log_path.parent / "metadata.yaml").is_file():
        inputs.append(log_path.parent)
    spec = load_spec(robot)
    if spec.spec_path is not None:
        inputs.append(spec.spec_path)
    check_output(out, option="--out", force=opts.force, inputs=inputs)
    # the frames at their header stamps: the time offset is measured from them, whatever
    # [camera] time_offset the topic spec has (the written one replaces it)
    ls = replace(read_log_spec(log_spec), camera_time_offset=0.0)
    if opts.corners and ls.marker.refinement is None:
        # the corners' own positions are fitted: refined from the marker's edges, which
        # OpenCV's cornerSubPix puts 0.15-0.5 px inside (docs/camera.md, "The corners")
        ls = replace(ls, marker=replace(ls.marker, refinement="edges"))
    joints = modelled_joints(spec) or []
    n_state = 4 * len(joints) + len(spec.theta)
    plan = plan_log(log_path, ls, joints)
    log = read_log(log_path, ls, joints, spec.model.T, n_state, plan, robot=spec.name)
    rob = load_robot(spec)
    links = link_angles(
        log, rob.stiffness_at(rob.theta_true), rob.Mm, rob.Fm, positions=ls.positions
    )
    obs = observations(log, ls.marker.size, corners=opts.corners)
    print(
        f"calibrate {log_path} with {spec.name}: {obs.m} camera frames, {log.K} encoder ticks "
        f"({log.K * log.T:.1f} s)"
    )
    if obs.corners is not None:
        print(
            f"  fit: the marker's 4 corners a frame (8 residuals; its side "
            f"{obs.marker_size * 1e3:g} mm, the topic spec's [marker] size) and its "
            "orientation on its link"
        )
    else:
        print("  fit: one point a frame (the tracked point)")
    print(f"  link angles: {links.note}")
    cal = calibrate(
        rob,
        links,
        obs,
        pixel_std=opts.pixel_std,
        max_offset=opts.max_offset,
        fit_time_offset=opts.fit_time_offset,
        progress=lambda s: print(f"  {s}"),
    )
    for line in report_lines(cal, rob, obs.skipped):
        print(line)
    for line in corner_caution(cal):
        print(line)
    text = calibrated_spec(rob, cal, str(log_path))
    topics = (
        calibrated_topic_spec(ls.source, cal.time_offset, str(log_path)) if cal.free[9] else None
    )

    def fill(tmp: Path) -> None:
        (tmp / "robot.toml").write_text(text)
        if topics is not None:
            (tmp / "topics.toml").write_text(topics)
        write_json(tmp / "calibration.json", _summary(cal, rob, log_path, obs.skipped))
        _write_residuals(tmp / "residuals.csv", cal)
        if opts.plots:
            _figure(tmp / "residuals.png", cal, rob)

    done = write_folder(out, fill, replace=opts.force)
    print(f"wrote {done}: robot.toml (amsfe generate {done / 'robot.toml'}), calibration.json")
    if topics is not None:
        print(
            f"  topics.toml: your topic spec with [camera] time_offset = "
            f"{round(cal.time_offset, 6):g} (amsfe estimate {log_path} --robot "
            f"{done / 'robot.toml'} --log-spec {done / 'topics.toml'})"
        )
    return cal, rob


def _rotation_error_deg(R_a: Any, R_b: Any) -> float:
    """The angle [deg] of the rotation between two rotation matrices."""
    c = (float(np.trace(np.asarray(R_a) @ np.asarray(R_b).T)) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def report_lines(cal: Calibration, robot: Robot, reader_skipped: dict[str, int]) -> list[str]:
    """What ``amsfe calibrate`` prints after the fit: parameters with intervals, the
    reprojection error per frame, the dropped frames by reason, what was held and why."""
    from amsfe_sym.load.rotation import matrix_to_quaternion

    hw = cal.half_width95()
    out = ["  parameter                  value        95 % interval (linearised)"]

    def row(label: str, k: int, scale: float, unit: str, value: float, digits: int) -> str:
        if not cal.free[k]:
            return f"  {label:<24} {value * scale:>+12.{digits}f} {unit:<4} held (see below)"
        return (
            f"  {label:<24} {value * scale:>+12.{digits}f} {unit:<4} "
            f"+- {hw[k] * scale:.{digits}f} {unit}"
        )

    for i, axis in enumerate("xyz"):
        out.append(row(f"camera position {axis}", 3 + i, 1e3, "mm", cal.position[i], 2))
    q = matrix_to_quaternion(cal.R_cw.T)
    out.append(f"  camera orientation       [{', '.join(f'{v:+.6f}' for v in q)}] (qx qy qz qw)")
    rot = ", ".join(f"{hw[i] * 180 / math.pi:.3f}" for i in range(3))
    out.append(f"    its rotation: +- {rot} deg about the camera's x, y, z axes")
    for i, axis in enumerate("xyz"):
        out.append(row(f"marker offset {axis}", 6 + i, 1e3, "mm", cal.offset[i], 2))
    out.append(row("time offset", 9, 1e3, "ms", cal.time_offset, 2))
    if cal.marker_R is not None:
        qm = matrix_to_quaternion(cal.marker_R)
        out.append(
            f"  marker orientation       [{', '.join(f'{v:+.6f}' for v in qm)}] (qx qy qz qw)"
        )
        if cal.free[10]:
            mr = ", ".join(f"{hw[i] * 180 / math.pi:.3f}" for i in range(10, 13))
            out.append(f"    its rotation: +- {mr} deg about the tracked frame's x, y, z axes")
        else:
            out.append("    held at the start's (see below)")
    moved = float(np.linalg.norm(cal.position - robot.camera.position))
    turned = _rotation_error_deg(cal.R_cw, robot.camera.R_cw)
    out.append(
        f"  (the spec's camera moved {moved * 1e3:.1f} mm and turned {turned:.3f} deg; "
        f"the marker moved {np.linalg.norm(cal.offset - robot.tracked_offset) * 1e3:.1f} mm; "
        "its rotation's interval is about the calibrated camera's axes)"
    )
    e = cal.frame_errors()
    out.append(
        f"  reprojection error per frame: median {np.median(e):.2f} px, "
        f"p95 {np.percentile(e, 95):.2f} px, max {e.max():.2f} px over {e.size} frames; "
        f"pixel noise {cal.pixel_std:.3f} px per axis"
    )
    reasons = Counter(cal.dropped.values())
    if reasons or reader_skipped:
        out.append("  frames dropped:")
        for why, count in sorted(reader_skipped.items()):
            out.append(f"    {count:>6}  {why} (log reader)")
        for why, count in sorted(reasons.items()):
            out.append(f"    {count:>6}  {why}")
    else:
        out.append("  frames dropped: none")
    names = {
        "time_offset": "the time offset",
        "offset": "the marker offset",
        "marker_rotation": "the marker orientation",
    }
    for group, why in cal.held.items():
        out.append(f"  cannot determine {names.get(group, group)}: {why}")
    return out


#: Printed after a corner fit of a recording (many frames, the sandwich's intervals): on
#: rendered recordings its intervals held the truth 109 times in 156, the detector's corners
#: carrying a lean that frames share (docs/calibrate.md, "Which fit runs").
CORNER_CAUTION = (
    "  caution: a corner fit's intervals understate its error on images: the detected "
    "corners carry a small error that frames share (on rendered recordings they held the "
    'truth 70 % of the time; the centre fit\'s, 97 %: docs/calibrate.md, "Which fit runs")'
)


def corner_caution(cal: Calibration) -> list[str]:
    """:data:`CORNER_CAUTION` after a corner fit whose intervals come from the sandwich (a
    recording: many frames), for the corners a detector found in images (what ``amsfe
    calibrate --corners`` fits); nothing after a centre fit or a few poses' block model (on
    ViSP's 8 real frames the corner fit's intervals held ViSP's result on 9 of 9 axes)."""
    sandwich = cal.errors is not None and cal.errors.kind == "sandwich"
    return [CORNER_CAUTION] if cal.fit == "corners" and sandwich else []


def _error_model(errors: ErrorModel | None) -> dict[str, Any] | None:
    """What ``calibration.json`` says of the intervals' error model (its ``kind``, the
    sandwich's bandwidth [frames], the block model's variances [px^2]) and the report's line."""
    from amsfe_sym.calibration.solve import describe_errors

    if errors is None:
        return None
    return {
        "kind": errors.kind,
        "bandwidth_frames": errors.bandwidth if errors.kind == "sandwich" else None,
        "sigma_px": float(np.sqrt(errors.sigma2)),
        "shift_sigma_px": float(np.sqrt(errors.tau2)) if errors.kind == "block" else None,
        "description": describe_errors(errors),
    }


def _summary(
    cal: Calibration, robot: Robot, log_path: Path, reader_skipped: dict[str, int]
) -> dict[str, Any]:
    """``calibration.json``: every parameter with its 1-sigma and 95 % half-width (null where
    held), the pose, the errors per frame, the dropped frames and what was held."""
    from amsfe_sym.calibration.solve import Z95
    from amsfe_sym.load.rotation import matrix_to_quaternion

    e = cal.frame_errors()
    hw = cal.half_width95()

    def num(v: float) -> float | None:
        return None if not np.isfinite(v) else float(v)

    return {
        "log": str(log_path),
        "robot": robot.name,
        "parameters": {
            name: {
                "value": float(cal.x[k]),
                "std": num(cal.std[k]),
                "half_width_95": num(hw[k]),
                "std_white": num(cal.std_white[k]),
                "fitted": bool(cal.free[k]),
            }
            for k, name in enumerate(cal.names)
        },
        "fit": cal.fit,
        "marker_orientation": None
        if cal.marker_R is None
        else matrix_to_quaternion(cal.marker_R).tolist(),
        "interval": f"linearised: +-{Z95:.3f} sigma, sigma^2 from the sandwich "
        "(J^T J)^-1 M (J^T J)^-1 at the solution (error_model: what M takes the pixel errors "
        "to be); std_white: the same with M = s^2 J^T J, independent pixel errors",
        "error_model": _error_model(cal.errors),
        "camera": {
            "position": cal.position.tolist(),
            "orientation": matrix_to_quaternion(cal.R_cw.T).tolist(),
            "R_cw": cal.R_cw.tolist(),
        },
        "tracked_offset": cal.offset.tolist(),
        "time_offset_s": cal.time_offset,
        "time_offset_meaning": "header stamp - exposure time [s]",
        "pixel_std": cal.pixel_std,
        "reprojection_px": {
            "median": float(np.median(e)),
            "p95": float(np.percentile(e, 95)),
            "max": float(e.max()),
            "frames": int(e.size),
        },
        "dropped": dict(Counter(cal.dropped.values())),
        "dropped_by_reader": dict(reader_skipped),
        "held": dict(cal.held),
        "initial_guess": {
            "position": cal.initial.position.tolist(),
            "orientation": matrix_to_quaternion(cal.initial.R_cw.T).tolist(),
            "time_offset_s": cal.initial.time_offset,
            "rms_px": cal.initial.rms,
        },
        "singular_values_scaled": cal.singular_values.tolist(),
        "correlation": {
            "parameters": list(cal.names),
            "matrix": [[num(round(float(v), 4)) for v in row] for row in cal.correlation],
        },
    }


def _write_residuals(path: Path, cal: Calibration) -> None:
    """One row per frame: stamp [s], pixel u, v, residual du, dv [px] (the corner fit: of
    each corner k, ``u<k>_px`` ...), used, why dropped."""
    P = cal.pixel.shape[1] // 2
    tags = [""] if P == 1 else [str(k) for k in range(P)]
    cols = [f"u{t}_px,v{t}_px" for t in tags] + [f"du{t}_px,dv{t}_px" for t in tags]
    lines = ["stamp_s," + ",".join(cols) + ",used,dropped"]
    for i in range(cal.stamp.size):
        why = cal.dropped.get(i, "").replace(",", ";")
        pix = ",".join(f"{v:.4f}" for v in cal.pixel[i])
        res = ",".join(f"{v:.5f}" for v in cal.residual[i])
        lines.append(f"{cal.stamp[i]:.6f},{pix},{res},{int(cal.used[i])},{why}")
    path.write_text("\n".join(lines) + "\n")


def _figure(path: Path, cal: Calibration, robot: Robot) -> None:
    """Residuals over time, and in the image (each frame's residual as an arrow, x20)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    u = cal.used
    P = cal.pixel.shape[1] // 2
    t, r = np.repeat(cal.stamp, P), cal.residual.reshape(-1, 2)  # (one row a point)
    p = cal.pixel.reshape(-1, 2)
    u = np.repeat(cal.used, P)
    a.plot(t[u], r[u, 0], ".", ms=2, label="u")
    a.plot(t[u], r[u, 1], ".", ms=2, label="v")
    bad = ~u & np.isfinite(r).all(axis=1)
    if bad.any():
        a.plot(t[bad], r[bad, 0], "x", color="red", label="dropped (u)")
    a.set_xlabel("exposure stamp [s]")
    a.set_ylabel("reprojection residual [px]")
    a.set_title(f"residuals over time (pixel noise {cal.pixel_std:.2f} px)")
    a.legend(loc="upper right")
    a.grid(True, alpha=0.3)
    b.quiver(p[u, 0], p[u, 1], 20 * r[u, 0], 20 * r[u, 1], angles="xy", scale_units="xy", scale=1)
    b.set_xlim(0, robot.camera.width)
    b.set_ylim(robot.camera.height, 0)
    b.set_aspect("equal")
    b.set_xlabel("u [px]")
    b.set_ylabel("v [px]")
    b.set_title("residuals in the image (x20)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``amsfe calibrate``."""
    p.add_argument("log", help="a ROS 1 .bag, a rosbag2 folder or an .mcap file")
    p.add_argument("--robot", required=True, help="the robot (name or robot.toml)")
    p.add_argument(
        "--out", default=None, help="output folder (default runs/calibrate-<log>-<stamp>)"
    )
    p.add_argument("--log-spec", default=None, metavar="FILE", help="topic spec (TOML)")
    p.add_argument(
        "--pixel-std",
        type=float,
        default=1.0,
        help="expected pixel noise [px]: the robust loss's scale before it is measured",
    )
    p.add_argument(
        "--max-time-offset",
        type=float,
        default=0.2,
        help="largest |time offset| the initial scan tries [s]",
    )
    p.add_argument(
        "--no-time-offset", action="store_true", help="hold the time offset at 0 (do not fit it)"
    )
    p.add_argument(
        "--corners",
        action="store_true",
        help="fit the marker's 4 corners a frame (images only), its orientation on the link "
        "too: for a few frames whose centres leave the camera's rotation undetermined "
        "(docs/calibrate.md: the detector's corners carry a bias the centre does not)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the figure")
    p.add_argument("--force", action="store_true", help="replace an --out that amsfe wrote")


def from_args(args: argparse.Namespace) -> int:
    """``amsfe calibrate`` from its parsed options."""
    from amsfe_sym.errors import ConfigError, describe

    log = Path(args.log)
    if not (math.isfinite(args.pixel_std) and args.pixel_std > 0):
        raise ConfigError(
            describe(
                "--pixel-std",
                "a number > 0 [px]",
                str(args.pixel_std),
                "give the detection noise in px",
            )
        )
    if not (math.isfinite(args.max_time_offset) and args.max_time_offset >= 0):
        raise ConfigError(
            describe(
                "--max-time-offset",
                "a number >= 0 [s]",
                str(args.max_time_offset),
                "give the largest camera delay to search, in s (default 0.2)",
            )
        )
    out = Path(args.out) if args.out else default_out(log)
    options = CalibrateOptions(
        log_spec=args.log_spec,
        pixel_std=args.pixel_std,
        max_offset=args.max_time_offset,
        fit_time_offset=not args.no_time_offset,
        corners=args.corners,
        plots=not args.no_plots,
        force=args.force,
    )
    calibrate_command(log, args.robot, out, options)
    return 0
