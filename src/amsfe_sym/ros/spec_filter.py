"""The topic spec's ``[filter]`` on a live node (docs/how-to/ros.md, "Topic spec"): the same keys
as a scenario's ``[filter]``, applied over the scenario's key by key by
:func:`~amsfe_sym.scenario.with_filter`, as ``amsfe estimate`` applies a log spec's, so that
one spec means one filter on a log and live."""

from __future__ import annotations

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.scenario import Scenario, with_filter
from amsfe_sym.topics.spec import FROM_LOG, TopicSpec

__all__ = ["live_filter"]


def live_filter(sc: Scenario, spec: TopicSpec) -> Scenario:
    """``sc`` with the topic spec's ``[filter]`` keys over its own (the spec wins key by key).

    Raises:
        ConfigError: ``encoder_q_std`` / ``encoder_qd_std = "log"`` (measured from a recorded
            log; live there is none yet: give numbers, e.g. what ``amsfe estimate`` printed on a
            recording of the same arm), or values the scenario refuses.
    """
    opts = dict(spec.filter_options)
    if not opts:
        return sc
    measured = [k for k, v in opts.items() if v == FROM_LOG]
    if measured:
        raise ConfigError(
            describe(
                f"{spec.source or 'topic spec'} [filter] {', '.join(measured)} on a live node",
                "numbers [rad, rad/s]",
                f'"{FROM_LOG}" (measured from a recorded log; live there is none)',
                "set the numbers amsfe estimate printed on a recording of this arm "
                "('encoder noise from the log: ...')",
            )
        )
    return with_filter(sc, opts, f"{spec.source or 'topic spec'} [filter] over the scenario's")
