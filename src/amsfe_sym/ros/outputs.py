"""The estimate's standard deviations and theta of ``amsfe node``, published at a lower rate
than the estimate (docs/how-to/ros.md: every :data:`DEFAULT_STD_EVERY`-th tick by default), with one
message object a topic filled in each time (rclpy serializes at ``publish``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.ros.tick import TickOut

__all__ = ["DEFAULT_STD_EVERY", "StdPublisher", "std_due", "std_every_parameter"]

#: Default of ``amsfe node --std-every``: ``estimate_std`` and ``theta`` at 1/10 of the
#: encoder rate (100 Hz at 1 kHz), which takes two of the four publishes off most ticks.
DEFAULT_STD_EVERY = 10


def std_due(k: int, every: int, end_k: int | None) -> bool:
    """Whether tick ``k`` publishes ``estimate_std`` and ``theta``: tick 0, every
    ``every``-th tick, and the last tick ``end_k`` of the node's duration (None: none)."""
    return k % every == 0 or (end_k is not None and k >= end_k)


def std_every_parameter(node: Any, default: int) -> int:
    """The ROS parameter ``publish.std_every`` of ``node`` (default ``default``), checked.

    Raises:
        ConfigError: not an integer >= 1.
    """
    value = node.declare_parameter("publish.std_every", default).value
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(
            describe(
                f"ROS parameter publish.std_every of {node.get_name()}",
                "an integer >= 1 (ticks between estimate_std / theta messages)",
                repr(value),
                "-p publish.std_every:=10 (1: every tick), or amsfe node --std-every 10",
            )
        )
    return int(value)


class StdPublisher:
    """Publishes a tick's standard deviations of q, qd [rad, rad/s] (JointState position,
    velocity) and theta (Float64MultiArray), remembering the last tick it published."""

    def __init__(self, m: Any, pub_std: Any, pub_theta: Any, names: tuple[str, ...], n: int,
                 theta: slice) -> None:  # fmt: skip
        self.m, self.pub_std, self.pub_theta, self.n, self.theta = m, pub_std, pub_theta, n, theta
        self.msg_std = m.joint_state(0, names)
        self.msg_theta = m.Float64MultiArray()
        self.k = -1  # the last tick published

    def publish(self, out: TickOut) -> None:
        """``estimate_std`` and ``theta`` of ``out``, stamped as its estimate."""
        m, n = self.m, self.n
        std = np.sqrt(np.maximum(out.P_diag, 0.0))
        msg = self.msg_std
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(out.stamp_ns, 1_000_000_000)
        msg.position, msg.velocity = m.doubles(std[:n]), m.doubles(std[n : 2 * n])
        self.pub_std.publish(msg)
        self.msg_theta.data = m.doubles(out.x_hat[self.theta])
        self.pub_theta.publish(self.msg_theta)
        self.k = out.k
