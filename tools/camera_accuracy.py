"""The camera chain's numbers in docs/camera.md ("Accuracy", "Speed", "End to end").

1. Detection accuracy: the paper's 2-link arm at random q, its marker rendered by the
   simulated camera through each lens (blur 0.8 px, noise 4 grey levels), detected,
   undistorted and compared with the generated camera map: RMS per axis, 90th percentile
   and worst error [px], frames missed; for a 10 cm and a 17 cm marker (~27 and ~45 px).
2. (Speed is ``amsfe bench``'s section 7, ``vision``, and its ``--logs ...:images``:
   docs/camera.md, "Speed".)
3. End to end (issue 35's done-when): ``amsfe simulate --controller amsfe --seed S --bag``
   with and without ``--images``, each estimated by ``amsfe estimate BAG --robot
   paper_2link``: link-angle RMSE of both and their ratio per joint.
4. (``--long``) A 60 s log with a 30 Hz camera, with and without images: bag size, read +
   estimate time, peak memory of ``amsfe estimate`` (memory bounded: it must not grow with
   the images' bytes).

Writes docs/data/camera-accuracy.json and prints the tables:

    .venv/bin/python tools/camera_accuracy.py [--frames 60] [--seeds 17 18 19] [--long]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from amsfe_sym.vision.camera_info import make_camera_info, undistort
from amsfe_sym.vision.marker import MarkerDetector, tracked_point
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer, marker_corners
from amsfe_sym.vision.sim_images import LENSES
from amsfe_sym.vision.spec import MarkerSpec


def accuracy(lib, lens: str, size: float, frames: int, seed: int) -> dict:
    model, D = LENSES[lens]
    cam = lib.manifest.camera
    info = make_camera_info(cam.width, cam.height, model, np.asarray(cam.K), D)
    spec = MarkerSpec(size=size)
    renderer, detector = MarkerRenderer(info, spec, ImageNoise()), MarkerDetector(spec)
    camera, point = lib.function("camera"), lib.function("tracked_point")
    rng = np.random.default_rng(seed)
    err, missed = [], 0
    while len(err) + missed < frames:
        q = rng.uniform(-np.pi, np.pi, lib.n)
        y = np.asarray(camera(q, lib.theta_true)[0]).ravel()
        if not (60 < y[0] < cam.width - 60 and 60 < y[1] < cam.height - 60):
            continue
        r = np.asarray(point(q, lib.theta_true)[0]).ravel()
        det = detector.detect(
            renderer.render(marker_corners(cam.K, cam.R_cw, cam.position, r, size), rng)
        )
        if det.corners is None:
            missed += 1
            continue
        err.append(tracked_point(undistort(info, det.corners), "centre") - y)
    e = np.array(err)
    a = np.abs(e).max(axis=1)
    return {
        "lens": lens,
        "marker_m": size,
        "frames": frames,
        "missed": missed,
        "rms_px": [round(float(v), 3) for v in np.sqrt(np.mean(e**2, axis=0))],
        "p90_px": round(float(np.percentile(a, 90)), 3),
        "max_px": round(float(a.max()), 3),
    }


def end_to_end(seed: int, tmp: Path) -> dict:
    from amsfe_sym.apps.cli import main

    out = {"seed": seed}
    for name, extra in (("pixels", []), ("images", ["--images"])):
        run = tmp / f"{name}-{seed}"
        assert main(["simulate", "--controller", "amsfe", "--seed", str(seed), "--out", str(run),
                     "--bag", "--no-plots", "--no-progress", *extra]) == 0  # fmt: skip
        est = tmp / f"est-{name}-{seed}"
        assert main(["estimate", str(run / "bag"), "--robot", "paper_2link", "--out", str(est),
                     "--no-plots"]) == 0  # fmt: skip
        s = json.loads((est / "summary.json").read_text())
        out[f"rmse_q_{name}"] = [round(float(v), 6) for v in s["estimation_rmse_q"]]
        out[f"frames_{name}"] = s["topics"]["camera"]["used"]
    out["ratio"] = [
        round(b / a, 4) for a, b in zip(out["rmse_q_pixels"], out["rmse_q_images"], strict=True)
    ]
    return out


_RSS = """
import json, resource, sys
from amsfe_sym.apps.cli import main
code = main(sys.argv[1:])
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"code": code, "max_rss_mb": rss}))
"""


def long_log(tmp: Path, seed: int = 23) -> dict:
    """Part 4: a 60 s run with a 30 Hz camera (period = delay = 33 ticks), written with and
    without ``--images``, each estimated in a process of its own: the bag's size, frames
    fused, the read + estimate time the command prints and the process's peak memory."""
    import subprocess
    import sys

    out: dict = {"seed": seed, "duration_s": 60, "camera_hz": 30}
    for name, extra in (("pixels", []), ("images", ["--images"])):
        run = tmp / f"long-{name}"
        sim = ["simulate", "--controller", "amsfe", "--seed", str(seed), "--duration", "60",
               "--set", "camera.period=33", "--set", "camera.delay=33", "--out", str(run),
               "--bag", "--no-plots", "--no-progress", *extra]  # fmt: skip
        subprocess.run([sys.executable, "-c", _RSS, *sim], check=True, capture_output=True)
        size = sum(f.stat().st_size for f in (run / "bag").iterdir())
        est = ["estimate", str(run / "bag"), "--robot", "paper_2link", "--out",
               str(tmp / f"long-est-{name}"), "--no-plots"]  # fmt: skip
        p = subprocess.run([sys.executable, "-c", _RSS, *est], check=True, capture_output=True,
                           text=True)  # fmt: skip
        lines = p.stdout.splitlines()
        speed = next(ln.strip() for ln in lines if ln.strip().startswith("speed:"))
        summary = json.loads((tmp / f"long-est-{name}" / "summary.json").read_text())
        out[name] = {
            "bag_mb": round(size / 2**20, 1),
            "frames_used": summary["topics"]["camera"]["used"],
            "speed_line": speed,
            "max_rss_mb": round(json.loads(lines[-1])["max_rss_mb"], 1),
            "rmse_q": [round(float(v), 6) for v in summary["estimation_rmse_q"]],
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seeds", type=int, nargs="*", default=[17, 18, 19])
    ap.add_argument("--long", action="store_true", help="only part 4 (60 s, 30 Hz), into --out")
    ap.add_argument(
        "--out", default=str(Path(__file__).parent.parent / "docs/data/camera-accuracy.json")
    )
    args = ap.parse_args()
    lib = library_for(load_scenario("paper-sim"))
    if args.long:  # part 4 alone, into the stored file
        with tempfile.TemporaryDirectory() as d:
            lg = long_log(Path(d))
        print(json.dumps(lg, indent=1))
        path = Path(args.out)
        doc = json.loads(path.read_text()) if path.is_file() else {}
        path.write_text(json.dumps({**doc, "long_log": lg}, indent=1) + "\n")
        return
    acc = [
        accuracy(lib, lens, size, args.frames, 100 + i)
        for i, (lens, size) in enumerate((lens, size) for size in (0.1, 0.17) for lens in LENSES)
    ]
    print("| lens | marker | frames | missed | RMS u, v [px] | p90 [px] | max [px] |")
    print("|---|---|---|---|---|---|---|")
    for a in acc:
        print(
            f"| {a['lens']} | {a['marker_m']} m | {a['frames']} | {a['missed']} | "
            f"{a['rms_px'][0]}, {a['rms_px'][1]} | {a['p90_px']} | {a['max_px']} |"
        )
    with tempfile.TemporaryDirectory() as d:
        e2e = [end_to_end(s, Path(d)) for s in args.seeds]
    for e in e2e:
        print(
            f"seed {e['seed']}: RMSE q pixels {e['rmse_q_pixels']}, images {e['rmse_q_images']}, "
            f"ratio {e['ratio']}, frames {e['frames_pixels']} / {e['frames_images']}"
        )
    path = Path(args.out)
    doc = json.loads(path.read_text()) if path.is_file() else {}
    kept = {"long_log": doc["long_log"]} if "long_log" in doc else {}
    path.write_text(json.dumps({"accuracy": acc, "end_to_end": e2e, **kept}, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
