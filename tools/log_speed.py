"""Speed and memory of reading and estimating a recorded log (docs/how-to/logs.md, "Speed"): the
10 s, 1 kHz paper-sim log (paper_2link) and the 60 s, 1 kHz panda-control log (7 joints, a
30 Hz camera), written by ``amsfe simulate --bag`` with fixed seeds, each timed before and
after in the same run, interleaved, the median of ``--repeat`` runs:

- ``read_log``: the log reader as it is in this tree (``logs/read.py``);
- ``iter+ref``: every message of the estimator's topics through ``iter_messages`` and decoded
  one by one by ``rosbags`` (the reference decoders of ``logs/decode.py``);
- ``read_topics``: the same topics read and decoded in bulk (``logs/stream.py``);
- ``per-tick``: ``estimate_log(..., batch=False)``, one Python ``step`` per tick;
- ``grid``: the tick grid from read_topics' columns (:func:`grid_log`, checked equal to
  read_log's on these logs);
- ``batch``: ``estimate_log`` of a compiled estimator, one C call per 2000 ticks.

Also a ROS 1 ``.bag`` of 60,000 9-joint JointStates (franka_ros' shape): read_topics
against ``rosbags``' bag reader + the reference decoding, CPU time.

Peak RSS is measured in a fresh process per (log, path): ``before`` = read_log + per-tick,
``after`` = read_topics + grid + batch.

``--imports BEFORE AFTER`` (the same trees) sums ``python -X importtime``'s self times of
``amsfe estimate LOG --no-plots`` by top-level package (numpy, scipy, pandas, ...), median of
``--repeat`` interleaved runs on the 10 s paper-sim log.

``--command BEFORE AFTER`` (two source trees, each ``TREE:GENERATED_DIR``) times the command
itself instead, ``amsfe estimate LOG --no-plots`` in a fresh process per run, the two trees
interleaved (their order alternating by round), with a bare ``python -c pass`` per round:
the process's wall time seen from outside, what the command printed (read + estimate) and,
where the tree reports them, its phases (``summary.json`` ``timing``); medians and the
before / after ratio (docs/how-to/logs.md, "Speed").

    .venv/bin/python tools/log_speed.py            # writes the logs into /tmp/amsfe-log-speed
    .venv/bin/python tools/log_speed.py --repeat 5 --out DIR
    .venv/bin/python tools/log_speed.py --command OLD/src:OLD_GEN NEW/src:NEW_GEN --repeat 5
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

LOGS = {  # name: (scenario, duration [s], seed)
    "paper-sim 10 s": ("paper-sim", 10.0, 1),
    "panda-control 60 s": ("panda-control", 60.0, 1),
}
TOPICS = ("/motor_encoders", "/motor_torque", "/camera/marker", "/amsfe/truth", "/amsfe/config")


def write_logs(out: Path) -> dict[str, Path]:
    """``amsfe simulate SCENARIO --bag`` for each log (skipped when its bag exists)."""
    bags = {}
    for name, (scenario, duration, seed) in LOGS.items():
        folder = out / scenario
        bag = folder / "bag"
        if not (bag / "metadata.yaml").is_file():
            cmd = [
                sys.executable, "-m", "amsfe_sym", "simulate", scenario, "--controller",
                "amsfe", "--duration", str(duration), "--seed", str(seed), "--bag",
                "--out", str(folder), "--no-plots", "--no-progress", "--force",
            ]  # fmt: skip
            print("$", " ".join(cmd[1:]), flush=True)
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        bags[name] = bag
    return bags


def _setup(bag: Path) -> tuple[Any, Any, Any]:
    from amsfe_sym.apps.estimate import EstimateOptions, _scenario
    from amsfe_sym.codegen import library_for
    from amsfe_sym.logs.read import read_config
    from amsfe_sym.logs.spec import LogSpec

    spec = LogSpec()
    sc = _scenario(bag, read_config(bag, spec), EstimateOptions())
    return spec, sc, library_for(sc)


def _estimator(sc: Any, lib: Any, z0: Any) -> Any:
    import numpy as np

    from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing

    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    return build_estimator(sc, lib, sensors, z0, compiled=True)


def _timed(fn: Any) -> tuple[tuple[float, float], Any]:
    """(wall, CPU) [s] of ``fn()``, and its result."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return (time.perf_counter() - t0, time.process_time() - c0), out


