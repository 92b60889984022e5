"""A section of ``amsfe bench``: the camera chain's decoding + detection per frame
(docs/camera.md, "Speed").

A 640 x 480 camera (f = 500 px, the simulated camera's barrel lens, blur 0.8 px, noise 4 grey
levels) watches a 36h11 tag of ``marker_px`` px moving on a Lissajous path, up to 9 px a frame
(the paper's arm at 30 Hz).  Its frames are serialized once, as a driver publishes them
(``rosbags``' CDR): ``mono8`` and ``bgr8`` ``sensor_msgs/Image`` and ``jpeg``
``sensor_msgs/CompressedImage`` of the grey and of a colour (bgr8) image.  Each kind is then
run through what the log reader does per frame (the loop of
:class:`amsfe_sym.vision.detections.ImageDecoder`: the payload read in place, grey, the
marker detected), plus the undistortion of its corners and the centre (which the log reader
does once for the whole log, the camera node per frame), twice: searching the whole image
every frame (``whole``), and in a region of interest around the previous frame's corners
(``roi``, the log reader's path: the whole image only when the marker is not there); for
mono8 also the whole image with OpenCV's default threshold windows (``opencv``: 3, 13 and
23 px instead of :data:`~amsfe_sym.vision.marker.THRESHOLD_WINDOW`), what the one window
saves.

OpenCV runs on one thread (:func:`amsfe_sym.vision.marker.single_threaded`), so CPU time
(``time.process_time``) is one core's; the wall time is beside it.  Medians over rounds;
frames/s = frames / time.  Each row also reports its stages' CPU time per frame (read +
grey, detection, undistortion + centre) and, for ``roi``, the largest difference of its
corners from ``whole``'s on the same frames [px].
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["KINDS", "STAGES", "VISION_TARGET_FPS", "bench_vision", "vision_lines"]

#: The message kinds timed: raw Images, and jpeg CompressedImages of a grey image (what
#: ``amsfe simulate --images jpeg`` writes) and of a colour one (a colour camera's
#: image_transport ``compressed``, decoded straight to grey).
KINDS = ("mono8", "bgr8", "jpeg mono8", "jpeg bgr8")
#: The stages timed per frame (CPU): payload read in place + grey, detection, undistortion of
#: the corners + the centre.
STAGES = ("read_grey", "detect", "undistort")
#: The target: decoding + detection per frame at 640 x 480 on one core [frames/s].
VISION_TARGET_FPS = 60.0

_W, _H, _F = 640, 480, 500.0


def _frames(count: int, marker_px: float, seed: int) -> list[NDArray[np.uint8]]:
    """``count`` rendered grey frames of the moving marker (module docstring)."""
    from amsfe_sym.vision.camera_info import make_camera_info
    from amsfe_sym.vision.render import ImageNoise, MarkerRenderer
    from amsfe_sym.vision.sim_images import LENSES
    from amsfe_sym.vision.spec import MarkerSpec

    K = np.array([[_F, 0.0, _W / 2], [0.0, _F, _H / 2], [0.0, 0.0, 1.0]])
    info = make_camera_info(_W, _H, LENSES["plumb_bob"][0], K, LENSES["plumb_bob"][1])
    renderer = MarkerRenderer(info, MarkerSpec(), ImageNoise())
    rng = np.random.default_rng(seed)
    h = 0.5 * marker_px
    square = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    out = []
    for k in range(count):
        t = k / 30.0
        centre = np.array([_W / 2 + 200 * np.sin(0.9 * t), _H / 2 + 150 * np.sin(1.3 * t + 0.5)])
        out.append(renderer.render(square + centre, rng))
    return out


def _payloads(frames: list[NDArray[np.uint8]], kind: str) -> tuple[list[bytes], str]:
    """The frames as a driver's CDR payloads of ``kind``, and the message type."""
    import cv2

    from amsfe_sym.logs.decode import typestore

    ts = typestore("cdr")
    T = ts.types
    out, msgtype = [], "sensor_msgs/msg/Image"
    for k, grey in enumerate(frames):
        ns = 1_000_000_000 + k * 33_333_333
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")
        colour = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR) if kind.endswith("bgr8") else grey
        if kind.startswith("jpeg"):
            buf = cv2.imencode(".jpg", colour)[1]
            msgtype = "sensor_msgs/msg/CompressedImage"
            msg: Any = T[msgtype](header=header, format="jpeg", data=buf.ravel())
        else:
            msg = T[msgtype](
                header=header, height=_H, width=_W, encoding=kind, is_bigendian=0,
                step=_W * (1 if colour.ndim == 2 else 3), data=colour.ravel(),
            )  # fmt: skip
        out.append(bytes(ts.serialize_cdr(msg, msgtype)))
    return out, msgtype


