"""The marker seen obliquely (docs/camera.md, "The simulated camera's images"): how often the
detector finds a marker fixed to its link, and how far its corners and centre are from the
true projections, by the angle between the marker's face and its line of sight.

calib_arm's camera (640 x 480, f = 500 px, tests/data/calibrate/robot.toml) with the
simulated camera's lens (plumb_bob), blur (0.8 px) and noise (4 grey levels); a 10 cm marker
at a random pixel at each distance, tilted by the angle about a random axis in its plane and
turned in it at random.  Per (distance, angle): the frames found, the worst corner's error
per frame (median, p90, worst) and the centre's RMS error [px], after undistortion.  Also the
smallest face-on markers the detector finds (the area under which the renderer does not draw
one: vision/marker_pose.py MIN_AREA_PX2).

    PYTHONPATH=src .venv/bin/python tools/marker_view_accuracy.py [--frames 30] \\
        [--out docs/data/marker-view-accuracy.json]

``--bias FRAMES``: the corner refinements compared (docs/camera.md, "Accuracy"): per blur
(0.5, 0.8, 1.2, 1.5 px), marker side (~200, 100, 50, 25 px: 0.25-2 m) and angle (0, 30, 60
deg), FRAMES renders (noise 4 grey levels), each detected with OpenCV's ``subpix``,
``contour`` and ``apriltag`` refinements and the edge fit (``edges``: a parabola per edge
in the raw image, as the log reader runs it; ``edges+info``: a line per edge in the
undistorted image, the detector given the CameraInfo).  Per method: the corners' mean signed
error along the marker's outward diagonal (its bias: negative = inside) and their RMS error
[px] against the renderer's exact corners, after undistortion::

    PYTHONPATH=src .venv/bin/python tools/marker_view_accuracy.py --bias 12 \\
        --out docs/data/marker-corner-bias.json

``--recording SEED``: the views of a calibration recording (tools/calibrate_seeds.py's true
calib_arm of ``--truth-seed`` SEED with the marker fixed to its tip,
tests/data/calibrate/robot-marker.toml, simulated with images at seed SEED): every frame's
exact corners (the renderer's), each view rendered ``--renders`` times (fresh noise) and
detected ungated with ``subpix``, ``edges`` (a curve per edge in the raw image), ``edges
unbent`` (those corners less the raw-image lines' error, vision.edges.unbend: what the log
reader uses) and ``edges+info`` (a line per edge in the undistorted image); per method
the centre's error (detected minus exact, after undistortion) [px]: over the frames
foreshortened under 40-60 deg (what ``[marker] max_foreshortening_deg`` keeps) its mean, its
spread and the mean over its standard error; per view (noise averaged) by foreshortening
[deg] and side [px], and by the image direction of the tilt::

    PYTHONPATH=src .venv/bin/python tools/marker_view_accuracy.py --recording 31652 \\
        --renders 2 --out docs/data/marker-recording-views.json

``--robot R`` draws the truth from another typed spec, e.g. the camera at 0.74 m
(docs/calibrate.md, "With the camera closer: margin")::

    PYTHONPATH=src .venv/bin/python tools/marker_view_accuracy.py --recording 32105 \\
        --renders 2 --robot tests/data/calibrate/robot-marker-near.toml \\
        --out docs/data/marker-recording-views-near.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from amsfe_sym.vision.camera_info import make_camera_info, undistort
from amsfe_sym.vision.detections import undistorted_corners
from amsfe_sym.vision.marker import (
    MarkerDetector,
    diagonals_meet,
    foreshortening,
    marker_axes,
)
from amsfe_sym.vision.marker_pose import marker_view
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer
from amsfe_sym.vision.sim_images import LENSES
from amsfe_sym.vision.spec import MarkerSpec

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
FACING = np.diag([1.0, -1.0, -1.0])  # the marker's frame facing a camera at the origin


def cell(renderer, detector, info, dist: float, deg: float, frames: int, rng) -> dict:
    """One (distance [m], angle [deg]) cell: ``frames`` renders, detected."""
    found, worst, centre, areas = 0, [], [], []
    for _ in range(frames):
        pixel = rng.uniform([100.0, 100.0], [540.0, 380.0])
        p = np.append((pixel - K[:2, 2]) / K[0, 0], 1.0) * dist
        axis = np.append(rng.normal(size=2), 0.0)
        tilt = cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(deg))[0]
        spin = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))[0]
        I3 = np.eye(3)
        view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), tilt @ FACING @ spin, 0.1)
        areas.append(view.area_px2)
        det = detector.detect(renderer.render(view.corners, rng, foreshortened=True))
        if det.corners is None:
            continue
        found += 1
        und = undistort(info, det.corners)
        worst.append(float(np.linalg.norm(und - view.corners, axis=1).max()))
        centre.append(float(np.linalg.norm(diagonals_meet(und) - diagonals_meet(view.corners))))
    w = np.array(worst) if worst else np.array([np.nan])
    return {
        "distance_m": dist,
        "angle_deg": deg,
        "area_px2_median": float(np.median(areas)),
        "found": f"{found} / {frames}",
        "corner_worst_px": {
            "median": float(np.median(w)),
            "p90": float(np.percentile(w, 90)),
            "worst": float(w.max()),
        },
        "centre_rms_px": float(np.sqrt(np.mean(np.square(centre)))) if centre else None,
    }


METHODS = ("subpix", "contour", "apriltag", "edges", "edges+info")


def placed(dist: float, deg: float, rng: np.random.Generator):
    """A 10 cm marker's view at ``dist`` [m], tilted ``deg`` [deg] about a random axis in its
    plane, turned at random, at a random pixel with 1.4x its extent inside the image."""
    I3 = np.eye(3)
    while True:
        pixel = rng.uniform([60.0, 60.0], [580.0, 420.0])
        p = np.append((pixel - K[:2, 2]) / K[0, 0], 1.0) * dist
        axis = np.append(rng.normal(size=2), 0.0)
        tilt = cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(deg))[0]
        spin = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))[0]
        view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), tilt @ FACING @ spin, 0.1)
        c = view.corners
        wide = c.mean(axis=0) + 1.4 * (c - c.mean(axis=0))
        if (wide.min(axis=0) > 5).all() and (wide.max(axis=0) < [635.0, 475.0]).all():
            return view


def summary(signed: list[float], norm: list[float]) -> dict:
    """Bias (mean signed error along the outward diagonal, its standard error) and RMS [px]."""
    s, n = np.array(signed), np.array(norm)
    if not s.size:
        return {"corners": 0}
    return {
        "corners": int(s.size),
        "bias_px": float(s.mean()),
        "bias_se_px": float(s.std(ddof=1) / math.sqrt(s.size)) if s.size > 1 else None,
        "rms_px": float(np.sqrt(np.mean(n**2))),
        "p90_px": float(np.percentile(n, 90)),
    }


def bias_study(info, frames: int, rng: np.random.Generator) -> dict:
    """The corner refinements on the same renders (module docstring, ``--bias``)."""
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)  # (every view: none gated)
    detectors = {m: MarkerDetector(spec, refinement=m) for m in METHODS[:-1]}
    detectors["edges+info"] = MarkerDetector(spec, refinement="edges", info=info)
    cells, total = [], {m: ([], []) for m in METHODS}
    by_blur: dict[float, dict] = {}
    for blur in (0.5, 0.8, 1.2, 1.5):
        renderer = MarkerRenderer(info, spec, ImageNoise(blur_px=blur))
        by_blur[blur] = {m: ([], []) for m in METHODS}
        for dist in (0.25, 0.5, 1.0, 2.0):
            for deg in (0, 30, 60):
                got = {m: ([], []) for m in METHODS}
                for _ in range(frames):
                    view = placed(dist, deg, rng)
                    img = renderer.render(view.corners, rng, foreshortened=True)
                    out = view.corners - view.corners.mean(axis=0)
                    out /= np.linalg.norm(out, axis=1)[:, None]
                    for m, det in detectors.items():
                        c = det.detect(img).corners
                        if c is None:
                            continue
                        e = undistort(info, c) - view.corners
                        for into in (got[m], total[m], by_blur[blur][m]):
                            into[0].extend(np.einsum("ij,ij->i", e, out).tolist())
                            into[1].extend(np.linalg.norm(e, axis=1).tolist())
                row = {"blur_px": blur, "side_px": 50.0 / dist, "angle_deg": deg}
                row.update({m: summary(*got[m]) for m in METHODS})
                cells.append(row)
                print(
                    f"blur {blur:.1f} side {50 / dist:4.0f} px {deg:2d} deg  "
                    + "  ".join(
                        f"{m} {row[m].get('bias_px', float('nan')):+.3f}"
                        f"/{row[m].get('rms_px', float('nan')):.3f}"
                        for m in METHODS
                    ),
                    flush=True,
                )
    return {
        "all": {m: summary(*total[m]) for m in METHODS},
        "by_blur": {str(b): {m: summary(*v[m]) for m in METHODS} for b, v in by_blur.items()},
        "cells": cells,
    }


def recording_views(seed: int, robot: Path | None = None) -> tuple[list[np.ndarray], object]:
    """The exact corners (4, 2) [px, pinhole image] of every frame the simulated camera drew
    in a calibration recording (the true calib_arm of truth seed ``seed``, the marker fixed to
    its tip, simulated at seed ``seed``; tools/calibrate_seeds.py), and the camera's
    CameraInfo.  ``robot``: the typed spec the truth is drawn from (None:
    tests/data/calibrate/robot-marker.toml)."""
    import os
    import shutil
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from calibrate_seeds import HERE, true_robot

    from amsfe_sym.apps.cli import main as amsfe
    from amsfe_sym.vision import sim_images

    work = Path(tempfile.mkdtemp(prefix="marker-views-"))
    os.environ["AMSFE_GENERATED_DIR"] = str(work / "generated")
    typed = robot.resolve() if robot is not None else HERE / "robot-marker.toml"
    truth = true_robot(work / "true", seed, f"calib_arm_views_{seed}", typed)
    views: list[np.ndarray] = []
    infos: list[object] = []
    original = sim_images.SimulatedCamera.corners

    def corners(self, q, theta):  # the exact corners of each drawn frame, kept
        c = original(self, q, theta)
        if c is not None:
            views.append(np.array(c, dtype=np.float64))
            infos[:] = [self.info]
        return c

    sim_images.SimulatedCamera.corners = corners  # type: ignore[method-assign]
    try:
        sim = ["simulate", str(truth.parent / "calib-sim.toml"), "--controller", "truth-ct"]
        sim += ["--out", str(work / "run"), "--bag", "--images", "mono8", "--no-plots"]
        sim += ["--no-progress", "--seed", str(seed), "--set", "camera.stamp_offset=0.025"]
        if amsfe(sim) != 0:
            raise SystemExit(f"simulate failed for seed {seed}")
    finally:
        sim_images.SimulatedCamera.corners = original  # type: ignore[method-assign]
        shutil.rmtree(work, ignore_errors=True)
    return views, infos[0]


def view_geometry(c: np.ndarray) -> dict:
    """A view's side [px] (mean edge), foreshortening [deg] (vision.marker.foreshortening),
    the image direction of the tilt [deg, 0-180: the axis along which the marker is
    compressed] and the image vectors of the marker's x and y per side (2, 2) (columns)."""
    A = marker_axes(c)
    U = np.linalg.svd(A)[0]
    return {
        "side": float(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1).mean()),
        "angle": foreshortening(c),
        "tilt_dir": math.degrees(math.atan2(U[1, 1], U[0, 1])) % 180.0,
        "A": A,
    }


