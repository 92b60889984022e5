"""The log spec is the topic spec (:mod:`amsfe_sym.topics.spec`): one definition of what a
topic means for recorded logs and live nodes alike.  Kept for the names logs/ used before."""

from __future__ import annotations

from amsfe_sym.topics.spec import TopicSpec, read_topic_spec

__all__ = ["LogSpec", "read_log_spec"]

LogSpec = TopicSpec
read_log_spec = read_topic_spec
