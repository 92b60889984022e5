"""A recorded log -> the estimator's inputs on its tick grid (docs/logs.md, "Topics" and
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
- a camera frame is taken at ``header.stamp`` (its exposure step kappa) and reaches the
  estimator at the first tick at or after its arrival; skipped frames are counted by reason.

Every role's messages, used and skipped by reason, are in :attr:`RobotLog.usage`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import AmsfeError, LogError, describe
from amsfe_sym.logs.decode import (
    JointStates,
    decode_float64_arrays,
    decode_joint_states,
    decode_points,
    decode_strings,
)
from amsfe_sym.logs.source import TopicData, TopicInfo, first_payloads, log_topics, read_topics
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.topics.roles import ROLES, EffortKind, joint_order

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

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

JOINT_STATE = "sensor_msgs/msg/JointState"
#: The input roles a log is read for (``config`` is read by :func:`read_config`).
_ROLES = ("encoders", "effort", "camera", "truth")
#: An encoder stamp whose (log time - stamp) is this far from the median is skipped [s] (a
#: stamp from another clock or a corrupt one); at least 100 T.
_FAR_S = 1.0


class LogRateError(LogError):
    """The log is sampled at another rate than the robot's T.

    Attributes:
        period: The log's period [s], to the 6 digits the message prints (the value to
            generate the robot at: ``amsfe generate ROBOT --period <period>``).
    """

    def __init__(self, message: str, period: float) -> None:
        super().__init__(message)
        self.period = period


@dataclass(frozen=True)
class LogPlan:
    """Which topic plays which role in a log, decided from its metadata and first messages.

    Attributes:
        path: The log.
        topics: Every topic of the log.
        roles: Role -> topic (``encoders`` always; ``effort``, ``camera``, ``truth`` where
            the log has them).  One topic may appear under several roles.
        how: Role -> how its topic was chosen: ``named`` (the topic spec), ``default`` (the
            role's default topic) or ``found`` (by message type and joint names).
        effort_kind: What the effort is (``none`` when there is no effort topic).
        kind_how: ``named`` (the spec said) or the shape rule that chose it.
        names: The log's JointState names of the robot's joints, in q order.
        unused: Role without a topic -> the log's topics of that role's types that play no
            role (a stream that is there but not used is said, never silent).
    """

    path: Path
    topics: dict[str, TopicInfo]
    roles: dict[str, str]
    how: dict[str, str]
    effort_kind: EffortKind
    kind_how: str
    names: tuple[str, ...]
    unused: dict[str, list[str]] = field(default_factory=dict)

    def lines(self) -> list[str]:
        """One line per role saying which topic plays it and why (printed by estimate)."""
        out = []
        for role in _ROLES:
            topic = self.roles.get(role)
            if topic is None:
                other = self.unused.get(role)
                out.append(
                    f"{role}: none"
                    + (f" (not used: {other}; name one in [topics] {role})" if other else "")
                )
                continue
            info = self.topics[topic]
            line = f"{role}: {topic} ({info.msgtype}, {self.how[role]})"
            if role == "effort":
                line += f", kind {self.effort_kind} ({self.kind_how})"
            out.append(line)
        return out


@dataclass(frozen=True)
class ClockOffset:
    """Log time minus header stamp over the encoder samples [s]: ``median`` (the offset
    between the recorder's clock and the stamping clock, plus the transport latency) and
    ``spread`` (5 % to 95 % range)."""

    median: float
    spread: float


@dataclass
class RoleUse:
    """What became of one role's messages.

    Attributes:
        topic: Its topic (None: the log has none).
        messages: Messages on the topic.
        used: Messages that entered the estimate.
        skipped: Messages not used, by reason.
        not_used: Without a topic: the log's topics of the role's types (not used).
        notes: Counts worth a look that changed nothing (used samples identical to the
            previous one: a driver republishing its last state, or an arm at rest).
    """

    topic: str | None
    messages: int = 0
    used: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    not_used: list[str] = field(default_factory=list)
    notes: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """For ``summary.json``."""
        return {
            "topic": self.topic,
            "messages": self.messages,
            "used": self.used,
            "skipped": dict(self.skipped),
            "topics_of_this_type_not_used": list(self.not_used),
            "notes": dict(self.notes),
        }


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
    clock: ClockOffset = ClockOffset(0.0, 0.0)
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


# ---------------------------------------------------------------------------- the plan
def _refuse(where: str, expected: str, found: str, fix: str) -> LogError:
    return LogError(describe(where, expected, found, fix))


def _check_type(path: Path, role: str, info: TopicInfo) -> None:
    types = ROLES[role].types
    if info.msgtype not in types:
        raise _refuse(
            f"log {path}: topic {info.topic} ({role})",
            f"messages of type {' or '.join(types)}",
            info.msgtype or "no type (a channel without a schema)",
            f"name the log's {role} topic in a topic spec's [topics] {role} (--log-spec; "
            "docs/topics.md)",
        )
    info.payload_encoding(path)  # a JSON-encoded channel: refused here, by name


def read_config(
    path: Path, spec: LogSpec | None = None, topics: dict[str, TopicInfo] | None = None
) -> dict[str, Any] | None:
    """amsfe's run config stored in a log by ``amsfe simulate --bag``, or None.

    Raises:
        LogError: the config topic exists with another type than ``std_msgs/msg/String``
            (named, not "found none"), or its text is not a JSON object.
    """
    spec = spec or LogSpec()
    topics = topics if topics is not None else log_topics(path)
    info = topics.get(spec.config)
    if info is None:
        if "config" in spec.explicit:
            raise _refuse(
                f"log {path}",
                f"the config topic {spec.config} named in the topic spec",
                f"no such topic (the log has {sorted(topics)})",
                "fix [topics] config, or drop it",
            )
        return None
    _check_type(path, "config", info)
    data = first_payloads(path, {spec.config}, topics)[spec.config]
    if not data.raws:
        return None
    text = decode_strings(data.raws[:1], info.payload_encoding(path), f"log {path}").data[0]
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise _refuse(
            f"log {path}: {spec.config}",
            "a JSON document (amsfe's run config)",
            f"{exc}",
            "point [topics] config at amsfe's config topic, or at a topic the log lacks",
        ) from exc
    if not isinstance(doc, dict):
        raise _refuse(f"log {path}: {spec.config}", "a JSON object", type(doc).__name__, "as above")
    return doc


def _first_states(path: Path, topics: dict[str, TopicInfo], which: set[str]) -> dict[str, Any]:
    """The first JointState of each topic in ``which``, as :class:`JointStates` (one row)."""
    firsts = first_payloads(path, which, topics)
    out: dict[str, Any] = {}
    for t, d in firsts.items():
        if d.raws:
            out[t] = decode_joint_states(
                d.raws[:1], topics[t].payload_encoding(path), f"log {path}: {t}"
            )
    return out


def _has(js: JointStates, names: Sequence[str], field_: int) -> bool:
    """Whether the first message names every joint and carries ``field_``'s values
    (0 position, 1 velocity, 2 effort) for each of its names."""
    have = js.names[int(js.names_index[0])]
    return all(n in have for n in names) and int(js.counts[0, field_]) == len(have) > 0


def plan_log(path: Path, spec: LogSpec, joints: Sequence[str]) -> LogPlan:
    """Which topic plays which role in the log at ``path`` for a robot with ``joints`` (q
    order), from the container's metadata and each candidate topic's first message.

    Raises:
        LogError: unreadable; a named topic missing or of the wrong type; a default topic of
            the wrong type; no encoder topic, or several that could be it; the robot's
            joints missing from the encoder topic (named).
    """
    topics = log_topics(path)
    if topics and not any(i.encoding in ("cdr", "ros1") for i in topics.values()):
        next(iter(topics.values())).payload_encoding(path)  # e.g. a JSON MCAP: named
    names = tuple(spec.joint_names or joints)
    if len(names) != len(joints):
        raise _refuse(
            "topic spec [joints] names",
            f"{len(joints)} names (the robot's joints {list(joints)}, in q order)",
            f"{list(names)}",
            f"give {len(joints)} names, the log's name of each robot joint in q order",
        )
    roles: dict[str, str] = {}
    how: dict[str, str] = {}
    for role in _ROLES:
        topic = spec.topic(role)
        if role in spec.explicit:
            if topic not in topics:
                raise _refuse(
                    f"log {path}",
                    f"the {role} topic {topic} named in the topic spec",
                    f"no such topic (the log has {sorted(topics)})",
                    f"fix [topics] {role} in the topic spec",
                )
            _check_type(path, role, topics[topic])
            roles[role], how[role] = topic, "named"
        elif topic in topics:
            _check_type(path, role, topics[topic])
            roles[role], how[role] = topic, "default"
    states = [t for t, i in topics.items() if i.msgtype == JOINT_STATE and i.encoding != "json"]
    firsts = _first_states(path, topics, set(states))
    if "encoders" not in roles:
        cands = [t for t in states if t in firsts and _has(firsts[t], names, 0)]
        if len(cands) > 1 and "/joint_states" in cands:
            cands = ["/joint_states"]
        if not cands:
            seen = {t: list(firsts[t].names[0]) for t in states if t in firsts}
            raise _refuse(
                f"log {path}",
                f"a JointState topic with the positions of {list(names)} (the encoders)",
                f"JointState topics {seen}" if seen else f"none among {sorted(topics)}",
                "name the encoder topic ([topics] encoders) and the log's joint names "
                "([joints] names) in a topic spec (--log-spec; docs/topics.md)",
            )
        if len(cands) > 1:
            raise _refuse(
                f"log {path}",
                "one JointState topic with the robot's joints (the encoders)",
                f"several: {cands}",
                "name one in a topic spec's [topics] encoders (--log-spec)",
            )
        roles["encoders"], how["encoders"] = cands[0], "found"
    enc = roles["encoders"]
    if enc in firsts:  # the robot's joints in the encoder topic, checked by name now
        _columns(firsts[enc], names, f"log {path}: {enc}")
    if "effort" not in roles:
        first = firsts.get(enc)
        if first is not None and _has(first, names, 2):
            roles["effort"], how["effort"] = enc, "found"
        else:
            only = [
                t
                for t in states
                if t != enc
                and t in firsts
                and _has(firsts[t], names, 2)
                and int(firsts[t].counts[0, 0]) == 0
            ]
            if len(only) == 1:
                roles["effort"], how["effort"] = only[0], "found"
    kind: EffortKind
    if "effort" not in roles:
        kind, kind_how = "none", "no effort topic: encoders only"
        if spec.effort_kind not in (None, "none"):
            raise _refuse(
                f"log {path}",
                f"an effort topic (the topic spec says [effort] kind = {spec.effort_kind!r})",
                f"none among {sorted(topics)}",
                'name it in [topics] effort, or say [effort] kind = "none"',
            )
    elif spec.effort_kind is not None:
        kind, kind_how = spec.effort_kind, "named"
    else:
        eff = roles["effort"]
        first = firsts.get(eff)
        if first is not None and int(first.counts[0, 0]) > 0:
            kind = "none"
            kind_how = (
                "the effort of a topic that also carries positions: a driver's measured "
                'effort; if it is the applied torque say [effort] kind = "applied", if it '
                'is a joint torque sensor\'s say "joint_torque"'
            )
        else:
            kind, kind_how = "applied", "a separate effort topic: the applied torque"
    used = set(roles.values())
    unused = {
        r: sorted(t for t, i in topics.items() if i.msgtype in ROLES[r].types and t not in used)
        for r in _ROLES
        if r not in roles
    }
    return LogPlan(
        path, topics, roles, how, kind, kind_how, names, {r: u for r, u in unused.items() if u}
    )


# ---------------------------------------------------------------------------- the grid
class _Grid:
    """Stamps -> tick indices: t_k = t0 + k T, a stamp on tick k within ``tol`` T."""

    def __init__(self, t0_ns: int, T: float, tolerance: float) -> None:
        self.t0, self.T, self.tol = t0_ns, T, tolerance

    def steps(self, stamp_ns: IntArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Tick of each stamp and whether it is on the grid (int64; off-grid ticks kept)."""
        s = (np.asarray(stamp_ns, dtype=np.int64) - self.t0) * 1e-9 / self.T
        k = np.rint(s)
        on = np.abs(s - k) <= self.tol
        big = np.abs(k) > 2**62
        return np.where(big, -(2**62), k).astype(np.int64), on & ~big

    def arrivals(self, log_ns: IntArray) -> IntArray:
        """The first tick at or after each arrival time (within the tolerance)."""
        s = (np.asarray(log_ns, dtype=np.int64) - self.t0) * 1e-9 / self.T - self.tol
        return np.clip(np.ceil(s), -(2**62), 2**62).astype(np.int64)


def _fit_t0(stamps: IntArray, T: float) -> int:
    """The grid origin: the first stamp moved to the phase of all of them (circular mean of
    the stamps modulo T), so that jitter of the first stamp does not shift the grid."""
    T_ns = T * 1e9
    rel = (stamps - stamps[0]).astype(np.float64)
    frac = (rel / T_ns) - np.rint(rel / T_ns)
    phase = float(np.angle(np.mean(np.exp(2j * np.pi * frac)))) / (2 * np.pi)
    return int(stamps[0] + round(phase * T_ns))


def _skip(use: RoleUse, reason: str, count: int = 1) -> None:
    if count > 0:
        use.skipped[reason] = use.skipped.get(reason, 0) + int(count)


def _decode(path: Path, data: TopicData) -> Any:
    enc = data.info.payload_encoding(path)
    where = f"log {path}: {data.info.topic}"
    t = data.info.msgtype
    if t == JOINT_STATE:
        return decode_joint_states(data.raws, enc, where)
    if t == "geometry_msgs/msg/PointStamped":
        return decode_points(data.raws, enc, where)
    if t == "std_msgs/msg/Float64MultiArray":
        return decode_float64_arrays(data.raws, enc, where)
    return decode_strings(data.raws, enc, where)


def _rate_fix(robot: str, period: float) -> str:
    """The one-step fix for a log at another rate: ``codegen.modes.period_fix`` where the
    build has it (the command with the substeps the joint modes need), else the command."""
    import importlib.util

    if robot != "ROBOT" and importlib.util.find_spec("amsfe_sym.codegen.modes") is not None:
        try:
            modes = importlib.import_module("amsfe_sym.codegen.modes")
            return f"{modes.period_fix(robot, period)}, or record at the robot's rate"
        except Exception:  # the plain command below still holds
            pass
    return (
        f"generate the robot at the log's period: amsfe generate {robot} --period "
        f"{period:.6g} (or record at the robot's rate)"
    )


def _read_decoded(path: Path, plan: LogPlan) -> tuple[dict[str, IntArray], dict[str, Any]]:
    """Log times and decoded columns of every topic the plan uses (a topic without a
    message: absent), in one pass: through the bulk reader ``amsfe_sym.logs.stream`` where
    this build has it (issue 26.8: MCAP chunks cut with numpy), else
    :func:`~amsfe_sym.logs.source.read_topics` and :mod:`amsfe_sym.logs.decode`."""
    import importlib.util

    wanted = set(plan.roles.values())
    if importlib.util.find_spec("amsfe_sym.logs.stream") is not None:
        stream = importlib.import_module("amsfe_sym.logs.stream")
        got = stream.read_topics(path, wanted)
        return (
            {t: np.asarray(v.log_time_ns, dtype=np.int64) for t, v in got.items()},
            {t: v.decoded for t, v in got.items()},
        )
    data = {t: d for t, d in read_topics(path, wanted, plan.topics).items() if len(d)}
    return (
        {t: d.log_time_ns for t, d in data.items()},
        {t: _decode(path, d) for t, d in data.items()},
    )


def _columns(js: JointStates, names: Sequence[str], where: str) -> IntArray:
    """(M, n) column of each robot joint in each message's padded arrays."""
    try:
        per = [joint_order(ns, names, where) for ns in js.names]
    except AmsfeError as exc:
        raise LogError(str(exc)) from exc
    table = np.asarray(per, dtype=np.int64).reshape(len(per), len(names))
    return table[js.names_index]


def read_log(
    path: Path,
    spec: LogSpec,
    joints: Sequence[str],
    T: float,
    N: int,
    plan: LogPlan | None = None,
    robot: str = "ROBOT",
) -> RobotLog:
    """Read ``path`` for a robot with ``joints`` (q order), sampling interval ``T`` [s] and
    ``N`` states (``robot``: its name, for the fix of a rate mismatch).

    Raises:
        LogError: unreadable; topics missing or of the wrong type; joint names not found or
            named twice; the log's rate not the robot's; stamps that run backwards or do not
            advance; a gap longer than ``max_gap_steps``; truth of another size than N.
    """
    plan = plan or plan_log(path, spec, joints)
    n = len(joints)
    names = plan.names
    times, decoded = _read_decoded(path, plan)
    usage = {r: RoleUse(plan.roles.get(r), not_used=plan.unused.get(r, [])) for r in _ROLES}
    for ru in usage.values():
        if ru.topic is not None:
            ru.messages = len(times.get(ru.topic, ()))
    if plan.roles["encoders"] not in decoded:
        raise _refuse(
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
    cols = _columns(js, names, where)
    rows = np.arange(len(js.stamp_ns))[:, None]
    width = np.array([len(ns) for ns in js.names])[js.names_index]
    pos, vel = js.position[rows, cols], js.velocity[rows, cols]
    shaped = (js.counts[:, 0] == width) & (js.counts[:, 1] == width)
    _skip(use, "sample without a position and a velocity per joint", int((~shaped).sum()))
    stamps = js.stamp_ns
    log_ns = times[et]
    ok = shaped.copy()
    if not ok.any():
        raise _refuse(
            where,
            "JointState samples with a position and a velocity per joint",
            f"none of {len(ok)} (counts per message {js.counts[0].tolist()} for "
            f"{len(js.names[0])} names)",
            "record the encoders' velocity too, or name another encoder topic",
        )
    # the clock offset, and stamps far from their log time (another clock, corrupt)
    off = (log_ns - stamps).astype(np.float64) * 1e-9
    med = float(np.median(off[ok]))
    dev = np.abs(off - med)
    spread = float(np.percentile(off[ok], 95) - np.percentile(off[ok], 5))
    far = ok & (dev > max(_FAR_S, 100 * T, 10 * spread))
    _skip(use, "stamp far from its log time (another clock or corrupt)", int(far.sum()))
    ok &= ~far
    # stamps that run backwards (in arrival order) beyond the tolerance
    st_ok = stamps[ok]
    back = int((st_ok[1:] < st_ok[:-1] - spec.grid_tolerance * T * 1e9).sum())
    if back > 0.01 * st_ok.size:
        raise _refuse(
            where,
            "header stamps that advance in the order the samples were received",
            f"{back} of {st_ok.size} stamps earlier than the one received before them",
            "fix the stamping clock (or cut the log where it jumps back)",
        )
    # (fewer: the samples are put in stamp order; none is dropped for it)
    sel = np.flatnonzero(ok)
    sel = sel[np.argsort(stamps[sel], kind="stable")]
    if sel.size < 2 or stamps[sel[-1]] == stamps[sel[0]]:
        raise _refuse(
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
    if period > 0 and sel.size > 2:  # least squares over each sample's count of periods
        rel = (stamps[sel] - stamps[sel[0]]).astype(np.float64) * 1e-9
        # counted in the robot's T when the median is near it (a jittered median is off by
        # a few %, enough to miscount a long log), else in the median
        idx = np.rint(rel / (T if abs(period - T) < 0.1 * T else period))
        if idx[-1] > 0:
            ic, rc = idx - idx.mean(), rel - rel.mean()
            period = float(ic @ rc / (ic @ ic))
    # another rate: more than 10 % off T (a multiple of T would put every sample on the grid
    # with gaps between); a drift of less is judged by the stamps off the grid below
    mismatch = abs(period - T) > 0.1 * T
    t0 = _fit_t0(stamps[sel], T)
    grid = _Grid(t0, T, spec.grid_tolerance)
    k_all, on = grid.steps(stamps[sel])
    offgrid = int((~on).sum())
    if mismatch or offgrid > 0.01 * sel.size:
        raise LogRateError(
            describe(
                where,
                f"samples every T = {T:g} s (robot {robot}'s sampling interval)",
                f"samples every {period:.6g} s (median), {offgrid} of {sel.size} stamps off "
                f"the grid of T within {spec.grid_tolerance:g} T",
                _rate_fix(robot, period),
            ),
            float(f"{period:.6g}"),
        )
    _skip(use, "stamp off the tick grid", offgrid)
    sel, k_all = sel[on], k_all[on]
    first_k = int(k_all[0])
    k_all = k_all - first_k
    t0 += round(first_k * T * 1e9)
    grid = _Grid(t0, T, spec.grid_tolerance)
    # two samples for one tick: the one whose log time fits the clock offset best is kept
    # (a stamp 0.9 s ahead lands on a later tick's sample; it is that one that goes)
    order = np.lexsort((dev[sel], k_all))
    sel, k_all = sel[order], k_all[order]
    uniq, first_idx = np.unique(k_all, return_index=True)
    _skip(use, "duplicate (a second sample for a tick)", int(k_all.size - uniq.size))
    sel = sel[first_idx]
    # gaps judged on the tick indices, before anything is allocated
    steps = np.diff(uniq) - 1
    if steps.size and int(steps.max()) > spec.max_gap_steps:
        i = int(np.argmax(steps))
        raise _refuse(
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
    _skip(use, "sample with a non-finite value (predicted through)", bad_samples)
    z[bad] = np.nan
    if bad.any():
        runs = np.split(np.flatnonzero(bad), np.flatnonzero(np.diff(np.flatnonzero(bad)) > 1) + 1)
        longest = max(runs, key=len)
        if len(longest) > spec.max_gap_steps:
            raise _refuse(
                where,
                f"gaps of at most {spec.max_gap_steps} samples (NaN and inf count as missing)",
                f"{len(longest)} missing or non-finite from t = {longest[0] * T:.4f} s",
                "raise [timing] max_gap_steps in a topic spec, or cut the log there",
            )
    if not np.isfinite(z[0]).all():
        raise _refuse(where, "a finite first encoder sample", "NaN or inf", "cut the log there")
    use.used = int(uniq.size) - bad_samples
    step1 = np.flatnonzero(np.diff(uniq) == 1)  # consecutive ticks with identical samples
    same = int((z[uniq[step1 + 1]] == z[uniq[step1]]).all(axis=1).sum())
    if same:
        use.notes["identical to the previous tick's sample (republished, or at rest)"] = same
    skipped: dict[str, int] = {}
    missing = int(bad.sum())
    if missing:
        skipped["encoder samples missing (predicted through)"] = missing

    # ------------------------------------------------------------------ effort: hold by stamp
    effort: FloatArray | None = None
    if "effort" in present:
        effort = _effort(path, plan, spec, times, decoded, grid, clock, K, usage["effort"], n)
    u = effort if plan.effort_kind == "applied" and effort is not None else np.zeros((K, n))

    # ------------------------------------------------------------------ camera frames
    frames: list[CameraFrame] = []
    if "camera" in present:
        frames = _frames(plan, times, decoded, grid, clock, K, usage["camera"])

    # ------------------------------------------------------------------ truth
    truth = None
    if "truth" in present:
        truth = _truth(path, plan, times, decoded, grid, clock, K, N, usage["truth"])

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


def _effort(
    path: Path,
    plan: LogPlan,
    spec: LogSpec,
    times: dict[str, IntArray],
    decoded: dict[str, Any],
    grid: _Grid,
    clock: ClockOffset,
    K: int,
    use: RoleUse,
    n: int,
) -> FloatArray:
    topic = plan.roles["effort"]
    where = f"log {path}: {topic} (effort)"
    d = decoded[topic]
    if plan.topics[topic].msgtype == JOINT_STATE:
        cols = _columns(d, plan.names, where)
        rows = np.arange(len(d.stamp_ns))[:, None]
        width = np.array([len(ns) for ns in d.names])[d.names_index]
        values = d.effort[rows, cols]
        shaped = d.counts[:, 2] == width
        stamps = d.stamp_ns
    else:  # Float64MultiArray: no header, stamped by its arrival (on the stamp clock)
        values = d.values[:, :n] if d.values.shape[1] >= n else np.full((len(d.counts), n), np.nan)
        shaped = d.counts == n
        stamps = times[topic] - round(clock.median * 1e9)
    _skip(use, "not one value per joint", int((~shaped).sum()))
    finite = shaped & np.isfinite(values).all(axis=1)
    _skip(use, "a non-finite value", int((shaped & ~finite).sum()))
    # zero-order hold by stamp: u(k) = the last effort stamped before t_k + T/2 (an effort
    # stamped off the encoder grid, or late by a receive latency, goes to its nearest tick)
    t_rel = (stamps.astype(np.int64) - grid.t0) * 1e-9 / grid.T
    far = finite & ((t_rel < -1e6) | (t_rel > K + 1e6))
    _skip(use, "stamp far outside the log", int(far.sum()))
    good = np.flatnonzero(finite & ~far)
    if good.size == 0:
        raise _refuse(
            where,
            f"effort samples with {n} finite values",
            f"none of {len(finite)}",
            'fix the topic, name another ([topics] effort), or say [effort] kind = "none"',
        )
    order = good[np.argsort(t_rel[good], kind="stable")]
    ts = t_rel[order]
    last = np.searchsorted(ts, np.arange(K) + 0.5, side="left") - 1
    if last[0] < 0:
        raise _refuse(
            where,
            "an effort sample at or before the first encoder tick",
            f"the first effort {ts[0] * grid.T:.4f} s after it",
            'cut the log\'s start to the first effort sample, or say [effort] kind = "none"',
        )
    out = values[order[last]]
    used = np.unique(last)
    use.used = int(used.size)
    _skip(use, "superseded before a tick (a later one was held)", int(order.size - used.size))
    return np.asarray(out, dtype=np.float64)


def _frames(
    plan: LogPlan,
    times: dict[str, IntArray],
    decoded: dict[str, Any],
    grid: _Grid,
    clock: ClockOffset,
    K: int,
    use: RoleUse,
) -> list[CameraFrame]:
    topic = plan.roles["camera"]
    pts = decoded[topic]
    log_ns = times[topic] - round(clock.median * 1e9)
    kappa, on = grid.steps(pts.stamp_ns)
    arrive = grid.arrivals(log_ns)
    frames: list[CameraFrame] = []
    seen: set[int] = set()
    for i in np.argsort(log_ns, kind="stable"):
        pix = pts.xyz[i, :2].astype(np.float64)
        kp, ar = int(kappa[i]), int(arrive[i])
        if not on[i]:
            _skip(use, "exposure off the tick grid")
        elif not np.isfinite(pix).all():
            _skip(use, "with a non-finite pixel")
        elif kp in seen:
            _skip(use, "duplicated (an exposure already seen)")
        elif kp < 0:
            _skip(use, "exposed before the first encoder sample")
        elif ar < kp:
            _skip(use, "arrived before its exposure")
        elif ar >= K:
            _skip(use, "arrived after the last tick")
        else:
            seen.add(kp)
            frames.append(CameraFrame(kp, pix, ar))
    use.used = len(frames)
    return frames


def _truth(
    path: Path,
    plan: LogPlan,
    times: dict[str, IntArray],
    decoded: dict[str, Any],
    grid: _Grid,
    clock: ClockOffset,
    K: int,
    N: int,
    use: RoleUse,
) -> FloatArray:
    topic = plan.roles["truth"]
    arr = decoded[topic]
    wrong = np.flatnonzero(arr.counts != N)
    if wrong.size:
        raise _refuse(
            f"log {path}: {topic} (truth)",
            f"the true state of the robot: N = {N} values [q, qd, qm, qmd, theta]",
            f"{int(arr.counts[wrong[0]])} values in {wrong.size} of {arr.counts.size} messages",
            "estimate with the robot the log was recorded for (--robot / the scenario's robot)",
        )
    truth = np.full((K, N), np.nan)
    k, on = grid.steps(times[topic] - round(clock.median * 1e9))
    inside = on & (k >= 0) & (k < K)
    _skip(use, "off the tick grid or outside the log", int((~inside).sum()))
    truth[k[inside]] = arr.values[inside, :N]
    use.used = int(inside.sum())
    return truth
