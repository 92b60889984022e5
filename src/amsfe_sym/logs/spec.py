"""The log spec: which topics and message types of a recorded log hold the estimator's inputs
(docs/logs.md, "Log spec").  Every key has a default, the convention ``amsfe simulate --bag``
writes; a small TOML file overrides any of them.

```toml
[topics]
encoders = "/motor_encoders"      # sensor_msgs/msg/JointState: position = qm, velocity = qmd
torque = "/motor_torque"          # JointState effort, or std_msgs/msg/Float64MultiArray data
camera = "/camera/marker"         # geometry_msgs/msg/PointStamped: x, y = pixel u, v
truth = "/amsfe/truth"            # std_msgs/msg/Float64MultiArray, the full true state (optional)
config = "/amsfe/config"          # std_msgs/msg/String, amsfe's run config (optional)

[joints]
names = ["joint1", "joint2"]      # JointState names, in the robot's q order (default: the robot's)

[timing]
grid_tolerance = 0.25             # |stamp - k T| allowed for a sample on the tick grid [T]
max_gap_steps = 5                 # missing encoder samples predicted through; more: refused
```
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from amsfe_sym.core.toml import read_toml
from amsfe_sym.errors import ConfigError, describe

__all__ = ["TORQUE_TYPES", "LogSpec", "read_log_spec"]

#: The message types a torque topic may have.
TORQUE_TYPES = ("sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray")


@dataclass(frozen=True)
class LogSpec:
    """Where a log keeps the estimator's inputs.

    Attributes:
        encoders: Topic of the motor encoders (``sensor_msgs/msg/JointState``: position =
            motor angle qm [rad], velocity = qmd [rad/s]; ``header.stamp`` = sample time).
        torque: Topic of the applied motor torque [N m], held from its stamp to the next
            sample (``JointState`` effort, or ``std_msgs/msg/Float64MultiArray`` data in q
            order, stamped by its log time).
        camera: Topic of the marker detections (``geometry_msgs/msg/PointStamped``: x, y =
            pixel u, v [px]; ``header.stamp`` = exposure time; the log time = arrival).
        truth: Topic of the true state x (``Float64MultiArray``, [q, qd, qm, qmd, theta]) if
            the log has one (a simulated run): the NEES is computed against it.
        config: Topic of amsfe's run config (``std_msgs/msg/String``, JSON).
        joint_names: JointState names in the robot's q order (None: the robot's joints).
        grid_tolerance: How far a stamp may be from the tick grid [T].
        max_gap_steps: Missing encoder samples in a row the estimator predicts through.
    """

    encoders: str = "/motor_encoders"
    torque: str = "/motor_torque"
    camera: str = "/camera/marker"
    truth: str = "/amsfe/truth"
    config: str = "/amsfe/config"
    joint_names: tuple[str, ...] | None = None
    grid_tolerance: float = 0.25
    max_gap_steps: int = 5
    source: Path | None = field(default=None, compare=False)


_KEYS = {
    "topics": ("encoders", "torque", "camera", "truth", "config"),
    "joints": ("names",),
    "timing": ("grid_tolerance", "max_gap_steps"),
}


def read_log_spec(path: str | os.PathLike[str] | None) -> LogSpec:
    """The log spec in ``path`` (None: the defaults).

    Raises:
        ConfigError: an unreadable file, an unknown key, a value of the wrong type.
    """
    if path is None:
        return LogSpec()
    p = Path(path)
    data = read_toml(p, ConfigError)
    spec = LogSpec(source=p)
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise ConfigError(
            describe(str(p), f"sections among {sorted(_KEYS)}", f"{unknown}", "remove them")
        )
    out: dict[str, Any] = {}
    for section, keys in _KEYS.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise ConfigError(describe(f"{p} [{section}]", "a table", repr(table), "fix it"))
        bad = sorted(set(table) - set(keys))
        if bad:
            raise ConfigError(
                describe(f"{p} [{section}]", f"keys among {list(keys)}", f"{bad}", "remove them")
            )
        for key, value in table.items():
            where = f"{p} [{section}] {key}"
            if section == "topics":
                if not isinstance(value, str) or not value.startswith("/"):
                    raise ConfigError(describe(where, "a topic name like '/x'", repr(value), ""))
                out[key] = value
            elif key == "names":
                if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                    raise ConfigError(describe(where, "a list of joint names", repr(value), ""))
                out["joint_names"] = tuple(value)
            elif key == "grid_tolerance":
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ConfigError(describe(where, "a number in (0, 0.5)", repr(value), ""))
                if not 0.0 < float(value) < 0.5:
                    raise ConfigError(describe(where, "a number in (0, 0.5)", repr(value), ""))
                out[key] = float(value)
            else:
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise ConfigError(describe(where, "an integer >= 0", repr(value), ""))
                out[key] = value
    return replace(spec, **out)