def grid_log(bag: Path, topics: dict[str, Any], joints: Any, T: float, N: int) -> Any:
    """A RobotLog from ``read_topics``' columns, vectorised, for the clean logs ``amsfe
    simulate --bag`` writes (every stamp on the grid, no gap, one layout per topic): the
    tick grid of logs/read.py's docstring, so that the "after" path is timed whole.  Not a
    reader (no tolerance handling, no refusals): :func:`measure` checks it equals read_log.
    """
    import math

    import numpy as np

    from amsfe_sym.core.camera_frame import CameraFrame
    from amsfe_sym.logs.read import RobotLog

    def order(js: Any) -> Any:
        if len(js.names) != 1:
            raise SystemExit(f"{bag}: more than one joint-name list; use read_log")
        names = list(js.names[0])
        return [names.index(j) for j in joints]

    enc = topics["/motor_encoders"].decoded
    idx = order(enc)
    t0 = int(enc.stamp_ns.min())
    k = np.rint((enc.stamp_ns - t0) * 1e-9 / T).astype(np.int64)
    K = int(k.max()) + 1
    z = np.full((K, 2 * len(idx)), np.nan)
    z[k] = np.hstack([enc.position[:, idx], enc.velocity[:, idx]])
    tq = topics["/motor_torque"].decoded
    kt = np.rint((tq.stamp_ns - t0) * 1e-9 / T).astype(np.int64)
    u = np.full((K, len(idx)), np.nan)
    u[kt[kt < K]] = tq.effort[kt < K][:, order(tq)]
    have = np.isfinite(u).all(axis=1)
    last = np.maximum.accumulate(np.where(have, np.arange(K), 0))
    u = u[last]  # zero-order hold
    cam = topics["/camera/marker"]
    kappa = np.rint((cam.decoded.stamp_ns - t0) * 1e-9 / T).astype(np.int64)
    arrive = [math.ceil((t - t0) * 1e-9 / T - 0.25) for t in cam.log_time_ns.tolist()]
    frames = [
        CameraFrame(int(a), cam.decoded.xyz[i, :2].copy(), int(b))
        for i, (a, b) in enumerate(zip(kappa.tolist(), arrive, strict=True))
        if b < K
    ]
    truth = None
    if "/amsfe/truth" in topics:
        tr = topics["/amsfe/truth"]
        kk = np.rint((tr.log_time_ns - t0) * 1e-9 / T).astype(np.int64)
        truth = np.full((K, N), np.nan)
        ok = (kk >= 0) & (kk < K) & (tr.decoded.counts == N)
        truth[kk[ok]] = tr.decoded.values[ok][:, :N]
    return RobotLog(bag, T, t0, z, u, frames, truth, None, {})


def _same_log(a: Any, b: Any) -> bool:
    import numpy as np

    arrays = all(
        np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in ("z", "u", "truth")
    )
    fa = [(f.exposure_step, f.delivery_step, tuple(f.z)) for f in a.frames]
    fb = [(f.exposure_step, f.delivery_step, tuple(f.z)) for f in b.frames]
    return bool(arrays and fa == fb and a.t0_ns == b.t0_ns)


def measure(bag: Path, repeat: int) -> dict[str, Any]:
    """Median times [s] of each part over ``repeat`` interleaved runs."""
    from amsfe_sym.logs import decode
    from amsfe_sym.logs.read import read_log
    from amsfe_sym.logs.replay import estimate_log
    from amsfe_sym.logs.source import iter_messages
    from amsfe_sym.logs.stream import read_topics

    spec, sc, lib = _setup(bag)
    times: dict[str, list[tuple[float, float]]] = {}

    def iter_ref() -> None:
        by: dict[tuple[str, str], list[bytes]] = {}
        for m in iter_messages(bag, set(TOPICS)):
            by.setdefault((m.topic, m.msgtype), []).append(m.raw)
        for (_, msgtype), raws in by.items():
            kind = decode.DECODERS[msgtype].__name__.removeprefix("decode_")
            getattr(decode, f"_reference_{kind}")(raws)

    log = None
    for _ in range(repeat):
        dt, log = _timed(lambda: read_log(bag, spec, lib.manifest.joints, lib.T, lib.N))
        times.setdefault("read_log", []).append(dt)
        times.setdefault("iter+ref", []).append(_timed(iter_ref)[0])
        dt, topics = _timed(lambda: read_topics(bag, TOPICS, progress=False))
        times.setdefault("read_topics", []).append(dt)
        dt, gridded = _timed(lambda t=topics: grid_log(bag, t, lib.manifest.joints, lib.T, lib.N))
        times.setdefault("grid", []).append(dt)
        if not _same_log(gridded, log):
            raise SystemExit(f"{bag}: the tool's grid differs from read_log's")
        for label, batch in (("per-tick", False), ("batch", True)):
            est = _estimator(sc, lib, log.z[0])
            dt = _timed(lambda g=log, e=est, b=batch: estimate_log(g, e, batch=b, progress=False))[
                0
            ]
            times.setdefault(label, []).append(dt)
    assert log is not None  # repeat >= 1 (argparse)
    med = {k: statistics.median(w for w, _ in v) for k, v in times.items()}
    med |= {f"{k} cpu": statistics.median(c for _, c in v) for k, v in times.items()}
    return {"ticks": log.K, "duration_s": log.K * log.T, "frames": len(log.frames), **med}


