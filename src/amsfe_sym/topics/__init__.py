"""What a topic means: one definition shared by recorded logs (``logs/``) and live ROS 2
nodes (``ros/``), so that a recorded session and a live one are the same run
(docs/topics.md).

Modules: ``roles`` (every role a topic can play for the estimator and the controller: its
message types, the fields used and their units, which stamp is the sample time, and the
meaning of a JointState's effort), ``spec`` (the topic spec: which topic plays which role,
the log's joint names, the effort's kind, timing tolerances, QoS and a live node's
watchdog bounds; TOML, every key with a default), ``watchdog`` (the ``[watchdog]`` table's
keys: docs/watchdogs.md).

May import: errors, core.  Nothing here reads a log or talks to a middleware; no ROS and no
``rosbags`` is needed to import it.
"""

from amsfe_sym.topics.roles import (
    EFFORT_KINDS,
    ROLES,
    EffortKind,
    Role,
    joint_order,
)
from amsfe_sym.topics.spec import TopicSpec, read_topic_spec

__all__ = [
    "EFFORT_KINDS",
    "ROLES",
    "EffortKind",
    "Role",
    "TopicSpec",
    "joint_order",
    "read_topic_spec",
]
