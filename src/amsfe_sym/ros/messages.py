"""The ROS 2 messages of the topic roles (:data:`amsfe_sym.topics.ROLES`), built and read
without per-element checks (arrays of doubles are handed over as ``array('d')``).

Imports the message packages of the ``[ros]`` extra: import this module only once
:func:`amsfe_sym.ros.middleware.load_rclpy` succeeded.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PointStamped
from numpy.typing import ArrayLike, NDArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String

from amsfe_sym.ros.middleware import ns_to_stamp

__all__ = [
    "Clock",
    "Float64MultiArray",
    "JointState",
    "PointStamped",
    "String",
    "clock",
    "doubles",
    "float64_array",
    "joint_state",
    "point_stamped",
]

FloatArray = NDArray[np.float64]


def doubles(values: ArrayLike) -> array[float]:
    """``values`` as ``array('d')`` (what rclpy stores for float64[] fields)."""
    return array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())


def _header(ns: int, frame: str = "") -> Header:
    return Header(stamp=ns_to_stamp(ns), frame_id=frame)


def joint_state(
    ns: int,
    names: Sequence[str],
    position: ArrayLike | None = None,
    velocity: ArrayLike | None = None,
    effort: ArrayLike | None = None,
) -> JointState:
    """A ``sensor_msgs/JointState`` stamped ``ns`` [ns]."""
    msg = JointState(header=_header(ns), name=list(names))
    if position is not None:
        msg.position = doubles(position)
    if velocity is not None:
        msg.velocity = doubles(velocity)
    if effort is not None:
        msg.effort = doubles(effort)
    return msg


def float64_array(values: ArrayLike) -> Float64MultiArray:
    """A ``std_msgs/Float64MultiArray`` (no layout: a flat vector)."""
    msg = Float64MultiArray()
    msg.data = doubles(values)
    return msg


def point_stamped(ns: int, u: float, v: float, frame: str = "camera") -> PointStamped:
    """A camera marker: pixel (u, v) [px] stamped at its exposure ``ns`` [ns]."""
    return PointStamped(header=_header(ns, frame), point=Point(x=float(u), y=float(v), z=0.0))


def clock(ns: int) -> Clock:
    """A ``rosgraph_msgs/Clock`` at ``ns`` [ns]."""
    return Clock(clock=ns_to_stamp(ns))


def values(field: Any) -> FloatArray:
    """A message's float64[] field as a numpy array (a copy)."""
    return np.array(field, dtype=np.float64)


def stamp_ns(stamp: Time) -> int:
    """Nanoseconds of a header stamp."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