def _mean_row(e: np.ndarray, **key: object) -> dict:
    """The mean of errors ``e`` (N, 2) [px], their spread and the mean over its standard
    error (per axis), under the labels ``key``."""
    mean, std = e.mean(axis=0), e.std(axis=0, ddof=1)
    return {
        **key,
        "n": len(e),
        "mean_px": mean.round(4).tolist(),
        "std_px": std.round(4).tolist(),
        "mean_over_se": (mean / std * math.sqrt(len(e))).round(2).tolist(),
    }


RECORDING_METHODS = ("subpix", "edges", "edges unbent", "edges+info")


def recording_study(
    seed: int, renders: int, rng: np.random.Generator, robot: Path | None = None
) -> dict:
    """The centre's error over a recording's views (module docstring, ``--recording``)."""
    views, info = recording_views(seed, robot)
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)  # (every view: none gated)
    detectors = {m: MarkerDetector(spec, refinement=m) for m in RECORDING_METHODS[:2]}
    detectors["edges+info"] = MarkerDetector(spec, refinement="edges", info=info)
    edges_spec = replace(spec, refinement="edges")
    renderer = MarkerRenderer(info, spec, ImageNoise())
    geo = [view_geometry(c) for c in views]
    err = {m: np.full((len(views), renders, 2), np.nan) for m in RECORDING_METHODS}
    for i, c in enumerate(views):
        truth = diagonals_meet(c)
        for r in range(renders):
            img = renderer.render(c, rng, foreshortened=True)
            for m, det in detectors.items():
                found = det.detect(img).corners
                if found is not None:
                    err[m][i, r] = diagonals_meet(undistort(info, found)) - truth
                if found is not None and m == "edges":  # (the log reader's: unbent)
                    und = undistorted_corners(info, found, edges_spec)[0]
                    err["edges unbent"][i, r] = diagonals_meet(und) - truth
    side = np.array([g["side"] for g in geo])
    angle = np.array([g["angle"] for g in geo])
    tilt = np.array([g["tilt_dir"] for g in geo])
    out: dict = {
        "seed": seed,
        "views": len(views),
        "renders": renders,
        "side_px": [float(side.min()), float(np.median(side)), float(side.max())],
        "foreshortening_deg": [float(np.median(angle)), float(np.percentile(angle, 90)),
                               float(angle.max())],
    }  # fmt: skip
    for m in RECORDING_METHODS:
        per_view = np.nanmean(err[m], axis=1)  # (views, 2): the view's own error
        ok = np.isfinite(per_view).all(axis=1)
        bins = []
        for lo, hi in ((0, 30), (30, 50), (50, 60), (60, 70), (70, 90)):
            for slo, shi in ((0, 35), (35, 50), (50, 1000)):
                sel = ok & (angle >= lo) & (angle < hi) & (side >= slo) & (side < shi)
                if sel.sum() >= 5:
                    bins.append(_mean_row(per_view[sel], deg=[lo, hi], side_px=[slo, shi]))
        dirs = [
            _mean_row(per_view[sel], tilt_dir_deg=[lo, lo + 45])
            for lo in range(0, 180, 45)
            if (sel := ok & (angle >= 50) & (tilt >= lo) & (tilt < lo + 45)).sum() >= 5
        ]
        gates = []
        for cut in (40, 45, 50, 55, 60, 90):
            one = err[m][angle < cut].reshape(-1, 2)
            gates.append(_mean_row(one[np.isfinite(one).all(axis=1)], under_deg=cut))
        out[m] = {
            "found": f"{int(np.isfinite(err[m][..., 0]).sum())} / {len(views) * renders}",
            "per_view": _mean_row(per_view[ok]),
            "gated_frames": gates,
            "views_by_foreshortening_side": bins,
            "views_over_50deg_by_tilt_direction": dirs,
        }
        print(f"{m}: {out[m]['found']} found; frames under a foreshortening of N deg:")
        for row in (*gates, *bins, *dirs):
            print(f"    {row}", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--out", default=None, help="JSON file to write")
    ap.add_argument("--bias", type=int, default=0, help="the refinements compared, frames a cell")
    ap.add_argument("--recording", type=int, default=None, help="a calibration recording's views")
    ap.add_argument("--renders", type=int, default=4, help="--recording: renders a view")
    ap.add_argument(
        "--robot", default=None,
        help="--recording: the typed robot spec (default tests/data/calibrate/robot-marker.toml)",
    )  # fmt: skip
    args = ap.parse_args(argv)
    if args.recording is not None:
        robot = Path(args.robot) if args.robot else None
        result = recording_study(args.recording, args.renders, np.random.default_rng(7), robot)
        if args.out:
            given = sys.argv[1:] if argv is None else argv
            result = {"command": "tools/marker_view_accuracy.py " + " ".join(given), **result}
            Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
        return 0
    model, D = LENSES["plumb_bob"]
    info = make_camera_info(640, 480, model, K, D)
    if args.bias:
        result = bias_study(info, args.bias, np.random.default_rng(5))
        for m, r in result["all"].items():
            print(
                f"{m:>10}: bias {r['bias_px']:+.3f} +- {r['bias_se_px']:.3f} px, RMS"
                f" {r['rms_px']:.3f} px, p90 {r['p90_px']:.3f} px ({r['corners']} corners)"
            )
        if args.out:
            result = {"command": f"tools/marker_view_accuracy.py --bias {args.bias}", **result}
            Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
        return 0
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)  # (every view: none gated)
    renderer, detector = MarkerRenderer(info, spec, ImageNoise()), MarkerDetector(spec)
    rng = np.random.default_rng(3)
    rows = [
        cell(renderer, detector, info, d, a, args.frames, rng)
        for d in (0.7, 1.5)
        for a in (0, 30, 45, 60, 70, 75, 80)
    ]
    small = [cell(renderer, detector, info, d, 0, args.frames, rng) for d in (2.5, 3.5, 4.5)]
    for r in rows + small:
        c = r["corner_worst_px"]
        print(
            f"{r['distance_m']:4.1f} m {r['angle_deg']:3.0f} deg {r['area_px2_median']:6.0f} px2"
            f"  found {r['found']:>7}  worst corner median {c['median']:.2f} p90 {c['p90']:.2f}"
            f" worst {c['worst']:.2f} px  centre RMS {r['centre_rms_px'] or float('nan'):.2f} px"
        )
    if args.out:
        result = {
            "command": "tools/marker_view_accuracy.py --frames " + str(args.frames),
            "oblique": rows,
            "face_on_small": small,
        }
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
