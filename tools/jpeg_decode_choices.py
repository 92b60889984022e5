"""How to decode a jpeg frame: the whole image in grey (what the log reader does) against
OpenCV's half-size grey (``cv2.IMREAD_REDUCED_GRAYSCALE_2``: libjpeg's scaled inverse DCT,
a quarter of the pixels), on the detection's accuracy against the simulated truth and on the
decoding's CPU time (docs/camera.md, "Speed").

The paper's 2-link arm at random q (frames where the tracked point is 60 px or more inside
the 640 x 480 image), its marker rendered by the simulated camera (plumb_bob lens, blur 0.8
px, noise 4 grey levels; ``tools/camera_accuracy.py``'s frames), compressed as ``amsfe
simulate --images jpeg`` writes it (quality 95), decoded both ways, the marker detected in
the whole image, its corners undistorted and the centre compared with the generated camera
map.  A corner (u, v) of the half-size image is (2 u + 0.5, 2 v + 0.5) in the full image
(pixel centres).  Error per frame: the largest of |du|, |dv| [px].

Writes docs/data/camera-jpeg-decode.json and prints the table:

    PYTHONPATH=src .venv/bin/python tools/jpeg_decode_choices.py [--frames 200] [--seed 31]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.core.provenance import provenance
from amsfe_sym.scenario import load_scenario
from amsfe_sym.vision.camera_info import make_camera_info, undistort
from amsfe_sym.vision.marker import MarkerDetector, single_threaded, tracked_point
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer, marker_corners
from amsfe_sym.vision.sim_images import LENSES
from amsfe_sym.vision.spec import MarkerSpec

MODES = {"whole, grey": cv2.IMREAD_GRAYSCALE, "half size, grey": cv2.IMREAD_REDUCED_GRAYSCALE_2}


def choices(lib, size: float, frames: int, seed: int) -> list[dict]:
    model, D = LENSES["plumb_bob"]
    cam = lib.manifest.camera
    info = make_camera_info(cam.width, cam.height, model, np.asarray(cam.K), D)
    spec = MarkerSpec(size=size)
    renderer = MarkerRenderer(info, spec, ImageNoise())
    camera, point = lib.function("camera"), lib.function("tracked_point")
    rng = np.random.default_rng(seed)
    jpegs, truth, sides = [], [], []
    while len(jpegs) < frames:
        q = rng.uniform(-np.pi, np.pi, lib.n)
        y = np.asarray(camera(q, lib.theta_true)[0]).ravel()
        if not (60 < y[0] < cam.width - 60 and 60 < y[1] < cam.height - 60):
            continue
        r = np.asarray(point(q, lib.theta_true)[0]).ravel()
        c = marker_corners(cam.K, cam.R_cw, cam.position, r, size)
        img = renderer.render(c, rng)
        jpegs.append(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].ravel())
        truth.append(y)
        sides.append(float(np.ptp(c[:, 0])))
    rows = []
    for name, flag in MODES.items():
        detector = MarkerDetector(spec)
        scale = 2.0 if flag == cv2.IMREAD_REDUCED_GRAYSCALE_2 else 1.0
        err, missed, cpu = [], 0, []
        for buf, y in zip(jpegs, truth, strict=True):
            t = time.process_time()
            grey = cv2.imdecode(buf, flag)
            cpu.append(time.process_time() - t)
            det = detector.whole(grey)
            if det.corners is None:
                missed += 1
                continue
            full = scale * det.corners + 0.5 * (scale - 1.0)
            err.append(tracked_point(undistort(info, full), "centre") - y)
        e = np.array(err)
        a = np.abs(e).max(axis=1)
        rows.append(
            {
                "decode": name,
                "marker_m": size,
                "marker_px_median": round(float(np.median(sides)), 1),
                "frames": frames,
                "missed": missed,
                "rms_px": [round(float(v), 3) for v in np.sqrt(np.mean(e**2, axis=0))],
                "p90_px": round(float(np.percentile(a, 90)), 3),
                "max_px": round(float(a.max()), 3),
                "decode_cpu_ms_median": round(1e3 * float(np.median(cpu)), 3),
                "jpeg_kb_median": round(float(np.median([b.size for b in jpegs])) / 1024, 1),
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--out", default="docs/data/camera-jpeg-decode.json")
    args = ap.parse_args()
    single_threaded()
    lib = library_for(load_scenario("paper-sim"))
    rows = [r for size in (0.10, 0.17) for r in choices(lib, size, args.frames, args.seed)]
    out = {
        "written_by": "tools/jpeg_decode_choices.py",
        "frames": args.frames,
        "seed": args.seed,
        "machine": provenance(),
        "rows": rows,
    }
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"{'decode':<18}{'marker':>8}{'px':>7}{'missed':>8}{'rms u, v [px]':>16}"
          f"{'p90':>8}{'max':>8}{'decode CPU':>12}")  # fmt: skip
    for r in rows:
        print(
            f"{r['decode']:<18}{r['marker_m']:>8.2f}{r['marker_px_median']:>7.1f}{r['missed']:>8}"
            f"{r['rms_px'][0]:>8.3f}{r['rms_px'][1]:>8.3f}{r['p90_px']:>8.3f}{r['max_px']:>8.3f}"
            f"{r['decode_cpu_ms_median']:>9.3f} ms"
        )


if __name__ == "__main__":
    main()
