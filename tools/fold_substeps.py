"""The rk4 substeps folded (one substep function called in a loop) against unrolled, in one
run (docs/explanation/codegen.md, "The rk4 substeps in a loop"): per robot and variant, the
generated C file's size, the CPU time of compiling it alone (``$CC -O1 -fPIC -c``, the
project's flags), the per-call time of the transition functions (the pure-C timer of
``amsfe bench``, the two variants interleaved), the largest relative difference of their
outputs at random states, and ``amsfe check`` on the folded library.

    PYTHONPATH=src .venv/bin/python tools/fold_substeps.py \\
        --robots panda@0.03333,ur5-rk4,paper_2link@0.5 --rounds 5 --out /tmp/fold.json

A robot is a shipped name, ``NAME@T`` (``spec_at_period``: its own library at period T [s]
with the substeps the modes choose) or ``NAME-rk4`` (the shipped spec with the rk4 model).
Nothing here is asserted by a test (the machine and its load move the times; the JSON
records the load average).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from amsfe_sym.load.spec import RobotSpec

_GEN = r"""
import json, sys
sys.path.insert(0, sys.argv[4])
from fold_substeps import spec_of
from amsfe_sym.codegen import generate
from amsfe_sym.symbolic import rk4_step
robot, out, fold = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
rk4_step.FOLD_SUBSTEPS = fold
r = generate(spec_of(robot), out=out, force=True)
print(json.dumps({"dir": str(r.out_dir), "timings": r.timings}))
"""


def spec_of(robot: str) -> RobotSpec:
    """The spec a robot argument names (module docstring)."""
    from amsfe_sym.codegen.modes import spec_at_period
    from amsfe_sym.load.spec import load_spec

    if "@" in robot:
        name, T = robot.split("@")
        return spec_at_period(name, float(T))
    if robot.endswith("-rk4"):
        spec = load_spec(robot[:-4])
        return replace(spec, model=replace(spec.model, integrator="rk4"))
    return load_spec(robot)


#: The functions timed and compared (``transition_step_chain`` is the C chain the estimators
#: call: not generated from the graph, so it is the same in both variants).
FUNCTIONS = (
    "transition_step",
    "transition_jacobian",
    "transition",
    "transition_inverse",
    "plant_step",
    "transition_step_chain",
)


def _generate(robot: str, out: Path, fold: bool) -> Path:
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            _GEN,
            robot,
            str(out),
            "1" if fold else "0",
            str(Path(__file__).parent),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return Path(json.loads(proc.stdout.strip().splitlines()[-1])["dir"])


def _compile_cpu_s(c_file: Path, workdir: Path) -> float:
    """CPU time [s] (user + sys) of compiling ``c_file`` alone with the project's flags."""
    from amsfe_sym.codegen import compiler

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(
        [compiler(), "-O1", "-fPIC", "-c", str(c_file), "-o", str(workdir / "unit.o")],
        check=True,
        cwd=c_file.parent,
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _inputs(lib: object, name: str, rng: np.random.Generator) -> list[np.ndarray]:
    """Random inputs of ``name``: a state near rest (springs slightly deflected), a torque."""
    n, N = lib.n, lib.N  # type: ignore[attr-defined]
    x = np.concatenate(
        [
            rng.uniform(-1.0, 1.0, n),
            rng.normal(0.0, 0.5, n),
            np.zeros(n),
            rng.normal(0.0, 0.5, n),
            np.array([t.initial for t in lib.manifest.theta]),  # type: ignore[attr-defined]
        ]
    )[:N]
    x[2 * n : 3 * n] = x[:n] + rng.normal(0.0, 1e-3, n)
    u = rng.normal(0.0, 1.0, n)
    if name == "plant_step":
        return [x[: 4 * n], u, x[4 * n :], np.zeros(2 * n)]
    return [x, u]


def _agreement(old: Path, new: Path, samples: int) -> dict[str, float]:
    """Largest ``max|new - old| / max|old|`` over the outputs of each function (the
    inverse's residual, two rounding errors, as its largest absolute value instead)."""
    from amsfe_sym.runtime.library import ModelLibrary

    a, b = ModelLibrary(old), ModelLibrary(new)
    worst: dict[str, float] = {}
    for name in FUNCTIONS:
        if name not in a.manifest.functions:
            continue
        rng = np.random.default_rng(0)
        for _ in range(samples):
            args = _inputs(a, name, rng)
            outs = zip(a.function(name)(*args), b.function(name)(*args), strict=True)
            for k, (ya, yb) in enumerate(outs):
                if name == "transition_inverse" and k == 1:  # the residual: rounding noise
                    key = "inverse_residual_abs"
                    worst[key] = max(
                        worst.get(key, 0.0), float(np.max(np.abs(ya))), float(np.max(np.abs(yb)))
                    )
                    continue
                scale = max(float(np.max(np.abs(ya))), 1e-300)
                err = float(np.max(np.abs(np.asarray(yb) - np.asarray(ya)))) / scale
                worst[name] = max(worst.get(name, 0.0), err)
    return worst


def _times(old: Path, new: Path, rounds: int) -> dict[str, dict[str, float]]:
    """Median over ``rounds`` interleaved samples (old, new, old, ...) of each function's
    per-call time [us] (each sample the median of 5 rounds of ``amsfe bench``'s timer)."""
    from amsfe_sym.apps.bench.timing import CTimer
    from amsfe_sym.runtime.library import ModelLibrary

    libs = {"unrolled": ModelLibrary(old), "folded": ModelLibrary(new)}
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        timer = CTimer(Path(tmp))
        for name in FUNCTIONS:
            if name not in libs["unrolled"].manifest.functions:
                continue
            args = _inputs(libs["unrolled"], name, np.random.default_rng(0))
            samples: dict[str, list[float]] = {k: [] for k in libs}
            for _ in range(rounds):
                for k, lib in libs.items():
                    t, _sum = timer.time(lib.library_path, name, args, 5, min_calls=20)
                    samples[k].append(t.median_us)
            med = {k: float(np.median(v)) for k, v in samples.items()}
            out[name] = {
                **{f"{k}_us": round(v, 3) for k, v in med.items()},
                "ratio": round(med["folded"] / med["unrolled"], 3),
            }
    return out


def measure(robot: str, workdir: Path, rounds: int, seeds: int) -> dict[str, object]:
    """Generate ``robot`` unrolled and folded and compare the two libraries."""
    from amsfe_sym.apps.check import run_checks
    from amsfe_sym.runtime.library import ModelLibrary

    row: dict[str, object] = {"robot": robot}
    dirs = {}
    for fold in (False, True):
        key = "folded" if fold else "unrolled"
        t0 = time.perf_counter()
        built = sorted((workdir / key).glob("*/manifest.json"))
        out = built[0].parent if built else _generate(robot, workdir / key, fold)
        wall = time.perf_counter() - t0
        c_file = out / f"{out.name}.c"
        row[key] = {
            "generate_wall_s": None if built else round(wall, 1),
            "c_bytes": c_file.stat().st_size,
            "c_lines": c_file.read_text().count("\n"),
            "compile_cpu_s": round(_compile_cpu_s(c_file, workdir), 2),
        }
        dirs[key] = out
    lib = ModelLibrary(dirs["folded"])
    row["model_substeps"] = lib.manifest.raw.get("model_substeps")
    row["plant_substeps"] = lib.manifest.raw.get("plant_substeps")
    row["max_rel_diff"] = _agreement(dirs["unrolled"], dirs["folded"], 5)
    row["per_call"] = _times(dirs["unrolled"], dirs["folded"], rounds)
    from amsfe_sym.load import load_robot

    spec_robot = load_robot(spec_of(robot))
    fails = [
        f"seed {s}: {r.function} {r.max_error:.3g}"
        for s in range(seeds)
        for r in run_checks(spec_robot, lib, samples=3, seed=s)
        if not r.passed
    ]
    row["check"] = {"seeds": seeds, "samples": 3, "failed": fails}
    row["loadavg_after"] = os.getloadavg()
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default="panda@0.03333,ur5-rk4", help="comma-separated")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved timing samples [5]")
    ap.add_argument("--seeds", type=int, default=5, help="amsfe check seeds (3 states) [5]")
    ap.add_argument("--out", type=Path, default=None, help="JSON file to write")
    ap.add_argument(
        "--workdir",
        type=Path,
        default=None,
        help="keep the libraries here (ROBOT/unrolled, ROBOT/folded; reused when built)",
    )
    args = ap.parse_args(argv)
    rows = []
    machine = {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        for robot in args.robots.split(","):
            row = measure(robot, (args.workdir or Path(tmp)) / robot, args.rounds, args.seeds)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.out:
        args.out.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
