"""``amsfe bench``'s camera chain section (``vision``; docs/camera.md, "Speed"): a real short
run through the command line, its report's shape and its correctness columns (every frame
found, the region of interest's corners the whole image's); no timing is asserted."""

from __future__ import annotations

import json
from pathlib import Path

from amsfe_sym.apps.bench.vision import KINDS, STAGES
from amsfe_sym.apps.cli import main
from amsfe_sym.core.provenance import cpu_name

OTHERS = ["generation", "calls", "estimators", "tick", "loop", "scaling", "logs"]


def test_the_vision_section_reports_every_kind_and_search(capsys, tmp_path: Path) -> None:
    out_json = tmp_path / "bench.json"
    argv = ["bench", "--rounds", "2", "--skip", *OTHERS, "--vision-frames", "12"]
    assert main([*argv, "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "7. camera chain per frame" in out and cpu_name() in out
    assert "OpenCV threads 1" in out and "frames/s on one core" in out
    for section in ("1. generation", "2. per-call", "3. estimator", "6. amsfe estimate"):
        assert section not in out  # (--skip left them out)
    v = json.loads(out_json.read_text())["vision"]
    assert (v["image"], v["frames"], v["rounds"], v["threads"]) == ("640 x 480", 12, 2, 1)
    rows = {(r["kind"], r["search"]): r for r in v["rows"]}
    assert set(rows) == {(k, s) for k in KINDS for s in ("whole", "roi")} | {("mono8", "opencv")}
    for (kind, search), r in rows.items():
        assert r["message"] == ("CompressedImage" if kind.startswith("jpeg") else "Image")
        assert r["found"] == 12, (kind, search)
        assert r["fps_cpu"] > 0 and r["fps_wall"] > 0 and r["cpu_s"] > 0
        assert set(r["stages_cpu_ms"]) == set(STAGES)
        # the stages are parts of the pass (cpu_s rounded to 0.1 ms, the stages to 1 us)
        assert sum(r["stages_cpu_ms"].values()) <= r["cpu_s"] / 12 * 1e3 + 0.02
        if search == "roi":  # the same corners as the whole image's, same frames
            assert r["max_corner_diff_px"] is not None and r["max_corner_diff_px"] < 1e-4
        assert f"{kind} {r['message']}" in out
    # a raw mono8 frame is ~307 kB, its jpeg much less
    assert rows[("mono8", "whole")]["bytes_per_frame"] > 640 * 480
    assert rows[("jpeg mono8", "whole")]["bytes_per_frame"] < 640 * 480 / 2


def test_vision_is_skippable(capsys) -> None:
    assert main(["bench", "--rounds", "1", "--skip", *OTHERS, "vision"]) == 0
    assert "camera chain" not in capsys.readouterr().out
