"""Reading + estimating a 60 s, 1 kHz Panda log without the applied torque, Python against C
(docs/explanation/effort.md, "Compiled").

The log: a closed-loop panda-control run (compiled loop, its amsfe controller, seed 1, 60 s
at T = 1 ms, a 30 Hz camera) written as ``amsfe simulate --bag`` writes it, the torque topic
holding what a Franka logs, the spring torque ``Ks (qm - q)`` plus 0.05 N m of white noise
(tests/test_log_effort.py's log), and a log spec ``[effort] kind = "joint_torque"``.  Each
run is ``amsfe estimate LOG --robot panda --log-spec SPEC --estimator E --runtime R`` (the
function behind it, ``estimate_command``, without figures); the real-time factor is 60 s over
its read + estimate time (``EstimateRun.read_s + estimate_s``, the run's outputs not
counted).  ``--kinds none`` reads the same log as encoders-only.

``--applied-ratio OTHER_SRC``: the applied path's speed against another tree (e.g. the
commit before this work): ``run_log`` of the compiled estimator on the same run logged with
its applied torque (``amsfe simulate --bag``'s log), in fresh processes of each tree,
interleaved, ``--repeat`` times each (after one warm-up round each); prints the median wall
time of each, their ratio (and of the CPU times), and whether both trees gave the same x_hat
and diag P bit for bit (a sha256).  The order alternates between rounds.
The other tree compiles its own library (``AMSFE_GENERATED_DIR`` of that process:
``--other-gen``).

``--real BAG``: the real franka_ros recording of docs/how-to/logs.md ("A real Panda recording,
worked"; its library generated first with ``amsfe generate panda --period 0.0333333``), with
that section's ``jt-tuned`` and ``none-tuned`` log specs and ``replay``, through both
runtimes: their times and how far apart their x, diag P and encoder NIS are.

    PYTHONPATH=src AMSFE_GENERATED_DIR=... .venv/bin/python tools/effort_speed.py \\
        [--out /tmp/amsfe-effort-speed] [--estimators replay oosm] [--kinds joint_torque] \\
        [--repeat 3] [--python-repeat 1] [--applied-ratio ../main/src --other-gen DIR]
        [--real joint_states.bag]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

DURATION, SEED, TORQUE_STD = 60.0, 1, 0.05


def write_logs(out: Path) -> tuple[Path, Path]:
    """The 60 s joint-torque Panda log and the same run with its applied torque (skipped
    when they exist)."""
    bag = out / "panda-joint_torque" / "log"
    applied = out / "panda-applied" / "log"
    if (bag / "metadata.yaml").is_file() and (applied / "metadata.yaml").is_file():
        return bag, applied
    import numpy as np

    from amsfe_sym.codegen import library_for
    from amsfe_sym.logs.write import write_run_bag
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    sc = load_scenario("panda-control").with_overrides(
        duration=DURATION, controller="amsfe", seed=SEED
    )
    res = run(sc, library_for(sc), runtime="compiled")
    lib, lay = res.lib, res.lib.layout
    tau = lib.stiffness(lib.theta_true) * (res.x_true[:, lay["qm"]] - res.x_true[:, lay["q"]])
    tau = tau + TORQUE_STD * np.random.default_rng(1).standard_normal(tau.shape)
    for path in (bag, applied):
        path.parent.mkdir(parents=True, exist_ok=True)
    write_run_bag(res, applied, replace=True)
    return write_run_bag(dataclasses.replace(res, u=tau), bag, replace=True), applied


def estimate(bag: Path, kind: str, estimator: str, runtime: str, out: Path) -> dict[str, Any]:
    """One ``amsfe estimate`` of the log: its read and estimate times [s] and counters."""
    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command

    spec = out / f"spec-{kind}.toml"
    spec.write_text(f'[effort]\nkind = "{kind}"\n')
    opts = EstimateOptions(
        robot="panda", log_spec=str(spec), estimator=estimator, plots=False, force=True
    )
    opts = dataclasses.replace(opts, runtime=runtime)
    run = estimate_command(bag, out / f"est-{kind}-{estimator}-{runtime}", opts)
    est = run.estimate
    return {
        "read_s": run.read_s,
        "estimate_s": run.estimate_s,
        "rtf": DURATION / (run.read_s + run.estimate_s),
        "frames_applied": int(est.counters.get("frames_applied", 0)),
        "x_last": est.x_hat[-1].tolist(),
    }


_APPLIED = """
import sys, time, numpy as np
from pathlib import Path
from amsfe_sym.apps.estimate import EstimateOptions, _scenario
from amsfe_sym.codegen import library_for
from amsfe_sym.logs.read import read_config, read_log
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.runtime.estimator_batch import run_log
from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing
bag = Path(sys.argv[1]); spec = LogSpec()
sc = _scenario(bag, read_config(bag, spec), EstimateOptions())
lib = library_for(sc)
log = read_log(bag, spec, lib.manifest.joints, lib.T, lib.N)
sens = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
est = build_estimator(sc, lib, sens, log.z[0], compiled=True)
fr = sorted(log.frames, key=lambda f: (f.delivery_step, f.exposure_step))
kap = np.array([f.exposure_step for f in fr], np.int64)
arr = np.array([f.delivery_step for f in fr], np.int64)
fz = np.array([f.z for f in fr], float).reshape(-1, 2)
t0, c0 = time.perf_counter(), time.process_time()
res = run_log(est, log.u, log.z, kap, arr, fz)
dt, dc = time.perf_counter() - t0, time.process_time() - c0
import hashlib
print(hashlib.sha256(res.x_hat.tobytes() + res.P_diag.tobytes()).hexdigest())
print(dc)
print(dt)
"""


def applied_ratio(bag: Path, other_src: str, other_gen: str, repeat: int) -> dict[str, Any]:
    """run_log's wall time on the log read as applied, this tree and the other, interleaved."""
    here = str(Path(__file__).resolve().parent.parent / "src")
    trees = {
        "this": (here, os.environ.get("AMSFE_GENERATED_DIR", "")),
        "other": (other_src, other_gen),
    }
    times: dict[str, list[float]] = {"this": [], "other": []}
    cpu: dict[str, list[float]] = {"this": [], "other": []}
    digests: dict[str, set[str]] = {"this": set(), "other": set()}
    for i in range(repeat + 1):  # the first round compiles and warms: not counted
        for name in ("this", "other") if i % 2 else ("other", "this"):
            src, gen = trees[name]
            env = {**os.environ, "PYTHONPATH": src}
            if gen:
                env["AMSFE_GENERATED_DIR"] = gen
            out = subprocess.run(
                [sys.executable, "-c", _APPLIED, str(bag)],
                env=env,
                check=True,
                capture_output=True,
                text=True,
            )
            lines = out.stdout.strip().splitlines()
            digests[name].add(lines[-3])
            cpu[name].append(float(lines[-2]))
            times[name].append(float(lines[-1]))
    med = {k: statistics.median(v[1:]) for k, v in times.items()}
    med_cpu = {k: statistics.median(v[1:]) for k, v in cpu.items()}
    same = len(digests["this"] | digests["other"]) == 1
    return {
        "times": times,
        "cpu": cpu,
        "median": med,
        "median_cpu": med_cpu,
        "this/other": med["this"] / med["other"],
        "this/other_cpu": med_cpu["this"] / med_cpu["other"],
        "x_hat_and_P_diag_bit_identical": same,
    }


