"""Write logs shaped like real arms' recordings (the writers of tests/real_logs.py).

* ``franka``: a ROS 1 ``.bag`` as franka_ros records a Panda: ``/joint_states`` at 30 Hz,
  position, velocity and measured joint torque for 7 joints + 2 fingers, header stamps
  203.6 s ahead of the log time, stamp jitter and latency as measured on a real recording
  (docs/data/real-recording.md);
* ``ur``: a rosbag2 folder (MCAP or sqlite3) as a UR driver's ``/joint_states``: 125 Hz,
  alphabetical joint order, motor currents as effort.

The motion is a smooth sinusoid per joint (tests/real_logs.py ``smooth_motion``: not the
dynamics of any arm; the tests feed simulated runs instead).  Usage::

    .venv/bin/python tools/make_real_like_logs.py franka OUT.bag [--duration 60] [--seed 0]
        [--offset 203.6] [--jitter 4.9e-5] [--repeat 0.0]
    .venv/bin/python tools/make_real_like_logs.py ur OUT_FOLDER [--storage mcap|sqlite3]
        [--rate 125]

The output must not exist; nothing else is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.real_logs import (  # (after the repository root is on the path)
    FRANKA_ARM,
    UR_JOINTS,
    FrankaLikeOptions,
    URLikeOptions,
    smooth_motion,
    write_franka_like_bag,
    write_ur_like_rosbag2,
)


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
    a = ap.parse_args(argv)
    if a.out.exists():
        print(f"make_real_like_logs: {a.out} exists; pass a new path (nothing was written)")
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
        motion = smooth_motion(FRANKA_ARM, a.duration, 0.001, rng)
        log = write_franka_like_bag(a.out, motion, rng, opts)
    else:
        u = URLikeOptions()
        uopts = URLikeOptions(
            rate_hz=a.rate or u.rate_hz,
            clock_offset=u.clock_offset if a.offset is None else a.offset,
            stamp_jitter=u.stamp_jitter if a.jitter is None else a.jitter,
            storage=a.storage,
        )
        motion = smooth_motion(UR_JOINTS, a.duration, 0.001, rng)
        log = write_ur_like_rosbag2(a.out, motion, rng, uopts)
    print(
        f"wrote {log.path}: {len(log.stamp_ns)} messages on {log.topic}, joints "
        f"{', '.join(log.names)}; header stamps {log.clock_offset_s:+g} s from the log time"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
