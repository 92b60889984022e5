"""A recorded log -> the estimator's inputs on its tick grid (docs/how-to/logs.md, "Topics" and
"Timing").

Two steps, both before anything is compiled:

1. :func:`plan_log` reads the container's metadata and the first message of a few topics and
   says which topic plays which role (:mod:`amsfe_sym.topics.roles`): a role the topic spec
   names is taken as named (and its type checked); otherwise its default topic if the log
   has it; otherwise, for the encoders, the JointState topic whose names include every joint
   of the robot (a driver's ``/joint_states``), and for the effort that same topic when it
   carries effort values, or an effort-only JointState.  One topic may play several roles.
   The effort's kind (:data:`~amsfe_sym.topics.roles.EFFORT_KINDS`) is the spec's, else by
   shape: effort on a topic that also carries positions is ``none`` (a driver's measured
   effort is not the applied torque u), a separate effort topic is ``applied``.
2. :func:`read_log` reads those topics in one pass, decodes each a topic at a time
   (:mod:`amsfe_sym.logs.decode`) and puts them on the tick grid t_k = t0 + k T:

- t0's phase is fitted to every encoder stamp (a jittered first stamp no longer shifts the
  grid), the log's period is measured (median stamp difference) and a log at another rate
  than the robot's T is refused with the ``amsfe generate --period`` that fits it;
- the clock offset between header stamps and log time (two machines) is the median of
  log time - stamp over the encoder samples; log times (camera arrivals, arrival-stamped
  topics) are moved onto the stamp clock by it;
- encoder stamps far from their log time (a stamp 11.6 days ahead, a zero stamp in an
  epoch-stamped log) are skipped and counted; stamps that run backwards are refused; gaps
  are judged on the tick indices before any array is allocated; samples that do not advance
  the grid (all stamps zero) are refused;
- the effort is held from its stamp (zero-order hold by stamp): u(k) is the last effort
  stamped at or before t_k (within the tolerance);
- a camera frame is taken at ``header.stamp`` less the topic spec's ``[camera] time_offset``
  in whole ticks (its exposure step kappa) and reaches the estimator at the first tick at or
  after its arrival; skipped frames are counted by reason.

Every role's messages, used and skipped by reason, are in :attr:`RobotLog.usage`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.arrays import FloatArray, IntArray
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import describe
from amsfe_sym.logs.decode import (
    JointStates,
)
from amsfe_sym.logs.grid import (
    VALUE_MAX,
    ClockOffset,
    LogRateError,
    RoleUse,
    TickGrid,
    clock_steps,
    count_skip,
    fit_t0,
    period_digits,
)
from amsfe_sym.logs.plan import (
    LOG_ROLES,
    LogPlan,
    joint_columns,
    plan_log,
    read_config,
    refuse,
)
from amsfe_sym.logs.sensors import OnGrid, camera_frames, held_effort, truth_on_grid
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.topics.roles import EffortKind

__all__ = [
    "ClockOffset",
    "LogPlan",
    "LogRateError",
    "RobotLog",
    "RoleUse",
    "plan_log",
    "read_config",
    "read_log",
]


@dataclass
class RobotLog:
    """What the estimator needs from a log, on the tick grid.

    Attributes:
        path: The log.
        T: Sampling interval [s].
        t0_ns: Time of tick 0 on the stamp clock [ns].
        z: Encoder samples [qm, qmd] per tick, (K, 2n); a row of NaN: no sample (a gap).
        u: Torque applied over [t_k, t_k+1] [N m], (K, n): the effort when its kind is
            ``applied``, zeros otherwise (then ``effort`` and ``effort_kind`` say what the
            log has; :mod:`amsfe_sym.estimation.effort` turns them into the input).
        frames: Camera frames with their exposure and delivery steps, in arrival order.
        truth: The true state per tick, (K, N), if the log has it.
        config: amsfe's run config (simulated logs), or None.
        skipped: Messages skipped, by reason (every role's, flat).
        effort: The logged effort held by stamp, (K, n) [N m], or None without one.
        effort_kind: What ``effort`` is (``none`` without one).
        clock: The offset between log time and header stamps.
        usage: Role -> :class:`RoleUse`.
        plan: Which topic played which role.
        period_s: The encoder period measured from the stamps [s].
    """

    path: Path
    T: float
    t0_ns: int
    z: FloatArray
    u: FloatArray
    frames: list[CameraFrame]
    truth: FloatArray | None = None
    config: dict[str, Any] | None = None
    skipped: dict[str, int] = field(default_factory=dict)
    effort: FloatArray | None = None
    effort_kind: EffortKind = "applied"
    clock: ClockOffset = field(default_factory=lambda: ClockOffset(0.0, 0.0))
    usage: dict[str, RoleUse] = field(default_factory=dict)
    plan: LogPlan | None = None
    period_s: float = 0.0

    @property
    def K(self) -> int:
        """Ticks on the grid."""
        return int(self.z.shape[0])

    @property
    def t(self) -> FloatArray:
        """Tick times relative to t0 [s]."""
        return np.arange(self.K, dtype=np.float64) * self.T


def _read_decoded(
    path: Path, plan: LogPlan, spec: LogSpec, image_threads: int | None = None
) -> tuple[dict[str, IntArray], dict[str, Any]]:
    """Log times and decoded columns of every topic the plan uses (a topic without a
    message: absent), in one pass of :func:`amsfe_sym.logs.stream.read_topics` (bounded
    memory, bulk decoding, a progress bar on long logs; an image topic decoded ahead on
    ``image_threads`` threads, :func:`amsfe_sym.logs.images.decoders`)."""
    from amsfe_sym.logs.stream import read_topics

    own: dict[str, Any] = {}
    if plan.camera_info is not None:  # an image camera topic: its marker detected as read
        from amsfe_sym.logs.images import decoders

        own = decoders(plan, spec.marker, image_threads)
    try:
        got = read_topics(path, plan.topics_read, decoders=own)
    finally:
        if own:
            from amsfe_sym.logs.images import close_decoders

            close_decoders(own)
    return (
        {t: np.asarray(v.log_time_ns, dtype=np.int64) for t, v in got.items()},
        {t: v.decoded for t, v in got.items()},
    )


def read_log(
    path: Path,
    spec: LogSpec,
    joints: Sequence[str],
    T: float,
    N: int,
    plan: LogPlan | None = None,
    robot: str = "ROBOT",
    image_threads: int | None = None,
) -> RobotLog:
    """Read ``path`` for a robot with ``joints`` (q order), sampling interval ``T`` [s] and
    ``N`` states (``robot``: its name, for the fix of a rate mismatch; ``image_threads``:
    an image topic's decoding threads, 0 serial, None ``$AMSFE_IMAGE_THREADS`` or the
    default: :func:`amsfe_sym.vision.prefetch.image_threads`).

    Raises:
        LogError: unreadable; topics missing or of the wrong type; joint names not found or
            named twice; the log's rate not the robot's; stamps that run backwards or do not
            advance; a gap longer than ``max_gap_steps``; truth of another size than N.
    """
    plan = plan or plan_log(path, spec, joints)
    n = len(joints)
    names = plan.names
    times, decoded = _read_decoded(path, plan, spec, image_threads)
    usage = {r: RoleUse(plan.roles.get(r), not_used=plan.unused.get(r, [])) for r in LOG_ROLES}
    for ru in usage.values():
        if ru.topic is not None:
            ru.messages = len(times.get(ru.topic, ()))
    if plan.roles["encoders"] not in decoded:
        raise refuse(
            f"log {path}",
            f"messages on the encoder topic {plan.roles['encoders']}",
            "none",
            "record the encoders, or name the topic that has them ([topics] encoders)",
        )
    present = {r: t for r, t in plan.roles.items() if t in decoded}

    # ------------------------------------------------------------------ encoders: the grid
    et = plan.roles["encoders"]
    use = usage["encoders"]
    js: JointStates = decoded[et]
    where = f"log {path}: {et}"
    cols = joint_columns(js, names, where)
    rows = np.arange(len(js.stamp_ns))[:, None]
    width = np.array([len(ns) for ns in js.names])[js.names_index]
    pos, vel = js.position[rows, cols], js.velocity[rows, cols]
    shaped = (js.counts[:, 0] == width) & (js.counts[:, 1] == width)
    count_skip(use, "sample without a position and a velocity per joint", int((~shaped).sum()))
    stamps = js.stamp_ns
    log_ns = times[et]
    ok = shaped.copy()
    if not ok.any():
        raise refuse(
            where,
            "JointState samples with a position and a velocity per joint",
            f"none of {len(ok)} (counts per message {js.counts[0].tolist()} for "
            f"{len(js.names[0])} names)",
            "record the encoders' velocity too, or name another encoder topic",
        )
    # clock steps (refused by name) and runs of stamps far from their log time (another
    # clock, corrupt: skipped), by the rule of grid.clock_steps (docs/input-rules.md)
    idx_ok = np.flatnonzero(ok)
    steps_found, bad_run = clock_steps(log_ns[idx_ok], stamps[idx_ok], T, spec.max_gap_steps)
    if steps_found:
        st0 = steps_found[0]
        raise refuse(
            where,
            "header stamps on one clock (a step of the stamping clock splices the trajectory)",
            st0.line() + (f" ({len(steps_found)} steps)" if len(steps_found) > 1 else ""),
            f"estimate the log up to t = {st0.at_s:.4f} s or from after it (cut it, e.g. "
            "mcap filter --end-secs), and let the clock slew instead of step (chrony: no "
            "makestep while recording)",
        )
    far = np.zeros_like(ok)
    far[idx_ok[bad_run]] = True
    off = (log_ns - stamps).astype(np.float64) * 1e-9
    med = float(np.median(off[ok & ~far]))
    dev = np.abs(off - med)
    count_skip(use, "stamp far from its log time (another clock or corrupt)", int(far.sum()))
    ok &= ~far
    # stamps that run backwards (in arrival order) beyond the tolerance
    st_ok = stamps[ok]
    back = int((st_ok[1:] < st_ok[:-1] - spec.grid_tolerance * T * 1e9).sum())
    if back > 0.01 * st_ok.size:
        raise refuse(
            where,
            "header stamps that advance in the order the samples were received",
            f"{back} of {st_ok.size} stamps earlier than the one received before them",
            "fix the stamping clock (or cut the log where it jumps back)",
        )
    # (fewer: the samples are put in stamp order; none is dropped for it)
    sel = np.flatnonzero(ok)
    sel = sel[np.argsort(stamps[sel], kind="stable")]
    if sel.size < 2 or stamps[sel[-1]] == stamps[sel[0]]:
        raise refuse(
            where,
            "at least two samples with advancing header stamps",
            f"{sel.size} usable, stamps from {stamps[sel[0]]} to {stamps[sel[-1]]} ns",
            "stamp each sample with its time (header.stamp), not zero",
        )
    off_good = off[sel]
    clock = ClockOffset(med, float(np.percentile(off_good, 95) - np.percentile(off_good, 5)))
    # the log's own period, against the robot's T
    d = np.diff(stamps[sel]).astype(np.float64) * 1e-9
    d = d[d > 0]
    period = float(np.median(d)) if d.size else T
    count = 1.0
    if period > 0 and sel.size > 2:  # least squares over each sample's count of periods
        rel = (stamps[sel] - stamps[sel[0]]).astype(np.float64) * 1e-9
        # counted difference by difference, in the robot's T when the median is within the
        # grid tolerance of it, else in the median (a jitter of less than half a period
        # never miscounts one difference; counting the whole log in T miscounted a log
        # stamped every 1.04 ms and printed 0.999997 ms)
        unit = T if abs(period - T) <= spec.grid_tolerance * T / 10 else period
        for _ in range(2):  # counted again in the fitted period (a gap's count is exact)
            idx = np.concatenate([[0.0], np.cumsum(np.rint(np.diff(rel) / unit))])
            count = float(idx[-1])
            if idx[-1] <= 0:
                break
            ic, rc = idx - idx.mean(), rel - rel.mean()
            period = unit = float(ic @ rc / (ic @ ic))
    # another rate: more than 10 % off T (a multiple of T would put every sample on the grid
    # with gaps between); a drift of less is judged by the stamps off the grid below
    mismatch = abs(period - T) > 0.1 * T
    t0 = fit_t0(stamps[sel], T)
    grid = TickGrid(t0, T, spec.grid_tolerance)
    k_all, on = grid.steps(stamps[sel])
    offgrid = int((~on).sum())
    if mismatch or offgrid > 0.01 * sel.size:
        text = period_digits(period, count)  # the number printed is the fix's number
        raise LogRateError(
            describe(
                where,
                f"samples every T = {T:g} s (robot {robot}'s sampling interval)",
                f"samples every {text} s (fitted over the stamps), {offgrid} of {sel.size} "
                f"stamps off the grid of T within {spec.grid_tolerance:g} T",
                f"generate the robot at the log's period: amsfe generate {robot} --period "
                f"{text} (or record at the robot's rate)",
            ),
            float(text),
        )
    count_skip(use, "stamp off the tick grid", offgrid)
    sel, k_all = sel[on], k_all[on]
    first_k = int(k_all[0])
    k_all = k_all - first_k
    t0 += round(first_k * T * 1e9)
    grid = TickGrid(t0, T, spec.grid_tolerance)
    # two samples for one tick: the one whose log time fits the clock offset best is kept
    # (a stamp 0.9 s ahead lands on a later tick's sample; it is that one that goes)
    order = np.lexsort((dev[sel], k_all))
    sel, k_all = sel[order], k_all[order]
    uniq, first_idx = np.unique(k_all, return_index=True)
    count_skip(use, "duplicate (a second sample for a tick)", int(k_all.size - uniq.size))
    sel = sel[first_idx]
    # gaps judged on the tick indices, before anything is allocated
    steps = np.diff(uniq) - 1
    if steps.size and int(steps.max()) > spec.max_gap_steps:
        i = int(np.argmax(steps))
        raise refuse(
            where,
            f"gaps of at most {spec.max_gap_steps} samples (predicted through)",
            f"{int(steps[i])} missing from t = {(uniq[i] + 1) * T:.4f} s",
            "raise [timing] max_gap_steps in a topic spec, or cut the log there",
        )
    K = int(uniq[-1]) + 1
    z = np.full((K, 2 * n), np.nan)
    z[uniq] = np.hstack([pos[sel], vel[sel]])
    bad = ~np.isfinite(z).all(axis=1)
    bad_samples = int(bad[uniq].sum())
    count_skip(use, "sample with a non-finite value (predicted through)", bad_samples)
    z[bad] = np.nan
    absurd = np.abs(np.nan_to_num(z[uniq])).max(axis=1) > VALUE_MAX
    if absurd.any():  # a 1e300: skipped and named, as a far stamp is
        first_k = int(uniq[np.argmax(absurd)])
        count_skip(
            use,
            f"sample with a value beyond {VALUE_MAX:g} (first at tick {first_k}, "
            f"t = {first_k * T:.4f} s; predicted through)",
            int(absurd.sum()),
        )
        bad[uniq[absurd]] = True
        z[bad] = np.nan
    if bad.any():
        runs = np.split(np.flatnonzero(bad), np.flatnonzero(np.diff(np.flatnonzero(bad)) > 1) + 1)
        longest = max(runs, key=len)
        if len(longest) > spec.max_gap_steps:
            raise refuse(
                where,
                f"gaps of at most {spec.max_gap_steps} samples (NaN and inf count as missing)",
                f"{len(longest)} missing or non-finite from t = {longest[0] * T:.4f} s",
                "raise [timing] max_gap_steps in a topic spec, or cut the log there",
            )
    if not np.isfinite(z[0]).all():
        raise refuse(where, "a finite first encoder sample", "NaN or inf", "cut the log there")
    use.used = int(uniq.size) - bad_samples - int(absurd.sum())
    step1 = np.flatnonzero(np.diff(uniq) == 1)  # consecutive ticks with identical samples
    same = int((z[uniq[step1 + 1]] == z[uniq[step1]]).all(axis=1).sum())
    if same:
        use.notes["identical to the previous tick's sample (republished, or at rest)"] = same
    # ------------------------------------------------------------------ effort: hold by stamp
    effort: FloatArray | None = None
    if "effort" in present and plan.effort_kind == "none":
        eu = usage["effort"]
        count_skip(eu, "not used: effort kind none (say [effort] kind to use it)", eu.messages)
    elif "effort" in present:
        on_grid = OnGrid(path, plan, times, decoded, grid, clock, K)
        held = held_effort(on_grid, spec, usage["effort"], n)
        effort, first = held.values, held.first
        if held.end < K:  # the effort stream ended early: the log ends with it, named
            ended = int(np.isfinite(z[held.end :]).all(axis=1).sum())
            end_k = held.end - 1 - spec.max_gap_steps
            count_skip(
                use,
                f"after the effort ended at tick {end_k} (t = {end_k * T:.4f} s; a torque is "
                "not held past max_gap_steps ticks: the log ends there)",
                ended,
            )
            use.used -= ended
            z, effort, K = z[: held.end], effort[: held.end], held.end
            if K - first < 2:
                raise refuse(
                    f"log {path}: {plan.roles['effort']} (effort)",
                    "effort samples over the encoders' ticks",
                    f"the effort ends at tick {end_k}, {K - first} ticks after it starts",
                    'record the effort over the whole log, or say [effort] kind = "none"',
                )
        if first > 0:  # the effort starts later than the encoders: so does the log
            finite = np.flatnonzero(np.isfinite(z).all(axis=1))
            later = finite[finite >= first]
            if later.size < 2:
                raise refuse(
                    f"log {path}: {plan.roles['effort']} (effort)",
                    "effort samples over the encoders' ticks",
                    f"the first effort at tick {first}, {later.size} encoder samples after it",
                    'record the effort from the start, or say [effort] kind = "none"',
                )
            start = int(later[0])
            dropped = int((finite < start).sum())
            count_skip(use, "sample before the first effort sample (the log starts there)", dropped)
            use.used -= dropped
            z, effort = z[start:], effort[start:]
            t0 += round(start * T * 1e9)
            grid = TickGrid(t0, T, spec.grid_tolerance)
            K -= start
    u = effort if plan.effort_kind == "applied" and effort is not None else np.zeros((K, n))
    skipped: dict[str, int] = {}
    missing = int((~np.isfinite(z).all(axis=1)).sum())
    if missing:
        skipped["encoder samples missing (predicted through)"] = missing

    # the encoders ending before the log's other streams: named (the log ends with them)
    others = [times[t][-1] for r, t in present.items() if r != "encoders" and times[t].size]
    if others:
        after = (max(others) - int(log_ns[-1])) * 1e-9
        if after > (spec.max_gap_steps + 1) * T:
            use.notes[
                f"the encoders end at tick {K - 1} (t = {(K - 1) * T:.4f} s), "
                f"{after:.4g} s before the log's other streams (ticks not estimated)"
            ] = round(after / T)

    # ------------------------------------------------------------------ camera frames
    on_grid = OnGrid(  # (the grid the log starts on)
        path, plan, times, decoded, grid, clock, K, spec.exposure_shift(T)
    )
    frames: list[CameraFrame] = []
    if "camera" in present and plan.camera_info is not None:  # images: docs/camera.md
        from amsfe_sym.logs.images import image_frames

        frames = image_frames(on_grid, usage["camera"], spec.marker)
    elif "camera" in present:
        frames = camera_frames(on_grid, usage["camera"])

    # ------------------------------------------------------------------ truth
    truth = None
    if "truth" in present:
        truth = truth_on_grid(on_grid, N, usage["truth"])

    for r, ru in usage.items():
        for reason, c in ru.skipped.items():
            # camera counters keep the names summary.json had before the per-role usage
            key = f"frame {reason}" if r == "camera" else f"{r}: {reason}"
            skipped[key] = skipped.get(key, 0) + c
    return RobotLog(
        path,
        T,
        t0,
        z,
        u,
        frames,
        truth,
        None,
        skipped,
        effort,
        plan.effort_kind,
        clock,
        usage,
        plan,
        period,
    )
