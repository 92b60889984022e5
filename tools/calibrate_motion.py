"""What a calibration motion can give, before recording it (docs/calibrate.md, "What the motion
must do").

For a scenario's desired motion (``[trajectory]``, the arm assumed to follow it), its robot's
camera and a pixel noise: the frames the camera would take (one every ``[camera] period``
ticks), which of them see the marker in the image, and the 95 % half-widths that ``amsfe
calibrate`` would state for each parameter, ``1.96 sigma`` from the Fisher information
``J^T J / pixel_std^2`` of the same reprojection map and exact jacobian
(:class:`amsfe_sym.calibration.ReprojectionModel`) at the camera's pose, without the
encoder noise, the spring's deflection or the plant's disturbances (the fit's stated
intervals on simulated recordings are within a few % of these: the "Accuracy" section).
From the same covariance, the share of recordings whose camera position would miss 2 mm,
its rotation 0.1 deg, the marker offset 1 mm (the issue's bounds), the errors drawn as
Gaussian (``MotionInformation.beyond``, 200 000 draws: it resolves no share below ~1e-5),
and the same shares by quadrature (``miss_probability``, :func:`norm_tail`),
with the time offset's 1 ms.  Also the motion's reach: the marker's depth range
[m], the joint ranges [rad] against the URDF's limits, the largest joint speed [rad/s], the
marker's lowest height [m].

    PYTHONPATH=src .venv/bin/python tools/calibrate_motion.py           # calib-sim.toml
    PYTHONPATH=src .venv/bin/python tools/calibrate_motion.py \\
        --set trajectory.amplitude=1.2,0.5,0.8 --set trajectory.omega=1.3,2.1,2.9 \\
        --set trajectory.phase=0,0,0 --set trajectory.offset=0,0.5,0.8     # the sweep before it
    PYTHONPATH=src .venv/bin/python tools/calibrate_motion.py \\
        --robot tests/data/calibrate/robot-near.toml        # the camera closer (its comment)
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent.parent / "tests" / "data" / "calibrate"
#: The issue's bounds: camera position [mm], rotation [deg], marker offset [mm].
BOUNDS = {"position_mm": 2.0, "rotation_deg": 0.1, "offset_mm": 1.0}
#: The issue's bound on the time offset [ms].
TIME_BOUND_MS = 1.0


def norm_tail(cov: np.ndarray, radius: float, nodes: int = 2001) -> float:
    """``P(|e| > radius)`` for ``e ~ N(0, cov)`` in 3 dimensions (``cov`` (3, 3), ``radius``
    in its units), by quadrature: along the widest principal axis exactly (``erfc``), over
    the other two on a grid of ``nodes`` points per axis within +-12 sigma.  Relative error
    below 1e-4 down to shares of 1e-8 (checked against the chi-square tail for equal axes
    and against 2e7 draws for unequal ones), where 200 000 draws resolve nothing below ~1e-5."""
    from scipy.special import erfc

    lam = np.clip(np.linalg.eigvalsh(cov), 0.0, None)  # ascending: lam[2] the widest
    z = np.linspace(-12.0, 12.0, nodes)
    w = np.exp(-0.5 * z**2) * (z[1] - z[0]) / math.sqrt(2 * math.pi)
    z1, z2 = np.meshgrid(z, z, indexing="ij")
    rest = radius**2 - lam[0] * z1**2 - lam[1] * z2**2  # what the widest axis must exceed
    tail = np.where(rest > 0, erfc(np.sqrt(np.clip(rest, 0, None) / (2 * lam[2]))), 1.0)
    return float(w @ tail @ w)


def motion_report(
    scenario: Path, sets: list[str], pixel_std: float | None = None, robot_spec: Path | None = None
) -> dict[str, Any]:
    """The predicted intervals and reach of ``scenario``'s motion (module docstring), with
    ``robot_spec`` (a robot spec) instead of the scenario's if given."""
    from scipy.special import erfc

    from amsfe_sym.calibration import PARAMETERS, LinkAngles
    from amsfe_sym.calibration.design import motion_information
    from amsfe_sym.load import load_robot
    from amsfe_sym.scenario.overrides import apply_sets
    from amsfe_sym.scenario.read import load_scenario
    from amsfe_sym.signals.trajectory import from_config

    sc = apply_sets(load_scenario(scenario), sets)
    robot_path = Path(sc.robot)
    if robot_spec is None and not robot_path.is_absolute():
        robot_path = scenario.parent / robot_path  # (the scenario's: beside it)
    robot = load_robot(robot_path if robot_spec is None else robot_spec)
    T, period = robot.spec.model.T, robot.camera.period
    sigma = float(sc.camera.pixel_std if pixel_std is None else pixel_std)
    ticks = round(sc.duration / T) + 1
    q, qd, _ = from_config(sc.trajectory).evaluate(np.arange(ticks + 1) * T)
    stamp = np.arange(period, ticks - 1, period) * T
    info = motion_information(robot, LinkAngles(T, q, "planned"), stamp, sigma)
    C, seen = info.covariance, info.seen
    unit = [180 / math.pi] * 3 + [1e3] * 6 + [1e3]  # deg, mm, ms
    half = info.half_width95()
    b = BOUNDS
    beyond = info.beyond(
        b["position_mm"] * 1e-3,
        math.radians(b["rotation_deg"]),
        b["offset_mm"] * 1e-3,
        np.random.default_rng(0),
    )
    miss = {
        k: norm_tail(C[sl, sl], b[k] * u)
        for k, sl, u in zip(
            BOUNDS,
            (slice(3, 6), slice(0, 3), slice(6, 9)),
            (1e-3, math.pi / 180, 1e-3),
            strict=True,
        )
    }
    miss["time_offset_ms"] = float(erfc(TIME_BOUND_MS * 1e-3 / math.sqrt(2 * C[9, 9])))
    corr = np.triu(info.correlation(), 1)
    strongest = np.argsort(-np.abs(corr), axis=None)[:3]
    lower = [robot.model.lowerPositionLimit[j.idx_q] for j in robot.joints]
    upper = [robot.model.upperPositionLimit[j.idx_q] for j in robot.joints]
    extra = [] if robot_spec is None else [f"--robot {robot_spec}"]
    return {
        "command": " ".join(["tools/calibrate_motion.py", *extra, *[f"--set {s}" for s in sets]]),
        "trajectory": dict(sc.trajectory),
        "duration_s": sc.duration,
        "pixel_std_px": sigma,
        "frames": int(stamp.size),
        "frames_in_view": int(seen.sum()),
        "depth_m": [float(info.depth[seen].min()), float(info.depth[seen].max())],
        "joint_range_rad": [[float(a), float(b)] for a, b in zip(q.min(0), q.max(0), strict=True)],
        "joint_limits_rad": [[float(a), float(b)] for a, b in zip(lower, upper, strict=True)],
        "max_speed_rad_s": [float(v) for v in np.abs(qd).max(0)],
        "lowest_marker_m": float(info.marker[seen][:, 2].min()),
        "half_width_95": {n: float(half[k] * unit[k]) for k, n in enumerate(PARAMETERS)},
        "position_rms_mm": float(math.sqrt(np.trace(C[3:6, 3:6])) * 1e3),
        "rotation_rms_deg": float(math.degrees(math.sqrt(np.trace(C[0:3, 0:3])))),
        "offset_rms_mm": float(math.sqrt(np.trace(C[6:9, 6:9])) * 1e3),
        "beyond_bound": dict(zip(BOUNDS, beyond, strict=True)),
        "miss_probability": miss,
        "strongest_correlations": [
            [PARAMETERS[k // len(PARAMETERS)], PARAMETERS[k % len(PARAMETERS)], float(corr.flat[k])]
            for k in strongest
        ],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenario", nargs="?", default=str(HERE / "calib-sim.toml"))
    ap.add_argument("--set", action="append", default=[], help="scenario KEY=VALUE override")
    ap.add_argument("--robot", default=None, help="robot spec instead of the scenario's")
    ap.add_argument("--pixel-std", type=float, default=None, help="[px] (the scenario's)")
    ap.add_argument("--out", default=None, help="JSON file to write")
    args = ap.parse_args(argv)
    robot = None if args.robot is None else Path(args.robot)
    result = motion_report(Path(args.scenario), args.set, args.pixel_std, robot)
    text = json.dumps(result, indent=1)
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
