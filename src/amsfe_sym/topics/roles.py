"""The roles a topic plays for amsfe, in one table (robot_localization's habit: each input
declared once, by topic, with the fields it contributes).  Recorded logs and live nodes read
and write these roles the same way (docs/reference/topics.md).

Inputs (what the estimator and the controller consume): ``encoders`` (required), ``effort``,
``camera``, ``truth`` and ``config``; outputs (what amsfe publishes live and writes into its
own bags): ``estimate``, ``estimate_std``, ``theta``, ``diagnostics``, ``commands`` and
``clock``.  :data:`ROLES` holds each one's default topic, message types, stamp and meaning;
docs/reference/topics.md has the table.

A driver's ``/joint_states`` (position, velocity and effort of every joint) plays the roles
``encoders`` and ``effort`` at once: one topic may serve several roles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from amsfe_sym.core.values import EFFORT_KINDS, EffortKind
from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "EFFORT_KINDS",
    "ROLES",
    "EffortKind",
    "Role",
    "joint_order",
]

JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_ARRAY = "std_msgs/msg/Float64MultiArray"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
STRING = "std_msgs/msg/String"
CLOCK = "rosgraph_msgs/msg/Clock"


@dataclass(frozen=True)
class Role:
    """One role a topic plays.

    Attributes:
        name: The role's name (the key in a topic spec's ``[topics]``).
        topic: Its default topic.
        types: The ROS 2 message types it accepts, the preferred first.
        stamp: Which time is the sample's: ``header`` (``header.stamp``) or ``arrival``
            (the receive time: a log's log time, a live node's clock at reception).
        direction: ``in`` (amsfe consumes it) or ``out`` (amsfe publishes it).
        required: Whether an estimate needs it (``encoders`` only: every other input is
            optional or has a mode without it).
        meaning: The fields used and their units, for messages and docs.
    """

    name: str
    topic: str
    types: tuple[str, ...]
    stamp: Literal["header", "arrival"]
    direction: Literal["in", "out"]
    required: bool
    meaning: str


ROLES: dict[str, Role] = {
    r.name: r
    for r in (
        Role(
            "encoders",
            "/motor_encoders",
            (JOINT_STATE,),
            "header",
            "in",
            True,
            "position = motor angle qm [rad], velocity = qmd [rad/s], by joint name",
        ),
        Role(
            "effort",
            "/motor_torque",
            (JOINT_STATE, FLOAT64_ARRAY),
            "header",  # a Float64MultiArray has no header: its arrival is its stamp
            "in",
            False,
            "JointState effort or Float64MultiArray data (q order) [N m]; its kind says "
            "whether it is the applied torque, the measured joint torque or unused",
        ),
        Role(
            "camera",
            "/camera/marker",
            (POINT_STAMPED,),
            "header",
            "in",
            False,
            "point.x, point.y = pixel u, v [px]; header.stamp = exposure, arrival = receive",
        ),
        Role(
            "truth",
            "/amsfe/truth",
            (FLOAT64_ARRAY,),
            "arrival",
            "in",
            False,
            "the true state [q, qd, qm, qmd, theta] (simulated runs)",
        ),
        Role("config", "/amsfe/config", (STRING,), "arrival", "in", False, "amsfe's run config"),
        Role(
            "estimate",
            "/amsfe/estimate",
            (JOINT_STATE,),
            "header",
            "out",
            False,
            "position = q_hat [rad], velocity = qd_hat [rad/s] of x(k|k)",
        ),
        Role(
            "estimate_std",
            "/amsfe/estimate_std",
            (JOINT_STATE,),
            "header",
            "out",
            False,
            "standard deviations of q_hat [rad] and qd_hat [rad/s]",
        ),
        Role("theta", "/amsfe/theta", (FLOAT64_ARRAY,), "arrival", "out", False, "theta_hat"),
        Role(
            "diagnostics",
            "/amsfe/diagnostics",
            (STRING,),
            "arrival",
            "out",
            False,
            "JSON: frames fused, refused by reason, NIS",
        ),
        Role(
            "commands",
            "/effort_controller/commands",
            (FLOAT64_ARRAY,),
            "arrival",
            "out",
            False,
            "effort command [N m] in q order (ros2_control forward command controller)",
        ),
        Role("clock", "/clock", (CLOCK,), "arrival", "out", False, "sim time"),
    )
}


def joint_order(names: Sequence[str], joints: Sequence[str], where: str) -> list[int]:
    """Indices of the robot's ``joints`` (q order) in a message's ``names``; extra names
    (fingers, grippers) are ignored.

    Raises:
        ConfigError: a joint of the robot is missing from ``names``, or ``names`` repeats one
            of them (which one would be meant?).
    """
    names = list(names)
    missing = [j for j in joints if j not in names]
    if missing:
        raise ConfigError(
            describe(
                where,
                f"JointState names including the robot's {list(joints)}",
                f"{names} (missing {missing})",
                "map the log's joint names to the robot's in the topic spec's [joints] names",
            )
        )
    twice = sorted({j for j in joints if names.count(j) > 1})
    if twice:
        raise ConfigError(
            describe(
                where,
                "each joint name once",
                f"{twice} more than once in {names}",
                "fix the publisher, or map other names in the topic spec's [joints] names",
            )
        )
    return [names.index(j) for j in joints]
