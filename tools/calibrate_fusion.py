"""Does the calibrated camera fuse?  One simulated recording of a moved camera (calib-sim, the
"true" calib_arm of tools/calibrate_seeds.py, its stamps ``--stamp-offset`` late), calibrated
with the typed robot.toml, then ``amsfe estimate`` (oosm) of that recording with three camera
specs, each with its time offset as the topic spec's ``[camera] time_offset``: the true one
(the true offset), the calibrated one (calibrate's ``topics.toml``) and the typed one (none).
Per spec: frames fused and gated, the camera's mean NIS (2 dof), the mean NEES
(docs/calibrate.md, "Does it fuse").

Each spec is given the true robot's name (``amsfe estimate`` checks that a scenario's robot
is the log's) and its own library folder::

    nice -n 10 .venv/bin/python tools/calibrate_fusion.py --seed 77 \\
        --out docs/data/calibrate-fusion.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent / "tests" / "data" / "calibrate"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=77)
    ap.add_argument("--truth-seed", type=int, default=0)
    ap.add_argument("--stamp-offset", type=float, default=0.025, help="camera stamps late [s]")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from calibrate_seeds import true_robot

    from amsfe_sym.apps.cli import main as amsfe

    work = Path(tempfile.mkdtemp(prefix="calibrate-fusion-"))
    name = "calib_arm_fusion"
    # its own library folder (a cached library keeps its first builder's spec path)
    os.environ["AMSFE_GENERATED_DIR"] = str(work / "generated")
    truth = true_robot(work / "true", args.truth_seed, name)
    sim = ["simulate", str(truth.parent / "calib-sim.toml"), "--controller", "truth-ct"]
    sim += ["--estimator", "oosm", "--seed", str(args.seed), "--no-plots", "--no-progress"]
    sim += ["--set", f"camera.stamp_offset={args.stamp_offset}"]
    assert amsfe([*sim, "--bag", "--out", str(work / "run")]) == 0
    bag = work / "run" / "bag"
    robot = ["--robot", str(HERE / "robot.toml"), "--no-plots"]
    assert amsfe(["calibrate", str(bag), *robot, "--out", str(work / "cal")]) == 0
    specs = {
        "true": truth.read_text(),
        "calibrated": (work / "cal" / "robot.toml").read_text(),
        "typed": (HERE / "robot.toml")
        .read_text()
        .replace('urdf = "calib_arm.urdf"', f'urdf = "{HERE / "calib_arm.urdf"}"'),
    }
    scenario = (truth.parent / "calib-sim.toml").read_text()
    result: dict[str, object] = {"command": "tools/calibrate_fusion.py " + " ".join(sys.argv[1:])}
    for which, text in specs.items():
        folder = work / which
        folder.mkdir(exist_ok=True)
        text = re.sub(r'(?m)^name = ".*"$', f'name = "{name}"', text)
        (folder / "robot.toml").write_text(text)
        (folder / "scenario.toml").write_text(scenario)
        os.environ["AMSFE_GENERATED_DIR"] = str(work / f"gen-{which}")
        est = ["estimate", str(bag), "--scenario", str(folder / "scenario.toml")]
        key = {"true": f"[camera]\ntime_offset = {args.stamp_offset}\n", "typed": ""}.get(
            which, (work / "cal" / "topics.toml").read_text()
        )
        (folder / "topics.toml").write_text(key)
        est += ["--log-spec", str(folder / "topics.toml")]
        assert amsfe([*est, "--estimator", "oosm", "--no-plots", "--out", str(folder / "est")]) == 0
        s = json.loads((folder / "est" / "summary.json").read_text())
        result[which] = {
            "frames_fused": s["counters"]["frames_applied"],
            "frames_gated": s["counters"]["refused_gated"],
            "camera_nis_mean": s["nis"]["camera"]["mean"],
            "camera_nis_inside_95": s["nis"]["camera"]["inside_95"],
            "nees_mean": s["nees_mean"],
            "nees_dof": s["nees_dof"],
            "time_offset_key_s": key.split("time_offset = ")[-1].strip() if key else None,
        }
    text = json.dumps(result, indent=1)
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
