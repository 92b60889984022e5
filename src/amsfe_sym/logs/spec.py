"""The log spec is the topic spec (:mod:`amsfe_sym.topics.spec`): one definition of what a
topic means for recorded logs and live nodes alike.  Kept for the names logs/ used before."""

from __future__ import annotations

from amsfe_sym.topics.roles import ROLES
from amsfe_sym.topics.spec import TopicSpec, read_topic_spec

__all__ = ["TORQUE_TYPES", "LogSpec", "read_log_spec"]

#: The message types an effort (torque) topic may have.
TORQUE_TYPES = ROLES["effort"].types

LogSpec = TopicSpec
read_log_spec = read_topic_spec
