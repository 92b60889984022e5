"""The facts of a recorded robot log, as docs/data/real-recording.md states them.

Reads any container rosbags' ``AnyReader`` opens (a ROS 1 ``.bag``, a rosbag2 folder with
MCAP or sqlite3 storage) and prints, for every topic: message type, count, rate; and for
every ``sensor_msgs/JointState`` topic: joint names, which of position / velocity / effort
are filled, the stamp period and its jitter, the clock offset between header stamps and the
recorder's log time (two machines), stamps that repeat, run backwards or are zero, samples
repeated verbatim, the velocity against the positions' finite differences and, with
``--urdf``, the effort at rest against the gravity torque g(q) of that URDF (Pinocchio).

Usage (the numbers in docs/data/real-recording.md)::

    .venv/bin/python tools/real_recording.py LOG [--urdf robots/panda/panda.urdf
        [--mass-at panda_hand_tcp]] [--json]

Nothing is written; ``--json`` prints the facts as one JSON object (the tests read it to
check this script against logs whose timing they made themselves, tests/real_logs.py).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
JOINT_STATE = ("sensor_msgs/msg/JointState", "sensor_msgs/JointState")
#: A joint is "at rest" in a sample when every arm joint moves slower than this [rad/s].
REST_SPEED = 0.01


@dataclass(frozen=True)
class Spread:
    """Median and extremes of a series (and its 1st / 99th percentile)."""

    median: float
    p01: float
    p99: float
    min: float
    max: float

    @staticmethod
    def of(x: FloatArray) -> Spread:
        if x.size == 0:
            nan = float("nan")
            return Spread(nan, nan, nan, nan, nan)
        p01, med, p99 = np.percentile(x, [1.0, 50.0, 99.0])
        return Spread(float(med), float(p01), float(p99), float(x.min()), float(x.max()))


@dataclass(frozen=True)
class TopicFacts:
    """One connection of the log."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float  # count over the topic's log-time span
    callerid: str | None = None


@dataclass(frozen=True)
class JointStateFacts:
    """What one JointState topic holds and how it is timed."""

    topic: str
    count: int
    names: list[str]
    names_constant: bool
    filled: dict[str, int]  # field -> entries per message (0: empty)
    stamp_period_s: Spread  # header stamp differences [s]
    log_period_s: Spread  # log time differences [s]
    jitter_over_period: Spread  # (stamp dt - median dt) / median dt
    stamp_minus_log_s: Spread  # header stamp - log time [s]; > 0: stamps ahead
    stamp_minus_log_mean_s: float
    grid_period_s: float  # the uniform grid fitted to the stamps (least squares) [s]
    grid_residual_std_s: float  # the stamps' std about that grid [s]
    gaps: int  # stamp differences over 1.5 median periods (messages missing)
    largest_gap_periods: float  # the largest stamp difference over the median
    backwards_stamps: int
    repeated_stamps: int
    zero_stamps: int
    repeated_samples: int  # consecutive messages with identical position and velocity
    position_range: dict[str, list[float]]  # joint -> [min, max] [rad] or [m]
    max_abs_velocity: dict[str, float]
    effort_range: dict[str, list[float]]
    effort_step: dict[str, float]  # smallest nonzero change between messages
    velocity_vs_difference: dict[str, float]  # rms(velocity - d position / d stamp)
    rest_samples: int = 0
    effort_minus_gravity_at_rest: dict[str, Spread] = field(default_factory=dict)
    mass_frame: str | None = None  # the point mass fitted to the rest residual sits here
    mass_fit_kg: float | None = None  # least squares over every rest sample and joint
    residual_after_mass_fit: dict[str, float] = field(default_factory=dict)  # medians [N m]


@dataclass(frozen=True)
class RecordingFacts:
    """A log: container, size, duration and its topics."""

    path: str
    container: str
    size_bytes: int
    start_ns: int
    end_ns: int
    duration_s: float
    message_count: int
    topics: list[TopicFacts]
    joint_states: list[JointStateFacts]