_TUNED = (
    '[filter]\nencoder_q_std = "log"\nencoder_qd_std = "log"\nlink_torque_std = 0.7\n'
    "motor_torque_std = 0.7\n"
)
REAL_SPECS = {
    "jt-tuned": '[joints]\npositions = "link"\n[effort]\nkind = "joint_torque"\n' + _TUNED,
    "none-tuned": _TUNED,
}


def real_recording(bag: Path, out: Path) -> dict[str, Any]:
    """docs/how-to/logs.md's real Panda bag with each spec of REAL_SPECS, C and Python."""
    import numpy as np

    from amsfe_sym.apps.estimate import EstimateOptions, estimate_command

    report: dict[str, Any] = {}
    for name, text in REAL_SPECS.items():
        spec = out / f"{name}.toml"
        spec.write_text(text)
        got = {}
        for runtime in ("compiled", "python"):
            opts = EstimateOptions(
                robot="panda", log_spec=str(spec), estimator="replay", plots=False, force=True
            )
            run = estimate_command(
                bag, out / f"real-{name}-{runtime}", dataclasses.replace(opts, runtime=runtime)
            )
            got[runtime] = run
        c, p = got["compiled"].estimate, got["python"].estimate

        def rel(a: Any, b: Any) -> float:
            return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))

        nis = np.isfinite(p.encoder_nis)
        report[name] = {
            "ticks": int(c.x_hat.shape[0]),
            **{f"{r}_read_s": got[r].read_s for r in got},
            **{f"{r}_estimate_s": got[r].estimate_s for r in got},
            "x_rel": rel(c.x_hat, p.x_hat),
            "P_diag_rel": rel(c.P_diag, p.P_diag),
            "encoder_nis_rel": float(
                np.max(np.abs(c.encoder_nis[nis] - p.encoder_nis[nis]) / p.encoder_nis[nis])
            ),
        }
        print(name, json.dumps(report[name]), flush=True)
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="/tmp/amsfe-effort-speed")
    ap.add_argument("--estimators", nargs="*", default=["replay", "oosm"])
    ap.add_argument("--kinds", nargs="+", default=["joint_torque"])
    ap.add_argument("--repeat", type=int, default=3, help="C runs per case (median)")
    ap.add_argument("--python-repeat", type=int, default=1, help="Python runs per case")
    ap.add_argument("--applied-ratio", default=None, metavar="OTHER_SRC")
    ap.add_argument("--other-gen", default="", help="AMSFE_GENERATED_DIR of the other tree")
    ap.add_argument("--real", default=None, metavar="BAG", help="docs/how-to/logs.md's Panda bag")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {"cases": {}}
    if a.real:
        report["real"] = real_recording(Path(a.real), out)
    if not (a.estimators or a.applied_ratio):
        (out / "effort-speed.json").write_text(json.dumps(report, indent=1))
        return 0
    bag, applied = write_logs(out)
    report["log"] = str(bag)
    for kind in a.kinds:
        for est in a.estimators:
            for runtime, reps in (("compiled", a.repeat), ("python", a.python_repeat)):
                runs = [estimate(bag, kind, est, runtime, out) for _ in range(reps)]
                if not runs:
                    continue
                best = sorted(runs, key=lambda r: r["read_s"] + r["estimate_s"])[len(runs) // 2]
                key = f"{kind} {est} {runtime}"
                report["cases"][key] = {k: v for k, v in best.items() if k != "x_last"}
                print(
                    f"{key}: read {best['read_s']:.2f} s + estimate {best['estimate_s']:.2f} s"
                    f" = {best['rtf']:.1f}x real time ({best['frames_applied']} frames fused)",
                    flush=True,
                )
    if a.applied_ratio:
        report["applied"] = applied_ratio(applied, a.applied_ratio, a.other_gen, a.repeat)
        med = report["applied"]["median"]
        print(
            f"applied run_log: this {med['this']:.3f} s, other {med['other']:.3f} s, "
            f"ratio {report['applied']['this/other']:.3f} (CPU time: "
            f"{report['applied']['this/other_cpu']:.3f}); x_hat and diag P bit-identical: "
            f"{report['applied']['x_hat_and_P_diag_bit_identical']}"
        )
    (out / "effort-speed.json").write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