def _run(
    raws: list[bytes], msgtype: str, search: str, clocks: tuple[Callable[[], float], ...]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One pass over the payloads: the corners (M, 4, 2) [px], the total (CPU, wall) [s] and
    the CPU time of each stage (3,) [s]."""
    from amsfe_sym.logs.image_wire import image_message
    from amsfe_sym.vision.camera_info import make_camera_info, undistort
    from amsfe_sym.vision.images import grey_from_message
    from amsfe_sym.vision.marker import THRESHOLD_WINDOW, MarkerDetector, tracked_point
    from amsfe_sym.vision.sim_images import LENSES
    from amsfe_sym.vision.spec import MarkerSpec

    K = np.array([[_F, 0.0, _W / 2], [0.0, _F, _H / 2], [0.0, 0.0, 1.0]])
    info = make_camera_info(_W, _H, LENSES["plumb_bob"][0], K, LENSES["plumb_bob"][1])
    window = None if search == "opencv" else THRESHOLD_WINDOW
    detector = MarkerDetector(MarkerSpec(), threshold_window=window)
    roi = search == "roi"
    cpu, wall = clocks
    corners = np.full((len(raws), 4, 2), np.nan)
    stages = np.zeros(3)
    last = None
    c0, w0 = cpu(), wall()
    for i, raw in enumerate(raws):
        a = cpu()
        grey = grey_from_message(image_message(raw, msgtype, "cdr"), msgtype)
        b = cpu()
        det = detector.detect(grey.pixels, last) if roi else detector.whole(grey.pixels)
        c = cpu()
        if det.corners is not None:
            corners[i] = det.corners
            tracked_point(undistort(info, det.corners), "centre")
        last = det.corners
        stages += (b - a, c - b, cpu() - c)
    return corners, np.array([cpu() - c0, wall() - w0]), stages


def bench_vision(frames: int = 150, rounds: int = 3, marker_px: float = 27.0) -> dict[str, Any]:
    """Time the camera chain per frame (module docstring).

    Args:
        frames: Frames per pass (30 Hz of the marker's path).
        rounds: Passes per row (medians reported).
        marker_px: The marker's side [px] (27: the paper's 10 cm tag at the arm's distance).

    Returns:
        ``{"image", "marker_px", "frames", "rounds", "threads", "rows": [{"kind", "search",
        "found", "cpu_s", "wall_s", "fps_cpu", "fps_wall", "stages_cpu_ms": {"read_grey",
        "detect", "undistort"}, "max_corner_diff_px" (roi rows)}]}``.
    """
    import cv2

    from amsfe_sym.vision.marker import single_threaded

    single_threaded()
    grey = _frames(frames, marker_px, seed=1)
    rows: list[dict[str, Any]] = []
    clocks = (time.process_time, time.perf_counter)
    for kind in KINDS:
        raws, msgtype = _payloads(grey, kind)
        whole_corners = None
        searches = ("whole", "roi", "opencv") if kind == "mono8" else ("whole", "roi")
        for search in searches:
            runs = [_run(raws, msgtype, search, clocks) for _ in range(rounds)]
            corners = runs[-1][0]
            found = np.isfinite(corners).all(axis=(1, 2))
            cpu = statistics.median(float(r[1][0]) for r in runs)
            wall = statistics.median(float(r[1][1]) for r in runs)
            st = np.median(np.array([r[2] for r in runs]), axis=0) / frames * 1e3
            row: dict[str, Any] = {
                "kind": kind,
                "message": msgtype.rsplit("/", 1)[-1],
                "search": search,
                "found": int(found.sum()),
                "bytes_per_frame": int(np.mean([len(r) for r in raws])),
                "cpu_s": round(cpu, 4),
                "wall_s": round(wall, 4),
                "fps_cpu": round(frames / max(cpu, 1e-9), 1),
                "fps_wall": round(frames / max(wall, 1e-9), 1),
                "stages_cpu_ms": dict(zip(STAGES, (round(float(v), 3) for v in st), strict=True)),
            }
            if search == "whole":
                whole_corners = corners
            elif search == "roi" and whole_corners is not None:
                both = found & np.isfinite(whole_corners).all(axis=(1, 2))
                diff = np.abs(corners[both] - whole_corners[both])
                row["max_corner_diff_px"] = float(diff.max()) if diff.size else None
            rows.append(row)
    return {
        "image": f"{_W} x {_H}",
        "marker_px": marker_px,
        "frames": frames,
        "rounds": rounds,
        "threads": int(cv2.getNumThreads()),
        "rows": rows,
    }


def vision_lines(v: dict[str, Any], cpu: str) -> list[str]:
    """The section's printed lines (``cpu``: the CPU model)."""
    lines = [
        "",
        f"7. camera chain per frame: read + grey + detect + undistort, {v['image']} px, a "
        f"{v['marker_px']:g} px tag moving; {v['frames']} frames, median of {v['rounds']}; "
        f"{cpu}, OpenCV threads {v['threads']}",
        f"   {'message':<28}{'search':<8}{'found':>7}{'fps CPU':>9}{'fps wall':>10}"
        f"{'read+grey':>10}{'detect':>8}{'undist':>8}  [CPU ms/frame]  roi - whole [px]",
    ]
    for r in v["rows"]:
        s = r["stages_cpu_ms"]
        d = r.get("max_corner_diff_px")
        lines.append(
            f"   {r['kind'] + ' ' + r['message']:<28}{r['search']:<8}"
            f"{r['found']:>4}/{v['frames']:<3}{r['fps_cpu']:>8.0f}{r['fps_wall']:>10.0f}"
            f"{s['read_grey']:>10.3f}{s['detect']:>8.3f}{s['undistort']:>8.3f}"
            f"{'' if d is None else f'  {d:.1e}':>18}"
        )
    lines.append(
        "   whole = the whole image every frame; roi = around the last corners (the log "
        "reader's path); opencv = whole, OpenCV's default threshold windows (3, 13, 23 px)"
    )
    lines.append(
        f"   target: decoding + detection >= {VISION_TARGET_FPS:g} frames/s on "
        "one core (fps CPU: time.process_time, OpenCV on one thread)"
    )
    return lines