def _container(path: Path) -> str:
    if path.is_dir():
        kinds = {p.suffix for p in path.iterdir()}
        return "rosbag2 (" + ", ".join(s.lstrip(".") for s in sorted(kinds) if s) + ")"
    return {".bag": "ROS 1 bag", ".mcap": "MCAP"}.get(path.suffix, path.suffix)


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _gravity(urdf: Path, frame: str | None) -> Any:
    """A function q-by-name -> (g(q), J_p(q)^T [0, 0, 9.81]) by name: the URDF's gravity
    torque and the torque of 1 kg at the origin of ``frame`` (Pinocchio; zeros if no frame)."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    fid = model.getFrameId(frame) if frame else None
    if fid is not None and fid >= model.nframes:
        raise SystemExit(f"real_recording: no frame {frame!r} in {urdf}; pass one of its frames")

    def g(values: dict[str, float]) -> tuple[dict[str, float], dict[str, float]]:
        q = pin.neutral(model)
        for j in range(1, model.njoints):
            name = model.names[j]
            if name in values and model.joints[j].nq == 1:
                q[model.joints[j].idx_q] = values[name]
        tau = pin.computeGeneralizedGravity(model, data, q)
        unit = np.zeros(model.nv)
        if fid is not None:
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
            unit = jac.T @ np.array([0.0, 0.0, 9.81])
        out: dict[str, float] = {}
        per_kg: dict[str, float] = {}
        for j in range(1, model.njoints):
            if model.joints[j].nv == 1:
                out[model.names[j]] = float(tau[model.joints[j].idx_v])
                per_kg[model.names[j]] = float(unit[model.joints[j].idx_v])
        return out, per_kg

    return g


def _joint_state_facts(
    topic: str,
    stamps: FloatArray,
    logs: FloatArray,
    names: list[str],
    names_constant: bool,
    pos: FloatArray,
    vel: FloatArray,
    eff: FloatArray,
    urdf: Path | None,
    mass_frame: str | None = None,
) -> JointStateFacts:
    n = len(names)
    dts = np.diff(stamps)
    dtl = np.diff(logs)
    med = float(np.median(dts)) if dts.size else float("nan")
    filled = {"position": pos.shape[1], "velocity": vel.shape[1], "effort": eff.shape[1]}
    same = np.zeros(max(len(stamps) - 1, 0), dtype=bool)
    if pos.shape[1]:
        same = np.all(pos[1:] == pos[:-1], axis=1)
        if vel.shape[1]:
            same &= np.all(vel[1:] == vel[:-1], axis=1)

    def per_joint(a: FloatArray, f: Any) -> dict[str, Any]:
        return {names[i]: f(a[:, i]) for i in range(a.shape[1])} if a.shape[1] == n else {}

    def step(x: FloatArray) -> float:
        d = np.abs(np.diff(x))
        d = d[d > 0]
        return float(d.min()) if d.size else 0.0

    vvd: dict[str, float] = {}
    if pos.shape[1] == n and vel.shape[1] == n and len(stamps) > 2:
        ok = dts > 0
        fd = np.diff(pos, axis=0)[ok] / dts[ok, None]
        vm = 0.5 * (vel[1:] + vel[:-1])[ok]
        vvd = {names[i]: float(np.sqrt(np.mean((vm[:, i] - fd[:, i]) ** 2))) for i in range(n)}
    rest = 0
    egr: dict[str, Spread] = {}
    fit: float | None = None
    after: dict[str, float] = {}
    if urdf is not None and pos.shape[1] == n and eff.shape[1] == n:
        g = _gravity(urdf, mass_frame)
        moving = np.abs(vel) if vel.shape[1] == n else np.zeros_like(pos)
        arm = [i for i in range(n) if np.ptp(pos[:, i]) > 0 or np.any(eff[:, i] != 0)]
        at_rest = np.all(moving[:, arm] < REST_SPEED, axis=1)
        rest = int(at_rest.sum())
        res: list[list[float]] = []
        col: list[list[float]] = []
        for k in np.flatnonzero(at_rest):
            gk, uk = g({names[i]: float(pos[k, i]) for i in range(n)})
            used = [i for i in arm if names[i] in gk]
            res.append([float(eff[k, i]) - gk[names[i]] for i in used])
            col.append([uk[names[i]] for i in used])
        if res:
            r, c = np.asarray(res), np.asarray(col)
            egr = {names[i]: Spread.of(r[:, m]) for m, i in enumerate(used)}
            if mass_frame and float(np.sum(c * c)) > 0:
                fit = float(np.sum(c * r) / np.sum(c * c))
                left = np.median(r - fit * c, axis=0)
                after = {names[i]: float(left[m]) for m, i in enumerate(used)}
    grid, resid = float("nan"), float("nan")
    if len(stamps) > 2:
        # each stamp's slot on the grid (a dropped message leaves its slot empty)
        idx = np.round((stamps - stamps[0]) / med)
        a = np.vstack([idx, np.ones_like(idx)]).T
        coef = np.linalg.lstsq(a, stamps - stamps[0], rcond=None)[0]
        grid = float(coef[0])
        resid = float(np.std(stamps - stamps[0] - a @ coef))
    return JointStateFacts(
        topic=topic,
        count=len(stamps),
        names=names,
        names_constant=names_constant,
        filled=filled,
        stamp_period_s=Spread.of(dts),
        log_period_s=Spread.of(dtl),
        jitter_over_period=Spread.of((dts - med) / med) if dts.size else Spread.of(dts),
        stamp_minus_log_s=Spread.of(stamps - logs),
        stamp_minus_log_mean_s=float(np.mean(stamps - logs)),
        grid_period_s=grid,
        grid_residual_std_s=resid,
        gaps=int(np.sum(dts > 1.5 * med)),
        largest_gap_periods=float(dts.max() / med) if dts.size else float("nan"),
        backwards_stamps=int(np.sum(dts < 0)),
        repeated_stamps=int(np.sum(dts == 0)),
        zero_stamps=int(np.sum(stamps == 0)),
        repeated_samples=int(same.sum()),
        position_range=per_joint(pos, lambda x: [float(x.min()), float(x.max())]),
        max_abs_velocity=per_joint(vel, lambda x: float(np.abs(x).max())),
        effort_range=per_joint(eff, lambda x: [float(x.min()), float(x.max())]),
        effort_step=per_joint(eff, step),
        velocity_vs_difference=vvd,
        rest_samples=rest,
        effort_minus_gravity_at_rest=egr,
        mass_frame=mass_frame,
        mass_fit_kg=fit,
        residual_after_mass_fit=after,
    )


def _stack(rows: list[FloatArray], n: int) -> FloatArray:
    """The rows as a (messages, n) array, or (messages, 0) when a field is not filled."""
    if {a.size for a in rows} != {n}:
        return np.zeros((len(rows), 0))
    return np.vstack(rows)


def recording_facts(
    path: Path, urdf: Path | None = None, mass_frame: str | None = None
) -> RecordingFacts:
    """Read the log at ``path`` once and return its facts (with ``urdf``: the effort at rest
    against its g(q); with ``mass_frame`` too: the point mass [kg] at that frame that best
    explains the difference, a negative one meaning the arm carries less than the URDF)."""
    from rosbags.highlevel import AnyReader

    topics: list[TopicFacts] = []
    js: list[JointStateFacts] = []
    with AnyReader([path]) as reader:
        per: dict[str, dict[str, Any]] = {}
        for c in reader.connections:
            ext = getattr(c, "ext", None)
            per.setdefault(
                c.topic,
                {"type": c.msgtype, "caller": getattr(ext, "callerid", None), "log": []},
            )
        rows: dict[str, dict[str, list[Any]]] = {}
        for c, t, raw in reader.messages():
            per[c.topic]["log"].append(t)
            if c.msgtype not in JOINT_STATE:
                continue
            m: Any = reader.deserialize(raw, c.msgtype)
            r = rows.setdefault(
                c.topic, {"stamp": [], "log": [], "names": [], "p": [], "v": [], "e": []}
            )
            r["stamp"].append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
            r["log"].append(t)
            r["names"].append(tuple(m.name))
            r["p"].append(np.asarray(m.position, dtype=np.float64))
            r["v"].append(np.asarray(m.velocity, dtype=np.float64))
            r["e"].append(np.asarray(m.effort, dtype=np.float64))
        for topic, d in sorted(per.items()):
            lt = np.asarray(d["log"], dtype=np.int64)
            span = (lt.max() - lt.min()) / 1e9 if lt.size > 1 else 0.0
            rate = (lt.size - 1) / span if span > 0 else float("nan")
            topics.append(TopicFacts(topic, d["type"], int(lt.size), float(rate), d["caller"]))
        for topic, r in sorted(rows.items()):
            names = list(r["names"][0])
            constant = all(x == r["names"][0] for x in r["names"])
            st = np.asarray(r["stamp"], dtype=np.int64)
            lg = np.asarray(r["log"], dtype=np.int64)
            base = int(lg[0])
            stamps = (st - base) / 1e9  # relative to the first log time: offsets stay exact
            logs = (lg - base) / 1e9

            p, v, e = (_stack(r[key], len(names)) for key in ("p", "v", "e"))
            js.append(
                _joint_state_facts(topic, stamps, logs, names, constant, p, v, e, urdf, mass_frame)
            )
        start, end = int(reader.start_time), int(reader.end_time)
        count = int(reader.message_count)
    return RecordingFacts(
        path=str(path),
        container=_container(path),
        size_bytes=_size(path),
        start_ns=start,
        end_ns=end,
        duration_s=(end - start) / 1e9,
        message_count=count,
        topics=topics,
        joint_states=js,
    )


def _fmt(s: Spread, scale: float = 1.0, unit: str = "") -> str:
    return (
        f"median {s.median * scale:.6g}{unit}, 1-99 % [{s.p01 * scale:.6g}, "
        f"{s.p99 * scale:.6g}]{unit}, min {s.min * scale:.6g}{unit}, max {s.max * scale:.6g}{unit}"
    )


def format_facts(f: RecordingFacts) -> str:
    """The facts as the lines the doc quotes."""
    out = [
        f"log: {f.path}",
        f"container: {f.container}, {f.size_bytes} bytes",
        f"log time: {f.start_ns} .. {f.end_ns} ns, duration {f.duration_s:.6f} s, "
        f"{f.message_count} messages",
    ]
    for t in f.topics:
        caller = f", callerid {t.callerid}" if t.callerid else ""
        out.append(f"topic {t.topic}: {t.msgtype}, {t.count} messages, {t.rate_hz:.4g} Hz{caller}")
    for j in f.joint_states:
        out += [
            f"[{j.topic}] {j.count} messages, joints "
            f"({'constant' if j.names_constant else 'CHANGING'}): {', '.join(j.names)}",
            f"  entries per message: {j.filled}",
            f"  stamp period: {_fmt(j.stamp_period_s, 1e3, ' ms')}",
            f"  log period: {_fmt(j.log_period_s, 1e3, ' ms')}",
            f"  jitter (stamp dt - median) / median: {_fmt(j.jitter_over_period)}",
            f"  stamp - log time: {_fmt(j.stamp_minus_log_s, 1e3, ' ms')}, "
            f"mean {j.stamp_minus_log_mean_s * 1e3:.6g} ms",
            f"  stamps about a fitted uniform grid: period {j.grid_period_s * 1e3:.6g} ms, "
            f"residual std {j.grid_residual_std_s * 1e3:.4g} ms; gaps over 1.5 periods "
            f"{j.gaps}, the largest {j.largest_gap_periods:.4g} periods",
            f"  stamps backwards {j.backwards_stamps}, repeated {j.repeated_stamps}, "
            f"zero {j.zero_stamps}; samples repeated verbatim {j.repeated_samples}",
        ]
        for name in j.names:
            line = f"  {name}:"
            if name in j.position_range:
                lo, hi = j.position_range[name]
                line += f" position [{lo:.6g}, {hi:.6g}]"
            if name in j.max_abs_velocity:
                line += f", max |velocity| {j.max_abs_velocity[name]:.4g}"
            if name in j.velocity_vs_difference:
                line += f", rms(velocity - dpos/dt) {j.velocity_vs_difference[name]:.3g}"
            if name in j.effort_range:
                lo, hi = j.effort_range[name]
                line += f", effort [{lo:.6g}, {hi:.6g}] step {j.effort_step[name]:.3g}"
            out.append(line)
        if j.effort_minus_gravity_at_rest:
            out.append(
                f"  at rest (every |velocity| < {REST_SPEED} rad/s): {j.rest_samples} samples"
            )
            for name, s in j.effort_minus_gravity_at_rest.items():
                out.append(f"  {name}: effort - g(q) {_fmt(s, 1.0, ' N m')}")
        if j.mass_fit_kg is not None:
            left = ", ".join(f"{v:.3g}" for v in j.residual_after_mass_fit.values())
            out.append(
                f"  point mass at {j.mass_frame} fitted to effort - g(q): {j.mass_fit_kg:.4g} kg;"
                f" median residual after it [N m]: {left}"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path, help="a ROS 1 .bag, a rosbag2 folder or an .mcap")
    ap.add_argument("--urdf", type=Path, help="compare the effort at rest with this URDF's g(q)")
    ap.add_argument("--mass-at", help="with --urdf: fit a point mass at this frame to the rest")
    ap.add_argument("--json", action="store_true", help="print the facts as JSON")
    a = ap.parse_args(argv)
    if not a.log.exists():
        print(f"real_recording: no log at {a.log}; pass a .bag, a rosbag2 folder or an .mcap")
        return 2
    facts = recording_facts(a.log, a.urdf, a.mass_at)
    print(json.dumps(asdict(facts), indent=1) if a.json else format_facts(facts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
