"""Issue 18, items 2-3, before and after in one interleaved run (docs/explanation/performance.md
section
"Estimator kernels and late frames"; writes docs/data/kernels.json and docs/data/kernels.md).

    .venv/bin/python tools/kernels_before_after.py --base 5059726 \
        [--seven robots/panda/robot.toml] [--rounds 5] [--duration 5] [--loop-duration 10]

Both sides are built from the same inputs: the ``--base`` commit's package (``git archive``,
imported through PYTHONPATH, its own generated/ folder) and this worktree's.  Per side and
robot, the oosm library of paper-sim (paper_2link, rk4), ur5-control (ur5, rk4) and a 7-DOF arm
(``--seven``: a robot spec, e.g. the Panda; default the bench's 7-joint chain).  Then, in
rounds that alternate the order of the sides:

1. **tick and late frame** in pure C (``apps/bench/c/tick_timer.c`` of this side, the same
   recorded inputs for both: u, encoder samples and the camera frames of one closed-loop run of
   the scenario): ``amsfe_est_tick`` median and p99, ``amsfe_est_camera_frame`` median and p99;
2. **closed loop** (``run(..., runtime="compiled")``, oosm + the scenario's controller) of
   paper-sim and ur5-control: real-time factor, and the estimation error against the plant's
   true state (RMS of q - q_hat [rad] and of theta - theta_hat) with the frames applied;
3. **the backward map's approximation** (this side only): the Python reference oosm driven by
   the recorded inputs; at each late frame its retrodicted x(kappa|k) (linearised about the
   stored forward pass) against the one the base computed (the model's inverse applied step
   by step from x(k|k) - v_hat): largest difference in q [rad] and in the camera's predicted
   pixel [px], beside the pixel noise.

Medians over rounds; the machine (CPU, load average) is written with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = ("paper-sim", "ur5-control")

#: Run inside one side's package (PYTHONPATH): generate, or time the closed loops.
SIDE = r"""
import json, sys
import numpy as np
mode, seven, loop_duration = sys.argv[1], sys.argv[2], float(sys.argv[4])
from amsfe_sym.codegen import generate, library_for
from amsfe_sym.scenario import load_scenario
out = {}
if mode == "gen":
    for name in ("paper-sim", "ur5-control"):
        out[name] = str(library_for(load_scenario(name)).dir)
    out["seven"] = str(generate(seven).out_dir)
else:
    import logging
    from amsfe_sym.sim.loop import run
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    for name in ("paper-sim", "ur5-control"):
        sc = load_scenario(name).with_overrides(duration=loop_duration, seed=1, estimator="oosm")
        lib = library_for(sc)
        res = run(sc, lib, runtime="compiled")
        n = lib.n
        e = res.x_true - res.x_hat
        out[name] = {
            "wall_s": res.wall_time_s,
            "rtf": loop_duration / res.wall_time_s,
            "rms_q_rad": float(np.sqrt(np.mean(e[:, :n] ** 2))),
            "rms_theta": float(np.sqrt(np.mean(e[:, 4 * n :] ** 2))),
            "frames_applied": int(res.counters.get("frames_applied", -1)),
            "frames_rejected": int(res.counters.get("frames_rejected", -1)),
        }
print(json.dumps(out))
"""


def extract_commit(commit: str, dest: Path) -> None:
    """The package, robots and scenarios of ``commit`` (``git archive``) into ``dest``."""
    blob = subprocess.run(
        ["git", "-C", str(REPO), "archive", commit, "src", "robots", "scenarios", "pyproject.toml"],
        capture_output=True,
        check=True,
    ).stdout
    with tarfile.open(fileobj=BytesIO(blob)) as tar:
        tar.extractall(dest, filter="data")


def side_env(src: Path, gen: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(src)
    env["AMSFE_GENERATED_DIR"] = str(gen)
    return env


def run_side(src: Path, gen: Path, mode: str, seven: Path, dur: float, loop_dur: float) -> Any:
    proc = subprocess.run(
        [sys.executable, "-c", SIDE, mode, str(seven), str(dur), str(loop_dur)],
        env=side_env(src, gen),
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise SystemExit(f"{src} {mode} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def seven_spec(arg: str | None, tmp: Path) -> Path:
    """The 7-DOF arm: ``arg``, else robots/panda if shipped, else the bench's 7-joint chain."""
    if arg:
        return Path(arg).resolve()
    panda = REPO / "robots" / "panda" / "robot.toml"
    if panda.is_file():
        return panda
    from amsfe_sym.apps.bench.scaling import chain_urdf

    folder = tmp / "chain7"
    folder.mkdir()
    (folder / "chain7.urdf").write_text(chain_urdf(7))
    (folder / "robot.toml").write_text(
        'name = "chain7"\nurdf = "chain7.urdf"\n[model]\nintegrator = "rk4"\n'
    )
    return folder / "robot.toml"


