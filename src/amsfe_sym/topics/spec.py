"""The topic spec: which topic plays which role (:mod:`amsfe_sym.topics.roles`), the log's
joint names, what its effort is, the timing tolerances and the QoS of live topics.  Every key
has a default; a small TOML file overrides any of them, and the same file serves
``amsfe estimate`` on a recording and ``amsfe node`` live (docs/topics.md).

```toml
[topics]                          # any role of topics.roles.ROLES; unset: the default topic,
encoders = "/joint_states"        # or, for a log, found by message type and joint names
effort = "/joint_states"          # one topic may serve several roles
camera = "/camera/marker"

[joints]
names = ["joint1", "joint2"]      # JointState names in the robot's q order (default: the robot's)

[effort]
kind = "joint_torque"             # "applied" | "joint_torque" | "none" (default: by shape)

[filter]                          # the filter's R and Q: the scenario's [filter] keys and units
encoder_q_std = 1e-5              # [rad]; "log": measured from the log (docs/logs.md)
link_torque_std = 0.5             # [N m]; over estimate --robot's defaults and a scenario's

[timing]
grid_tolerance = 0.25             # |stamp - k T| allowed for a sample on the tick grid [T]
max_gap_steps = 5                 # missing encoder samples predicted through; more: refused

[qos]                             # live topics (amsfe node, sim-node, play)
reliability = "reliable"          # or "best_effort" (what most drivers' sensor topics use)
depth = 100                       # history depth (KEEP_LAST)

[watchdog]                        # the bounds past which a live node holds (topics.watchdog)
tracking_error = 0.1              # [rad]; every key: docs/watchdogs.md
```

The key ``[topics] torque`` of older log specs is read as ``effort``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from amsfe_sym.core.toml import read_toml
from amsfe_sym.core.values import BACKWARD_MAPS, read_int, read_number
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.topics.roles import EFFORT_KINDS, ROLES, EffortKind
from amsfe_sym.topics.watchdog import WATCHDOG_KEYS, WatchdogBounds, parse_watchdog

__all__ = ["FILTER_KEYS", "FROM_LOG", "TopicSpec", "parse_topic_spec", "read_topic_spec"]

_TOPIC_KEYS = tuple(ROLES)
_ALIASES = {"torque": "effort"}


@dataclass(frozen=True)
class TopicSpec:
    """Where amsfe's inputs and outputs live, and how to read them.

    Attributes:
        encoders, effort, camera, truth, config: Topics of the input roles
            (:data:`~amsfe_sym.topics.roles.ROLES` says what each means).
        estimate, estimate_std, theta, diagnostics, commands, clock: Topics of the outputs.
        explicit: The roles whose topic the spec file set (the others are defaults: a log
            reader may find them by message type and joint names instead).
        joint_names: JointState names in the robot's q order (None: the robot's joints).
        positions: What the encoder positions are: ``"motor"``, the motor angle qm of eq. (2)
            (amsfe's own logs), or ``"link"``, the link angle q (franka_ros' ``/joint_states``:
            libfranka's ``q``); with a joint torque the estimator is given
            ``qm = q + tau_J / Ks`` (docs/effort.md).
        effort_kind: What the effort is (None: the default for the message's shape, decided
            by the reader: docs/topics.md).
        effort_options: The other ``[effort]`` keys as written (``joint_torque_std``,
            ``input_model``, ``input_rate_std``, ``input_std0``), checked by the estimator's
            ``effort_spec`` (docs/effort.md).
        filter_options: The ``[filter]`` keys as written, type-checked (:data:`FILTER_KEYS`:
            the scenario's ``[filter]``, docs/scenarios.md); ``amsfe estimate`` applies them
            over ``--robot``'s defaults and over a scenario's ``[filter]`` (the log spec wins,
            key by key) and the scenario's own checks judge the result.  ``encoder_q_std``
            and ``encoder_qd_std`` may be :data:`FROM_LOG`: measured from the log.
        grid_tolerance: How far a stamp may be from the tick grid [T].
        max_gap_steps: Missing encoder samples in a row the estimator predicts through.
        reliability: QoS reliability of live topics: ``reliable`` or ``best_effort``.
        depth: QoS history depth of live topics (KEEP_LAST).
        watchdog: The bounds of a live node's watchdogs (``[watchdog]``,
            :class:`~amsfe_sym.topics.watchdog.WatchdogBounds`).
        source: The file read (None: the defaults).
    """

    encoders: str = ROLES["encoders"].topic
    effort: str = ROLES["effort"].topic
    camera: str = ROLES["camera"].topic
    truth: str = ROLES["truth"].topic
    config: str = ROLES["config"].topic
    estimate: str = ROLES["estimate"].topic
    estimate_std: str = ROLES["estimate_std"].topic
    theta: str = ROLES["theta"].topic
    diagnostics: str = ROLES["diagnostics"].topic
    commands: str = ROLES["commands"].topic
    clock: str = ROLES["clock"].topic
    explicit: frozenset[str] = frozenset()
    joint_names: tuple[str, ...] | None = None
    positions: Literal["motor", "link"] = "motor"
    effort_kind: EffortKind | None = None
    effort_options: tuple[tuple[str, Any], ...] = ()
    filter_options: tuple[tuple[str, Any], ...] = ()
    grid_tolerance: float = 0.25
    max_gap_steps: int = 5
    reliability: Literal["reliable", "best_effort"] = "reliable"
    depth: int = 100
    watchdog: WatchdogBounds = field(default_factory=WatchdogBounds)
    source: Path | None = field(default=None, compare=False)

    def topic(self, role: str) -> str:
        """The topic of ``role`` (a key of :data:`~amsfe_sym.topics.roles.ROLES`)."""
        if role not in ROLES:
            raise ConfigError(describe("topic role", f"one of {list(ROLES)}", repr(role), ""))
        return str(getattr(self, role))

    def roles_of(self, topic: str, roles: tuple[str, ...] = tuple(ROLES)) -> list[str]:
        """Every role among ``roles`` that ``topic`` plays (a driver's ``/joint_states`` plays
        ``encoders`` and ``effort`` at once)."""
        return [r for r in roles if self.topic(r) == topic]

    @property
    def torque(self) -> str:
        """The effort topic under its former name (log specs before the effort kinds)."""
        return self.effort


#: ``[effort]`` keys passed on to the estimator's effort model (``estimation.effort``'s
#: ``effort_spec`` checks their values; docs/effort.md): noise and input model.
_EFFORT_NOISE_KEYS = ("joint_torque_std", "input_model", "input_rate_std", "input_std0")

#: The ``[filter]`` keys: the scenario's (``scenario.model.FilterSettings``' fields, same
#: names and units; tests/test_log_noise.py holds the two lists equal), by value type.
_FILTER_NUMBERS = (
    "link_torque_std",  # [N m] held over one step (Q of eq. (3))
    "motor_torque_std",  # [N m]
    "theta_rate_std",  # [unit/s]
    "paper_torque_std",  # [N m]
    "encoder_q_std",  # [rad] (R)
    "encoder_qd_std",  # [rad/s]
    "camera_pixel_std",  # [px]
    "gate_probability",
)
_FILTER_INTS = ("camera_iterations", "buffer_steps")
FILTER_KEYS = (*_FILTER_NUMBERS, *_FILTER_INTS, "backward_map")

#: The value of ``[filter] encoder_q_std`` / ``encoder_qd_std`` that asks for the noise
#: measured from the log (:mod:`amsfe_sym.logs.noise`).
FROM_LOG = "log"
_FROM_LOG_KEYS = ("encoder_q_std", "encoder_qd_std")

_SECTIONS = {
    "topics": _TOPIC_KEYS + tuple(_ALIASES),
    "joints": ("names", "positions"),
    "effort": ("kind", *_EFFORT_NOISE_KEYS),
    "filter": FILTER_KEYS,
    "timing": ("grid_tolerance", "max_gap_steps"),
    "qos": ("reliability", "depth"),
    "watchdog": WATCHDOG_KEYS,
}


def _number(where: str, value: Any, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not lo < value < hi:
        raise ConfigError(describe(where, f"a number in ({lo:g}, {hi:g})", repr(value), "fix it"))
    return float(value)


def _count(where: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ConfigError(describe(where, f"an integer >= {lo}", repr(value), "fix it"))
    return int(value)


def _filter_value(at: str, key: str, value: Any) -> Any:
    """A ``[filter]`` value of the type of the scenario's key (ranges: the scenario's
    checks, once applied)."""
    if key in _FROM_LOG_KEYS and value == FROM_LOG:
        return value
    if key in _FILTER_NUMBERS:
        if isinstance(value, str) and key in _FROM_LOG_KEYS:
            raise ConfigError(
                describe(
                    at,
                    f'a noise std >= 0 or "{FROM_LOG}" (measured from the log)',
                    repr(value),
                    f'write {key} = 1e-5 or {key} = "{FROM_LOG}"',
                )
            )
        return read_number(value, at, ConfigError, low=0.0)
    if key in _FILTER_INTS:
        return read_int(value, at, ConfigError, 1)
    if value not in BACKWARD_MAPS:  # backward_map
        raise ConfigError(
            describe(at, f"one of {list(BACKWARD_MAPS)}", repr(value), 'write "linearised"')
        )
    return value


def parse_topic_spec(data: dict[str, Any], where: str = "topic spec") -> TopicSpec:
    """A :class:`TopicSpec` from a parsed TOML document.

    Raises:
        ConfigError: an unknown section or key, a value of the wrong type, one joint named
            twice, a topic name that does not start with ``/``.
    """
    unknown = sorted(set(data) - set(_SECTIONS))
    if unknown:
        raise ConfigError(
            describe(where, f"sections among {sorted(_SECTIONS)}", f"{unknown}", "remove them")
        )
    out: dict[str, Any] = {}
    explicit: set[str] = set()
    for section, keys in _SECTIONS.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise ConfigError(describe(f"{where} [{section}]", "a table", repr(table), "fix it"))
        bad = sorted(set(table) - set(keys))
        if bad:
            fix = "drop them"
            if section == "filter":
                fix = "rename or drop them (the scenario's [filter] keys: docs/scenarios.md)"
            raise ConfigError(
                describe(f"{where} [{section}]", f"keys among {list(keys)}", str(bad), fix)
            )
        if section == "watchdog":
            out["watchdog"] = parse_watchdog(table, f"{where} [watchdog]")
            continue
        for key, value in table.items():
            at = f"{where} [{section}] {key}"
            if section == "topics":
                if not isinstance(value, str) or not value.startswith("/") or " " in value:
                    raise ConfigError(describe(at, "a topic name like '/x'", repr(value), "fix it"))
                role: str = _ALIASES.get(str(key), str(key))
                if role in explicit and role != key:
                    raise ConfigError(
                        describe(at, f"one of '{key}' and '{role}'", "both", f"keep '{role}'")
                    )
                out[role] = value
                explicit.add(role)
            elif key == "names":
                if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                    raise ConfigError(describe(at, "a list of joint names", repr(value), "fix it"))
                twice = sorted({v for v in value if value.count(v) > 1})
                if twice:
                    raise ConfigError(
                        describe(at, "each joint name once", f"{twice} repeated", "fix the list")
                    )
                out["joint_names"] = tuple(value)
            elif key == "positions":
                if value not in ("motor", "link"):
                    raise ConfigError(
                        describe(
                            at,
                            "'motor' (the motor angle qm) or 'link' (the link angle q)",
                            repr(value),
                            'say positions = "link" for a Franka\'s /joint_states',
                        )
                    )
                out[key] = value
            elif key == "kind":
                if value not in EFFORT_KINDS:
                    raise ConfigError(
                        describe(at, f"one of {list(EFFORT_KINDS)}", repr(value), "fix it")
                    )
                out["effort_kind"] = value
            elif key in _EFFORT_NOISE_KEYS:
                out["effort_options"] = (*out.get("effort_options", ()), (key, value))
            elif section == "filter":
                item = (key, _filter_value(at, key, value))
                out["filter_options"] = (*out.get("filter_options", ()), item)
            elif key == "grid_tolerance":
                out[key] = _number(at, value, 0.0, 0.5)
            elif key == "max_gap_steps":
                out[key] = _count(at, value, 0)
            elif key == "reliability":
                if value not in ("reliable", "best_effort"):
                    raise ConfigError(
                        describe(at, "'reliable' or 'best_effort'", repr(value), "fix it")
                    )
                out[key] = value
            else:  # depth
                out[key] = _count(at, value, 1)
    return replace(TopicSpec(), explicit=frozenset(explicit), **out)


def read_topic_spec(path: str | os.PathLike[str] | None) -> TopicSpec:
    """The topic spec in the TOML file ``path`` (None: the defaults).

    Raises:
        ConfigError: an unreadable file, or what :func:`parse_topic_spec` refuses.
    """
    if path is None:
        return TopicSpec()
    p = Path(path)
    return replace(parse_topic_spec(read_toml(p, ConfigError), str(p)), source=p)
