"""The topic spec: which topic plays which role (:mod:`amsfe_sym.topics.roles`), the log's
joint names, what its effort is, the timing tolerances and the QoS of live topics.  Every key
has a default; a small TOML file overrides any of them, and the same file serves
``amsfe estimate`` on a recording and ``amsfe node`` live (docs/reference/topics.md).

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
encoder_q_std = 1e-5              # [rad]; "log": measured from the log (docs/how-to/logs.md)
link_torque_std = 0.5             # [N m]; over estimate --robot's defaults and a scenario's

[timing]
grid_tolerance = 0.25             # |stamp - k T| allowed for a sample on the tick grid [T]
max_gap_steps = 5                 # missing encoder samples predicted through; more: refused

[qos]                             # live topics (amsfe node, sim-node, play)
reliability = "reliable"          # or "best_effort" (what most drivers' sensor topics use)
depth = 100                       # history depth (KEEP_LAST)

[camera]                          # when [topics] camera is an image topic (docs/camera.md)
info = "/camera/camera_info"      # its CameraInfo (default: the log's one CameraInfo topic)
time_offset = 0.025               # [s] header stamp - exposure (amsfe calibrate measures it)

[marker]                          # what the images are searched for (amsfe_sym.vision.spec)
dictionary = "DICT_APRILTAG_36h11"
id = 0
size = 0.05                       # [m]
point = "centre"                  # or a corner: "top_left", ...

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
from amsfe_sym.core.values import (
    BACKWARD_MAPS,
    BUFFER_STEPS_MAX,
    NOISE_STD_MAX,
    read_in_range,
    read_int,
    read_number,
)
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.topics.roles import EFFORT_KINDS, ROLES, EffortKind
from amsfe_sym.topics.watchdog import WATCHDOG_KEYS, WatchdogBounds, for_effort, parse_watchdog
from amsfe_sym.vision.spec import MarkerSpec, parse_camera_section, parse_marker

__all__ = ["FILTER_KEYS", "FROM_LOG", "TopicSpec", "parse_topic_spec", "read_topic_spec"]

_TOPIC_KEYS = tuple(ROLES)
#: Largest |[camera] time_offset| [s] a topic spec takes (a USB camera's ~0.1 s, ten times).
CAMERA_TIME_OFFSET_MAX = 1.0
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
            ``qm = q + tau_J / Ks`` (docs/explanation/effort.md).
        effort_kind: What the effort is (None: the default for the message's shape, decided
            by the reader: docs/reference/topics.md).
        effort_options: The other ``[effort]`` keys as written (``joint_torque_std``,
            ``input_model``, ``input_rate_std``, ``input_std0``), checked by the estimator's
            ``effort_spec`` (docs/explanation/effort.md).
        filter_options: The ``[filter]`` keys as written, type-checked (:data:`FILTER_KEYS`:
            the scenario's ``[filter]``, docs/reference/scenarios.md); ``amsfe estimate`` applies
            them
            over ``--robot``'s defaults and over a scenario's ``[filter]`` (the log spec wins,
            key by key) and the scenario's own checks judge the result.  ``encoder_q_std``
            and ``encoder_qd_std`` may be :data:`FROM_LOG`: measured from the log.
        grid_tolerance: How far a stamp may be from the tick grid [T].
        max_gap_steps: Missing encoder samples in a row the estimator predicts through.
        reliability: QoS reliability of live topics: ``reliable`` or ``best_effort``.
        depth: QoS history depth of live topics (KEEP_LAST).
        camera_info: The CameraInfo topic of an image camera topic (None: the log's one).
        camera_time_offset: How much later the camera's header stamps are than its
            exposures [s] (``[camera] time_offset``, what ``amsfe calibrate`` measures): a
            frame stamped ``s`` was exposed at ``s - time_offset``, rounded to the nearest
            tick (:meth:`exposure_shift`).
        marker: The marker an image camera topic is searched for.
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
    camera_info: str | None = None
    camera_time_offset: float = 0.0
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    watchdog: WatchdogBounds = field(default_factory=WatchdogBounds)
    source: Path | None = field(default=None, compare=False)

    def topic(self, role: str) -> str:
        """The topic of ``role`` (a key of :data:`~amsfe_sym.topics.roles.ROLES`)."""
        if role not in ROLES:
            raise ConfigError(
                describe(
                    "topic role", f"one of {list(ROLES)}", repr(role), "name one of those roles"
                )
            )
        return str(getattr(self, role))

    def roles_of(self, topic: str, roles: tuple[str, ...] = tuple(ROLES)) -> list[str]:
        """Every role among ``roles`` that ``topic`` plays (a driver's ``/joint_states`` plays
        ``encoders`` and ``effort`` at once)."""
        return [r for r in roles if self.topic(r) == topic]

    def exposure_shift(self, T: float) -> int:
        """The camera's time offset in whole ticks of ``T`` [s] (rounded to the nearest):
        a frame stamped at tick k was exposed at tick ``k - exposure_shift(T)``.  Frames are
        fused at ticks, so the remainder (at most T/2) is not applied."""
        return round(self.camera_time_offset / T)

    @property
    def torque(self) -> str:
        """The effort topic under its former name (log specs before the effort kinds)."""
        return self.effort


#: ``[effort]`` keys passed on to the estimator's effort model (``estimation.effort``'s
#: ``effort_spec`` checks their values; docs/explanation/effort.md): noise and input model.
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
#: The R keys whose 0 means, in a scenario, "the simulated sensor's true noise": a log has
#: no such thing, so a log spec refuses 0 there (it was printed as applied and was not).
_MEASURED_STD = (*_FROM_LOG_KEYS, "camera_pixel_std")

_SECTIONS = {
    "topics": _TOPIC_KEYS + tuple(_ALIASES),
    "joints": ("names", "positions"),
    "effort": ("kind", *_EFFORT_NOISE_KEYS),
    "filter": FILTER_KEYS,
    "timing": ("grid_tolerance", "max_gap_steps"),
    "qos": ("reliability", "depth"),
    "camera": ("info", "time_offset"),
    "marker": ("dictionary", "id", "size", "point", "pixel_std"),
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
        if key == "gate_probability":
            return read_in_range(value, at, ConfigError, 0.0, 1.0, "e.g. 0.9999 (0: no gate)")
        if key not in _MEASURED_STD:
            return read_in_range(value, at, ConfigError, 0.0, NOISE_STD_MAX)
        v = read_number(value, at, ConfigError)
        if not 0.0 < v <= NOISE_STD_MAX:  # 0: a simulation's "the sensor's true noise"
            log = key in _FROM_LOG_KEYS
            raise ConfigError(
                describe(
                    at,
                    f"a noise std in (0, {NOISE_STD_MAX:g}]" + (f' or "{FROM_LOG}"' if log else ""),
                    "0 (the simulator's 'true sensor noise', which a log does not know)"
                    if v == 0
                    else repr(value),
                    f'write {key} = "{FROM_LOG}" (measured from the log) or the sensor\'s std'
                    if log
                    else f"write the sensor's std, or leave {key} out",
                )
            )
        return v
    if key == "buffer_steps":
        return read_int(value, at, ConfigError, 1, BUFFER_STEPS_MAX)
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
        if section == "camera":
            out["camera_info"] = parse_camera_section(table, f"{where} [camera]")
            if "time_offset" in table:
                out["camera_time_offset"] = read_in_range(
                    table["time_offset"],
                    f"{where} [camera] time_offset",
                    ConfigError,
                    -CAMERA_TIME_OFFSET_MAX,
                    CAMERA_TIME_OFFSET_MAX,
                    "write the camera's stamp - exposure in seconds (amsfe calibrate prints it)",
                )
            continue
        if section == "marker":
            out["marker"] = parse_marker(table, f"{where} [marker]")
            continue
        bad = sorted(set(table) - set(keys))
        if bad:
            fix = "drop them"
            if section == "filter":
                fix = (
                    "rename or drop them (the scenario's [filter] keys: "
                    "docs/reference/scenarios.md)"
                )
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
                if role != key and role in table:  # both spellings, in either order
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
                out[key] = read_int(value, at, ConfigError, 1, BUFFER_STEPS_MAX)
    if out.get("positions") == "link" and out.get("effort_kind") in ("applied", "none"):
        raise ConfigError(
            describe(
                f"{where} [joints] positions",
                '"link" with [effort] kind = "joint_torque" (qm = q + tau_J / Ks)',
                f'"link" with kind {out["effort_kind"]!r}: the link angles would be taken as '
                "motor angles",
                'say kind = "joint_torque" (a torque-sensing arm\'s tau_J), or drop positions '
                '= "link" if the positions are the motor\'s',
            )
        )
    # the innovation bound of the effort kind, unless [watchdog] set it (topics/watchdog.py)
    set_nis = "innovation_nis" in data.get("watchdog", {})
    wd = for_effort(out.get("watchdog", WatchdogBounds()), out.get("effort_kind"), set_nis)
    out["watchdog"] = wd
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