def record_inputs(libdirs: dict[str, str], work: Path, dur: float) -> dict[str, Any]:
    """The recorded inputs of each robot (this side's package and libraries)."""
    from amsfe_sym.apps.bench.tick import record_tick_inputs, write_tick_input
    from amsfe_sym.apps.bench.ticks import timing_scenario
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import load_scenario

    out = {}
    for key, d in libdirs.items():
        lib = ModelLibrary(Path(d))
        if key == "seven":
            sc = timing_scenario(lib, dur)
        else:
            sc = load_scenario(key).with_overrides(duration=dur, estimator="oosm")
        inp = record_tick_inputs(sc, lib)
        path = write_tick_input(work / f"{key}.bin", "oosm", inp, frames=True)
        out[key] = {"input": path, "inputs": inp, "lib": lib}
    return out


def time_c(exe: Path, lib: Path, data: Path) -> dict[str, float]:
    proc = subprocess.run([str(exe), str(lib), str(data)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"tick timer on {lib}: {proc.stderr}")
    lines = proc.stdout.splitlines()
    tmed, tp99 = (float(v) / 1e3 for v in lines[0].split())
    fmed, fp99, frames, applied = lines[2].split()
    return {
        "tick_median_us": tmed,
        "tick_p99_us": tp99,
        "frame_median_us": float(fmed) / 1e3,
        "frame_p99_us": float(fp99) / 1e3,
        "frames": int(frames),
        "applied": int(applied),
    }


def approximation(rec: dict[str, Any]) -> dict[str, float]:
    """Section 3: the linearised backward map against the stepwise inverse (Python path)."""
    from amsfe_sym.estimation import CameraFrame
    from amsfe_sym.estimation.base import StepReport
    from amsfe_sym.estimation.oosm import OosmEstimator, a1_retrodict

    inp = rec["inputs"]
    model, camera, n = inp.kwargs["model"], inp.kwargs["camera"], inp.lib.n
    worst = {"dq_rad": 0.0, "dx": 0.0, "dpx": 0.0, "frames": 0}
    dqs: list[float] = []
    dpxs: list[float] = []

    class Compared(OosmEstimator):
        """oosm that, before each late frame, computes x(kappa|k) both ways."""

        def _late_frame(self, frame: CameraFrame, k: int, report: StepReport) -> None:
            kappa, B, N = frame.exposure_step, self.config.buffer_steps, self.nx
            Phi, Q, s = np.eye(N), np.zeros((N, N)), np.zeros(N)
            for j in range(kappa, k):  # as OosmEstimator._late_frame
                A_j = self._A[j % B]
                Phi, Q, s = A_j @ Phi, A_j @ Q @ A_j.T + self._Q[j % B], A_j @ s
                if j + 1 < k:
                    s += self._x_post[(j + 1) % B] - self._x_prior[j % B]
            retro = a1_retrodict(self.x, self.P, 0.5 * (Q + Q.T), self._last)
            x_lin = self._x_post[kappa % B] + np.linalg.solve(
                Phi, s + retro.x_shift - self._x_prior[(k - 1) % B]
            )
            x_exact = retro.x_shift  # the base's eq. (24): the inverse, step by step
            for j in range(k - 1, kappa - 1, -1):
                u_j = self._u[j % B]
                assert u_j is not None
                x_exact = model.inverse(x_exact, u_j)
            dy = camera.predict(x_lin)[0] - camera.predict(x_exact)[0]
            dqs.append(float(np.max(np.abs((x_lin - x_exact)[:n]))))
            dpxs.append(float(np.max(np.abs(dy))))
            worst["dq_rad"] = max(worst["dq_rad"], dqs[-1])
            worst["dx"] = max(worst["dx"], float(np.max(np.abs(x_lin - x_exact))))
            worst["dpx"] = max(worst["dpx"], float(np.max(np.abs(dy))))
            worst["frames"] += 1
            super()._late_frame(frame, k, report)

    est = Compared(**inp.kwargs)
    frames: dict[int, list[CameraFrame]] = {}
    for kappa, k, zu, zv in inp.frames:
        frames.setdefault(int(k), []).append(CameraFrame(int(kappa), np.array([zu, zv])))
    for k in range(len(inp.u)):
        z = inp.z[k] if np.isfinite(inp.z[k]).all() else None
        est.step(inp.u[k], z, frames.get(k + 1, []))
    worst["pixel_std"] = float(np.sqrt(camera.R[0, 0]))
    worst["median_dq_rad"] = float(np.median(dqs)) if dqs else 0.0
    worst["median_dpx"] = float(np.median(dpxs)) if dpxs else 0.0
    worst["last_half_max_dq_rad"] = float(np.max(dqs[len(dqs) // 2 :])) if dqs else 0.0
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="commit before the change (required unless --render)")
    ap.add_argument("--render", action="store_true", help="only rewrite kernels.md from the json")
    ap.add_argument("--seven", help="robot spec of the 7-DOF arm")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=5.0, help="recorded run [s]")
    ap.add_argument("--loop-duration", type=float, default=10.0, help="closed loop [s]")
    ap.add_argument("--out", default=str(REPO / "docs" / "data"))
    args = ap.parse_args()
    if args.render:
        report = json.loads((Path(args.out) / "kernels.json").read_text())
        (Path(args.out) / "kernels.md").write_text(markdown(report))
        return
    if not args.base:
        ap.error("--base is required")
    t0 = time.time()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="amsfe-kernels-") as tmpname:
        tmp = Path(tmpname)
        seven = seven_spec(args.seven, tmp)
        extract_commit(args.base, tmp / "base")
        sides = {"before": tmp / "base" / "src", "after": REPO / "src"}
        gens = {k: tmp / f"gen-{k}" for k in sides}
        libs = {}
        for k in sides:
            print(f"[kernels] generating ({k}) ...", flush=True)
            libs[k] = run_side(sides[k], gens[k], "gen", seven, args.duration, args.loop_duration)
        rec = record_inputs(libs["after"], tmp, args.duration)
        from amsfe_sym.apps.bench.tick import build_tick_timer

        exe = build_tick_timer(tmp)
        timings: dict[str, dict[str, list[dict[str, float]]]] = {
            k: {r: [] for r in rec} for k in sides
        }
        loops: dict[str, list[Any]] = {k: [] for k in sides}
        for rnd in range(args.rounds):
            order = list(sides) if rnd % 2 == 0 else list(reversed(sides))
            for robot in rec:
                for k in order:
                    lib = Path(libs[k][robot])
                    so = next(lib.glob("lib*.so"))
                    timings[k][robot].append(time_c(exe, so, rec[robot]["input"]))
            for k in order:
                loops[k].append(
                    run_side(sides[k], gens[k], "loop", seven, args.duration, args.loop_duration)
                )
            print(f"[kernels] round {rnd + 1}/{args.rounds} done", flush=True)
        approx = {robot: approximation(rec[robot]) for robot in rec}
    report = summarize(args, seven, timings, loops, approx, load0, time.time() - t0)
    out = Path(args.out)
    (out / "kernels.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / "kernels.md").write_text(markdown(report))
    print(markdown(report))


def med(values: list[float]) -> float:
    return float(f"{statistics.median(values):.6g}")


def summarize(
    args: argparse.Namespace,
    seven: Path,
    timings: dict[str, dict[str, list[dict[str, float]]]],
    loops: dict[str, list[Any]],
    approx: dict[str, dict[str, float]],
    load0: tuple[float, float, float],
    seconds: float,
) -> dict[str, Any]:
    cpu = "unknown"
    if Path("/proc/cpuinfo").is_file():
        names = [
            ln.split(":", 1)[1].strip()
            for ln in Path("/proc/cpuinfo").read_text().splitlines()
            if ln.startswith("model name")
        ]
        cpu = f"{names[0]} x {len(names)}" if names else cpu
    ticks = {
        side: {
            robot: {key: med([t[key] for t in runs]) for key in runs[0]}
            for robot, runs in per.items()
        }
        for side, per in timings.items()
    }
    loop = {
        side: {
            sc: {key: med([r[sc][key] for r in runs]) for key in runs[0][sc]} for sc in SCENARIOS
        }
        for side, runs in loops.items()
    }
    after7 = ticks["after"]["seven"]
    targets = {
        "7-DOF oosm tick median <= 20 us": after7["tick_median_us"] <= 20.0,
        "7-DOF oosm tick p99 <= 60 us": after7["tick_p99_us"] <= 60.0,
        "paper-sim >= 300x real time": loop["after"]["paper-sim"]["rtf"] >= 300.0,
        "ur5-control >= 80x real time": loop["after"]["ur5-control"]["rtf"] >= 80.0,
    }
    head = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    dirty = subprocess.run(
        ["git", "-C", str(REPO), "status", "--porcelain", "src"], capture_output=True, text=True
    ).stdout.strip()
    return {
        "command": " ".join(["tools/kernels_before_after.py", *sys.argv[1:]]),
        "base": args.base,
        "after": head + (" + uncommitted changes in src/" if dirty else ""),
        "seven": str(seven.relative_to(REPO))
        if seven.is_relative_to(REPO)
        else f"{seven.parent.name}/{seven.name}",
        "machine": {
            "cpu": cpu,
            "platform": platform.platform(),
            "loadavg_start": [round(v, 2) for v in load0],
            "loadavg_end": [round(v, 2) for v in os.getloadavg()],
        },
        "rounds": args.rounds,
        "seconds": round(seconds, 1),
        "tick_and_frame": ticks,
        "closed_loop": loop,
        "backward_map": approx,
        "targets": {k: "met" if v else "not met" for k, v in targets.items()},
    }


def markdown(r: dict[str, Any]) -> str:
    rows = [
        f"Measured by `{r['command']}`: before = commit {r['base']}, after = {r['after']} "
        f"({r['rounds']} interleaved rounds, medians; "
        f"machine: {r['machine']['cpu']}, load average {r['machine']['loadavg_start']} at the "
        f"start, {r['machine']['loadavg_end']} at the end).",
        "",
        "| robot | tick median before / after [us] | tick p99 before / after [us] | "
        "late frame median before / after [us] | late frame p99 before / after [us] |",
        "|---|---|---|---|---|",
    ]
    names = {"paper-sim": "paper_2link (rk4, lag 125)", "ur5-control": "ur5 (rk4, lag 33)"}
    names["seven"] = f"7-DOF `{r['seven']}` (rk4)"
    b, a = r["tick_and_frame"]["before"], r["tick_and_frame"]["after"]
    for robot in a:
        rows.append(
            f"| {names[robot]} | {b[robot]['tick_median_us']:.1f} / "
            f"{a[robot]['tick_median_us']:.1f} | {b[robot]['tick_p99_us']:.1f} / "
            f"{a[robot]['tick_p99_us']:.1f}"
            f" | {b[robot]['frame_median_us']:.0f} / {a[robot]['frame_median_us']:.0f}"
            f" | {b[robot]['frame_p99_us']:.0f} / {a[robot]['frame_p99_us']:.0f} |"
        )
    rows += [
        "",
        "| closed loop (oosm, compiled) | real-time factor before / after | RMS q error "
        "before / after [rad] | RMS theta error before / after | frames applied before / after |",
        "|---|---|---|---|---|",
    ]
    lb, la = r["closed_loop"]["before"], r["closed_loop"]["after"]
    for sc in SCENARIOS:
        rows.append(
            f"| {sc} | {lb[sc]['rtf']:.0f}x / {la[sc]['rtf']:.0f}x"
            f" | {lb[sc]['rms_q_rad']:.5g} / {la[sc]['rms_q_rad']:.5g}"
            f" | {lb[sc]['rms_theta']:.5g} / {la[sc]['rms_theta']:.5g}"
            f" | {lb[sc]['frames_applied']:.0f} / {la[sc]['frames_applied']:.0f} |"
        )
    rows += [
        "",
        "| backward map, linearised vs stepwise inverse | late frames | abs dq [rad] median / "
        "max (max over the second half of the run) | max abs dx | predicted-pixel difference "
        "[px] median / max | pixel noise std [px] |",
        "|---|---|---|---|---|---|",
    ]
    for robot, w in r["backward_map"].items():
        rows.append(
            f"| {names[robot]} | {w['frames']} | {w['median_dq_rad']:.2g} / {w['dq_rad']:.2g} "
            f"({w['last_half_max_dq_rad']:.2g}) | {w['dx']:.2g} "
            f"| {w['median_dpx']:.2g} / {w['dpx']:.2g} | {w['pixel_std']:.2g} |"
        )
    rows += ["", "| target | status |", "|---|---|"]
    rows += [f"| {k} | {v} |" for k, v in r["targets"].items()]
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    main()
