"""Write logs shaped like real arms' recordings (the writers of tests/real_logs.py).

* ``franka``: a ROS 1 ``.bag`` as franka_ros records a Panda: ``/joint_states`` at 30 Hz,
  position, velocity and measured joint torque for 7 joints + 2 fingers, header stamps
  203.6 s ahead of the log time, stamp jitter and latency as measured on a real recording
  (docs/data/real-recording.md);
* ``ur``: a rosbag2 folder (MCAP or sqlite3) as a UR driver's ``/joint_states``: 125 Hz,
  alphabetical joint order, motor currents as effort.

The motion is a smooth sinusoid per joint (tests/real_logs.py ``smooth_motion``: not the
dynamics of any arm), or with ``--scenario`` a simulated run of a shipped scenario on its
robot (``panda-control`` for franka, ``ur5-demo`` / ``ur5-control`` for ur): the effort is
then the spring torque Ks (qm - q) (franka: what its torque sensors measure) or the applied
torque u turned into currents (ur), and ``--truth FILE.npz`` saves the run's true state and
which sample each message carries.  Usage::

    .venv/bin/python tools/make_real_like_logs.py franka OUT.bag [--duration 60] [--seed 0]
        [--offset 203.6] [--jitter 4.9e-5] [--repeat 0.0] [--scenario panda-control]
        [--truth OUT.npz]
    .venv/bin/python tools/make_real_like_logs.py ur OUT_FOLDER [--storage mcap|sqlite3]
        [--rate 125] [--scenario ur5-demo]

The outputs must not exist; nothing else is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Literal

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.real_logs import (  # (after the repository root is on the path)
    FRANKA_ARM,
    UR_JOINTS,
    ArmMotion,
    FrankaLikeOptions,
    URLikeOptions,
    motion_from_run,
    smooth_motion,
    write_franka_like_bag,
    write_ur_like_rosbag2,
)

_RUN: list[Any] = []  # the simulated run behind the motion, if any


def _motion(
    a: argparse.Namespace,
    names: tuple[str, ...],
    effort: Literal["joint_torque", "applied"],
    rng: np.random.Generator,
) -> ArmMotion:
    if a.scenario is None:
        return smooth_motion(names, a.duration, 0.001, rng)
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    sc = load_scenario(a.scenario).with_overrides(duration=a.duration)
    res = run(sc, lib=library_for(sc))
    _RUN.append(res)
    motion = motion_from_run(res, effort)
    if motion.names != names:
        raise SystemExit(
            f"make_real_like_logs: scenario {a.scenario} moves {motion.names}; pass a scenario "
            f"of a robot with joints {names}"
        )
    return motion


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kind", choices=["franka", "ur"])
    ap.add_argument("out", type=Path, help="the .bag (franka) or rosbag2 folder (ur) to write")
    ap.add_argument("--duration", type=float, default=60.0, help="[s]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rate", type=float, help="[Hz] (franka 30, ur 125)")
    ap.add_argument("--offset", type=float, help="header stamps minus log time [s]")
    ap.add_argument("--jitter", type=float, help="stamp std about the grid [s]")
    ap.add_argument("--repeat", type=float, default=0.0, help="franka: P(sample re-sent)")
    ap.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    ap.add_argument("--scenario", help="simulate this shipped scenario for the motion")
    ap.add_argument("--truth", type=Path, help="with --scenario: save the truth (.npz)")
    a = ap.parse_args(argv)
    for out in (a.out, a.truth):
        if out is not None and out.exists():
            print(f"make_real_like_logs: {out} exists; pass a new path (nothing was written)")
            return 2
    if a.truth is not None and a.scenario is None:
        print("make_real_like_logs: --truth needs --scenario (a sinusoid has no other truth)")
        return 2
    if not a.duration > 0:
        print(f"make_real_like_logs: --duration {a.duration}; pass a duration > 0 s")
        return 2
    rng = np.random.default_rng(a.seed)
    if a.kind == "franka":
        f = FrankaLikeOptions()
        opts = FrankaLikeOptions(
            rate_hz=a.rate or f.rate_hz,
            clock_offset=f.clock_offset if a.offset is None else a.offset,
            stamp_jitter=f.stamp_jitter if a.jitter is None else a.jitter,
            repeat_probability=a.repeat,
        )
        motion = _motion(a, FRANKA_ARM, "joint_torque", rng)
        log = write_franka_like_bag(a.out, motion, rng, opts)
    else:
        u = URLikeOptions()
        uopts = URLikeOptions(
            rate_hz=a.rate or u.rate_hz,
            clock_offset=u.clock_offset if a.offset is None else a.offset,
            stamp_jitter=u.stamp_jitter if a.jitter is None else a.jitter,
            storage=a.storage,
        )
        motion = _motion(a, UR_JOINTS, "applied", rng)
        log = write_ur_like_rosbag2(a.out, motion, rng, uopts)
    if a.truth is not None and _RUN:
        res = _RUN[0]
        np.savez(
            a.truth,
            t=res.t,
            x_true=res.x_true,
            u=res.u,
            sample_index=log.sample_index,
            true_time=log.true_time,
            stamp_ns=log.stamp_ns,
            log_time_ns=log.log_time_ns,
            joints=np.array(res.lib.manifest.joints),
        )
        print(f"wrote {a.truth}: the run's t, x_true, u and each message's sample")
    print(
        f"wrote {log.path}: {len(log.stamp_ns)} messages on {log.topic}, joints "
        f"{', '.join(log.names)}; header stamps {log.clock_offset_s:+g} s from the log time"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