def _vm(key: str) -> float:
    """A ``/proc/self/status`` size [MB] (VmRSS: now, VmHWM: the peak since the last reset)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")


def peak_rss(bag: Path, path: str) -> dict[str, float]:
    """One path in this (fresh) process: how far its peak RSS [MB] rises above the process
    ready to read (the library loaded), and its wall and CPU times [s].  ``before``: read_log
    + the per-tick estimate; ``after``: read_topics + :func:`grid_log` + the batch."""
    import mcap.reader  # noqa: F401 - imports are not the log's: loaded before the clock
    import numpy as np
    import zstandard  # noqa: F401

    from amsfe_sym.logs.read import read_log
    from amsfe_sym.logs.replay import estimate_log
    from amsfe_sym.logs.stream import read_topics

    spec, sc, lib = _setup(bag)
    est = _estimator(sc, lib, np.zeros(2 * len(lib.manifest.joints)))  # warm: scipy, ctypes
    del est
    ready = _vm("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM <- VmRSS (Linux >= 4.0)
    t0, c0 = time.perf_counter(), time.process_time()
    if path == "after":
        topics = read_topics(bag, TOPICS, progress=False)
        log = grid_log(bag, topics, lib.manifest.joints, lib.T, lib.N)
    else:
        log = read_log(bag, spec, lib.manifest.joints, lib.T, lib.N)
    est = _estimator(sc, lib, np.asarray(log.z[0]))
    estimate_log(log, est, batch=path == "after", progress=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if path == "after":
        del topics
    return {"rise_mb": _vm("VmHWM") - ready, "wall_s": wall, "cpu_s": cpu}


def per_type(bag: Path) -> list[tuple[str, str, int, float, float]]:
    """Each topic's payloads (as iter_messages gives them) decoded by the reference and by
    the bulk decoder: (topic, type, messages, reference CPU [s], bulk CPU [s]), median of 3."""
    from amsfe_sym.logs import decode
    from amsfe_sym.logs.source import iter_messages

    by: dict[tuple[str, str], list[bytes]] = {}
    for m in iter_messages(bag, set(TOPICS)):
        by.setdefault((m.topic, m.msgtype), []).append(m.raw)
    rows = []
    for (topic, msgtype), raws in sorted(by.items()):
        bulk = decode.DECODERS[msgtype]
        ref = getattr(decode, "_reference_" + bulk.__name__.removeprefix("decode_"))
        cpu = [
            statistics.median(_timed(lambda f=f, r=raws: f(r))[0][1] for _ in range(3))
            for f in (ref, bulk)
        ]
        rows.append((topic, msgtype, len(raws), cpu[0], cpu[1]))
    return rows


def ros1_bag(out: Path, count: int = 60_000) -> dict[str, float]:
    """A ROS 1 bag of ``count`` 9-joint JointStates at 1 kHz (franka_ros' /joint_states shape,
    random values, seed 0): CPU time [s] of read_topics against rosbags' bag reader followed
    by the reference decoding, median of 3."""
    import numpy as np
    from rosbags.rosbag1 import Reader, Writer

    from amsfe_sym.logs import decode
    from amsfe_sym.logs.stream import read_topics

    path = out / "joint_states.bag"
    if not path.is_file():
        ts = decode.typestore("ros1")
        T = ts.types
        names = [f"panda_joint{i}" for i in range(1, 8)] + ["finger1", "finger2"]
        rng = np.random.default_rng(0)
        with Writer(path) as w:
            c = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
            for k in range(count):
                t = 1_700_000_000 * 10**9 + k * 10**6
                stamp = T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
                msg = T["sensor_msgs/msg/JointState"](
                    header=T["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id=""),
                    name=names,
                    position=rng.normal(size=9),
                    velocity=rng.normal(size=9),
                    effort=rng.normal(size=9),
                )
                w.write(c, t, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/JointState")))

    def reference() -> None:
        with Reader(path) as r:
            raws = [bytes(raw) for _, _, raw in r.messages()]
        decode._reference_joint_states(raws, "ros1")

    bulk = statistics.median(
        _timed(lambda: read_topics(path, {"/joint_states"}, progress=False))[0][1] for _ in range(3)
    )
    ref = statistics.median(_timed(reference)[0][1] for _ in range(3))
    return {"messages": count, "mb": path.stat().st_size / 1e6, "bulk_cpu": bulk, "ref_cpu": ref}


def _tree_env(tree: str) -> dict[str, str]:
    """The environment of a ``TREE_SRC:GENERATED_DIR`` tree's processes."""
    import os

    src, _, gen = tree.partition(":")
    return {**os.environ, "PYTHONPATH": src, "AMSFE_GENERATED_DIR": gen}


