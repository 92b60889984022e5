"""The effort, the camera frames and the truth of a log on its tick grid (docs/how-to/logs.md,
"Timing"): the effort held by stamp (zero-order hold to the nearest tick), each frame at its
exposure step and its arrival tick, the truth at its log time; every message not used is
counted by reason in its role's :class:`~amsfe_sym.logs.grid.RoleUse`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.arrays import FloatArray, IntArray
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.logs.grid import VALUE_MAX, ClockOffset, RoleUse, TickGrid, count_skip
from amsfe_sym.logs.plan import JOINT_STATE, LogPlan, joint_columns, refuse
from amsfe_sym.logs.spec import LogSpec

__all__ = ["HeldEffort", "OnGrid", "camera_frames", "held_effort", "truth_on_grid"]


@dataclass(frozen=True)
class OnGrid:
    """A log's decoded topics and the tick grid they are put on.

    Attributes:
        path: The log (for messages).
        plan: Which topic plays which role.
        times: Each topic's log times [ns].
        decoded: Each topic's decoded columns (:mod:`amsfe_sym.logs.decode`).
        grid: The encoders' tick grid.
        clock: Log time minus header stamp over the encoder samples.
        K: Ticks on the grid.
        exposure_shift: The camera's time offset in ticks (the topic spec's ``[camera]
            time_offset``, :meth:`~amsfe_sym.topics.spec.TopicSpec.exposure_shift`): a frame
            stamped at tick k was exposed at tick k - exposure_shift.
    """

    path: Path
    plan: LogPlan
    times: dict[str, IntArray]
    decoded: dict[str, Any]
    grid: TickGrid
    clock: ClockOffset
    K: int
    exposure_shift: int = 0

    def on_stamp_clock(self, topic: str) -> IntArray:
        """``topic``'s log times moved onto the header stamps' clock [ns] (its arrivals, as
        the encoders' stamps count time)."""
        out: IntArray = self.times[topic] - round(self.clock.median * 1e9)
        return out


@dataclass(frozen=True)
class HeldEffort:
    """The effort on the tick grid.

    Attributes:
        values: The effort held by stamp [N m], (K, n); NaN before ``first`` and from
            ``end`` on.
        first: The first tick that has an effort sample.
        end: The tick after the last one the effort covers: K, or where the stream ended
            (its last sample more than ``max_gap_steps`` ticks before the last tick: the
            torque is not held past that; docs/input-rules.md).
    """

    values: FloatArray
    first: int
    end: int


def held_effort(log: OnGrid, spec: LogSpec, use: RoleUse, n: int) -> HeldEffort:
    """The effort held by stamp on the K ticks (zero-order hold to the nearest tick: the last
    effort stamped before t_k + T/2) [N m], (K, n), NaN before the first effort sample and
    after the stream ends, and the first and end ticks it covers.

    Raises:
        LogError: no effort sample with n finite values, or none before the last tick.
    """
    plan, grid, K = log.plan, log.grid, log.K
    topic = plan.roles["effort"]
    where = f"log {log.path}: {topic} (effort)"
    d = log.decoded[topic]
    if plan.topics[topic].msgtype == JOINT_STATE:
        cols = joint_columns(d, plan.names, where)
        rows = np.arange(len(d.stamp_ns))[:, None]
        width = np.array([len(ns) for ns in d.names])[d.names_index]
        values = d.effort[rows, cols]
        shaped = d.counts[:, 2] == width
        stamps = d.stamp_ns
    else:  # Float64MultiArray: no header, stamped by its arrival (on the stamp clock)
        values = d.values[:, :n] if d.values.shape[1] >= n else np.full((len(d.counts), n), np.nan)
        shaped = d.counts == n
        stamps = log.on_stamp_clock(topic)
    count_skip(use, "not one value per joint", int((~shaped).sum()))
    finite = shaped & np.isfinite(values).all(axis=1)
    count_skip(use, "a non-finite value", int((shaped & ~finite).sum()))
    absurd = finite & (np.abs(np.nan_to_num(values)).max(axis=1) > VALUE_MAX)
    count_skip(use, f"a value beyond {VALUE_MAX:g} N m (absurd)", int(absurd.sum()))
    finite &= ~absurd
    # zero-order hold by stamp: u(k) = the last effort stamped before t_k + T/2 (an effort
    # stamped off the encoder grid, or late by a receive latency, goes to its nearest tick)
    t_rel = (stamps.astype(np.int64) - grid.t0) * 1e-9 / grid.T
    far = finite & ((t_rel < -1e6) | (t_rel > K + 1e6))
    count_skip(use, "stamp far outside the log", int(far.sum()))
    good = np.flatnonzero(finite & ~far)
    if good.size == 0:
        raise refuse(
            where,
            f"effort samples with {n} finite values",
            f"none of {len(finite)}",
            'fix the topic, name another ([topics] effort), or say [effort] kind = "none"',
        )
    order = good[np.argsort(t_rel[good], kind="stable")]
    ts = t_rel[order]
    last = np.searchsorted(ts, np.arange(K) + 0.5, side="left") - 1
    if last[-1] < 0:
        raise refuse(
            where,
            "effort samples over the encoders' ticks",
            f"the first effort {ts[0] * grid.T:.4f} s after the first encoder tick, past the last",
            'fix the effort\'s stamps, or say [effort] kind = "none"',
        )
    out = np.asarray(values[order[np.maximum(last, 0)]], dtype=np.float64)
    out[last < 0] = np.nan  # before the first effort sample: the caller starts the log later
    # a stream that ends early is not held: the last sample's tick plus max_gap_steps
    end = min(K, int(np.floor(ts[-1] + 0.5)) + 1 + spec.max_gap_steps)
    out[end:] = np.nan
    used = np.unique(last[last >= 0])
    use.used = int(used.size)
    count_skip(use, "superseded before a tick (a later one was held)", int(order.size - used.size))
    return HeldEffort(out, int(np.argmax(last >= 0)), end)


def camera_frames(
    log: OnGrid, use: RoleUse, corners: FloatArray | None = None
) -> list[CameraFrame]:
    """Each camera frame at its exposure step (its stamp's tick less ``log.exposure_shift``)
    and its arrival tick, in arrival order; the frames not used counted by reason.
    ``corners``: the marker's corners (M, 4, 2) [px] of the topic's points, kept with their
    frames (an image topic)."""
    topic = log.plan.roles["camera"]
    pts = log.decoded[topic]
    log_ns = log.on_stamp_clock(topic)
    kappa, on = log.grid.steps(pts.stamp_ns)
    kappa = kappa - log.exposure_shift
    arrive = log.grid.arrivals(log_ns)
    frames: list[CameraFrame] = []
    seen: set[int] = set()
    for i in np.argsort(log_ns, kind="stable"):
        pix = pts.xyz[i, :2].astype(np.float64)
        kp, ar = int(kappa[i]), int(arrive[i])
        if not on[i]:
            count_skip(use, "exposure off the tick grid")
        elif not np.isfinite(pix).all():
            count_skip(use, "with a non-finite pixel")
        elif kp in seen:
            count_skip(use, "duplicated (an exposure already seen)")
        elif kp < 0:
            count_skip(use, "exposed before the first encoder sample")
        elif ar < kp:
            count_skip(use, "arrived before its exposure")
        elif ar >= log.K:
            count_skip(use, "arrived after the last tick")
        else:
            seen.add(kp)
            c = None if corners is None else np.asarray(corners[i], dtype=np.float64)
            frames.append(CameraFrame(kp, pix, ar, c))
    use.used = len(frames)
    if len(frames) >= 3:  # a camera that stops: named at its last frame (docs/input-rules.md)
        arrivals = np.array([f.delivery_step for f in frames])
        every = float(np.median(np.diff(np.sort(arrivals)))) if arrivals.size > 1 else 0.0
        last = int(arrivals.max())
        if every > 0 and log.K - 1 - last > 3 * every:
            use.notes[
                f"frames end at tick {last} (t = {last * log.grid.T:.4f} s): none over the "
                "last ticks of the log (ticks without a frame)"
            ] = log.K - 1 - last
    return frames


def truth_on_grid(log: OnGrid, N: int, use: RoleUse) -> FloatArray:
    """The true state at each tick (NaN where the log has none), (K, N).

    Raises:
        LogError: the truth does not have the robot's N values.
    """
    K = log.K
    topic = log.plan.roles["truth"]
    arr = log.decoded[topic]
    wrong = np.flatnonzero(arr.counts != N)
    if wrong.size:
        raise refuse(
            f"log {log.path}: {topic} (truth)",
            f"the true state of the robot: N = {N} values [q, qd, qm, qmd, theta]",
            f"{int(arr.counts[wrong[0]])} values in {wrong.size} of {arr.counts.size} messages",
            "estimate with the robot the log was recorded for (--robot / the scenario's robot)",
        )
    truth = np.full((K, N), np.nan)
    k, on = log.grid.steps(log.on_stamp_clock(topic))
    inside = on & (k >= 0) & (k < K)
    count_skip(use, "off the tick grid or outside the log", int((~inside).sum()))
    truth[k[inside]] = arr.values[inside, :N]
    use.used = int(inside.sum())
    return truth