def _outer(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU (user + system) time [s] of a child process."""
    import resource

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def command_runs(
    trees: list[str], bags: dict[str, Path], out: Path, repeat: int, plots: bool = False
) -> None:
    """``amsfe estimate LOG --no-plots`` (``plots``: with its figures) of each tree in fresh
    processes, interleaved."""
    import os

    envs = [_tree_env(t) for t in trees]
    load0 = os.getloadavg()
    rows: dict[tuple[str, int], list[dict[str, Any]]] = {}
    bare: list[float] = []
    for r in range(repeat):
        bare.append(_outer([sys.executable, "-c", "pass"], envs[0])[0])
        for name, bag in bags.items():
            order = range(len(trees)) if r % 2 == 0 else reversed(range(len(trees)))
            for i in order:
                folder = out / f"command-{i}"
                cmd = [sys.executable, "-m", "amsfe_sym", "estimate", str(bag), "--out",
                       str(folder), "--force"] + ([] if plots else ["--no-plots"])  # fmt: skip
                wall, cpu = _outer(cmd, envs[i])
                s = json.loads((folder / "summary.json").read_text())
                rows.setdefault((name, i), []).append({"process_s": wall, "cpu_s": cpu, **s})
    load1 = os.getloadavg()
    py = statistics.median(bare)
    print(
        f"\namsfe estimate LOG{'' if plots else ' --no-plots'}, fresh processes, median of "
        f"{repeat} interleaved "
        f"runs; python -c pass {py:.3f} s; load average {load0[0]:.2f} -> {load1[0]:.2f}"
    )
    for name in bags:
        print(f"\n{name}:")
        meds = []
        for i, tree in enumerate(trees):
            runs = rows[(name, i)]
            d = runs[0]["duration_s"]
            keys = ("process_s", "cpu_s", "read_s", "estimate_s")
            m = {k: statistics.median(x[k] for x in runs) for k in keys}
            phases = ""
            if all("timing" in x for x in runs):
                phase_keys = ("startup_s", "setup_s", "library_s", "write_s", "wall_s")
                t = {k: statistics.median(x["timing"][k] or 0.0 for x in runs) for k in phase_keys}
                phases = (
                    f"; start-up {t['startup_s']:.3f}, setup {t['setup_s']:.3f}, library "
                    f"{t['library_s']:.3f}, writing {t['write_s']:.3f}, command wall "
                    f"{t['wall_s']:.3f} s = {d / t['wall_s']:.0f}x"
                )
            le = m["read_s"] + m["estimate_s"]
            print(
                f"  {tree}: process {m['process_s']:.3f} s = {d / m['process_s']:.1f}x real "
                f"time ({d / (m['process_s'] - py):.1f}x without python's start + exit; CPU "
                f"{m['cpu_s']:.3f} s = {d / m['cpu_s']:.1f}x); read "
                f"{m['read_s']:.3f} + estimate {m['estimate_s']:.3f} = {le:.3f} s = "
                f"{d / le:.0f}x{phases}"
            )
            meds.append(m)
        if len(meds) == 2:
            a, b = meds
            le_a, le_b = a["read_s"] + a["estimate_s"], b["read_s"] + b["estimate_s"]
            print(
                f"  before / after: process {a['process_s'] / b['process_s']:.2f}x faster (CPU "
                f"{a['cpu_s'] / b['cpu_s']:.2f}x), read + estimate {le_a / le_b:.2f}x"
            )


def import_costs(trees: list[str], bag: Path, out: Path, repeat: int) -> None:
    """``-X importtime`` self times of ``amsfe estimate`` by top-level package, per tree."""
    import collections
    import os

    envs = [_tree_env(t) for t in trees]
    runs: list[list[collections.Counter[str]]] = [[] for _ in trees]
    for r in range(repeat):
        for i in range(len(trees)) if r % 2 == 0 else reversed(range(len(trees))):
            cmd = [sys.executable, "-X", "importtime", "-m", "amsfe_sym", "estimate", str(bag),
                   "--out", str(out / f"imports-{i}"), "--no-plots", "--force"]  # fmt: skip
            err = subprocess.run(cmd, env=envs[i], capture_output=True, text=True).stderr
            by: collections.Counter[str] = collections.Counter()
            for line in err.splitlines():
                cells = line.removeprefix("import time:").split("|")
                if line.startswith("import time:") and cells[0].strip().isdigit():
                    by[cells[2].strip().split(".")[0]] += int(cells[0])
            runs[i].append(by)

    def med(i: int, k: str | None) -> float:
        return statistics.median((sum(b.values()) if k is None else b[k]) for b in runs[i]) / 1e3

    names = {k for rs in runs for b in rs for k in b}
    top = sorted(names, key=lambda k: -sum(med(i, k) for i in range(len(trees))))[:14]
    print(f"\n-X importtime self times by package [ms], median of {repeat}, load average "
          f"{os.getloadavg()[0]:.2f}: " + " | ".join(trees))  # fmt: skip
    for k in [*top, None]:
        print(f"  {k or 'all':20s}" + "".join(f"{med(i, k):10.0f}" for i in range(len(trees))))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", default="/tmp/amsfe-log-speed", help="where the logs are written")
    p.add_argument("--repeat", type=int, default=3, choices=range(1, 50), metavar="N")
    p.add_argument("--rss", nargs=2, metavar=("BAG", "PATH"), help=argparse.SUPPRESS)
    p.add_argument("--plots", action="store_true", help="--command: with the figures")
    p.add_argument("--imports", nargs=2, metavar=("BEFORE", "AFTER"), help="import cost by package")
    p.add_argument(
        "--command",
        nargs=2,
        metavar=("BEFORE", "AFTER"),
        help="time amsfe estimate of two trees, each TREE_SRC:GENERATED_DIR",
    )
    args = p.parse_args()
    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    if args.rss:
        print(json.dumps(peak_rss(Path(args.rss[0]), args.rss[1])))
        return
    if args.imports:
        bag = write_logs(Path(args.out))["paper-sim 10 s"]
        import_costs(list(args.imports), bag, Path(args.out), args.repeat)
        return
    if args.command:
        bags = write_logs(Path(args.out))
        command_runs(list(args.command), bags, Path(args.out), args.repeat, args.plots)
        return
    r1 = ros1_bag(Path(args.out))
    print(
        f"ROS 1 bag, {r1['messages']} JointStates ({r1['mb']:.1f} MB): read_topics CPU "
        f"{r1['bulk_cpu']:.3f} s; rosbags' reader + reference decoding CPU {r1['ref_cpu']:.3f} s"
    )
    bags = write_logs(Path(args.out))
    for name, bag in bags.items():
        print(f"\n{name}: decoding per type, CPU (reference -> bulk):")
        for topic, msgtype, count, ref, bulk in per_type(bag):
            print(
                f"  {topic:16s} {msgtype:32s} {count:6d} msgs  {1e6 * ref / count:6.1f} -> "
                f"{1e6 * bulk / count:5.2f} us a message ({ref / max(bulk, 1e-9):.0f}x)"
            )
        m = measure(bag, args.repeat)
        d = m["duration_s"]
        before = m["read_log"] + m["per-tick"]
        after = m["read_topics"] + m["grid"] + m["batch"]
        print(f"\n{name}: {m['ticks']} ticks, {m['frames']} frames, {bag}")
        for k in ("read_log", "iter+ref", "read_topics", "grid", "per-tick", "batch"):
            print(f"  {k:12s} wall {m[k]:8.3f} s  CPU {m[k + ' cpu']:8.3f} s")
        cb = m["read_log cpu"] + m["per-tick cpu"]
        ca = m["read_topics cpu"] + m["grid cpu"] + m["batch cpu"]
        print(
            f"  end to end before (read_log + per-tick): {before:.3f} s = {d / before:.0f}x "
            f"real time; after (read_topics + grid + batch): {after:.3f} s = {d / after:.0f}x"
        )
        print(f"  on CPU time: before {d / cb:.0f}x, after {d / ca:.0f}x real time")
        for path in ("before", "after"):
            cmd = [sys.executable, __file__, "--rss", str(bag), path]
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            r = json.loads(out.strip().splitlines()[-1])
            print(
                f"  {path:6s} fresh process: peak RSS +{r['rise_mb']:.0f} MB over the process "
                f"ready to read; wall {r['wall_s']:.3f} s, CPU {r['cpu_s']:.3f} s "
                f"({d / r['cpu_s']:.0f}x real time on CPU time)"
            )


if __name__ == "__main__":
    main()
