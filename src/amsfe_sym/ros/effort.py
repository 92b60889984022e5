"""The effort topic of a live node by its kind (docs/how-to/ros.md, "Effort";
docs/explanation/effort.md).

``applied``: the torque the arm applied, the estimator's input (:meth:`LiveLoop.applied
<amsfe_sym.ros.live.LiveLoop.applied>`).  ``joint_torque``: a measured joint torque
``tau_J`` (Franka, iiwa), fused with the encoders as ``amsfe estimate`` fuses a log's: each
encoder sample's row is :func:`~amsfe_sym.estimation.effort.encoder_row` of the sample and
the joint torque held at its tick (:class:`TorqueHold`, the log reader's zero-order hold by
stamp), the input carried as states.  ``none``: encoders only, the input as states.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation.effort import EffortSpec, effort_spec
from amsfe_sym.topics import TopicSpec

__all__ = ["TorqueHold", "effort_values", "live_effort"]

FloatArray = NDArray[np.float64]


def live_effort(spec: TopicSpec) -> EffortSpec | None:
    """The :class:`~amsfe_sym.estimation.effort.EffortSpec` a live node estimates with (as
    ``amsfe estimate`` builds it from a log spec: ``[effort]`` keys, ``[joints]
    positions``), or None for kind ``applied`` (the effort is the input).

    Raises:
        ConfigError: a bad ``[effort]`` value, or ``input_model = "reconstruct"`` (it needs
            the next sample's rate; live, only the input as states is built).
    """
    kind = spec.effort_kind or "applied"
    if kind == "applied":
        return None
    where = f"{spec.source or 'topic spec'} [effort]"
    eff = replace(effort_spec(dict(spec.effort_options), where), kind=kind)
    eff = replace(eff, positions=spec.positions)
    if eff.input_model != "state":
        raise ConfigError(
            describe(
                f"{where} input_model of a live node",
                '"state" (the input carried as states)',
                repr(eff.input_model),
                'leave input_model out live ("reconstruct" is for amsfe estimate of a log)',
            )
        )
    return eff


def effort_values(m: Any, msg: Any, idx: list[int], n: int) -> FloatArray:
    """A JointState's effort in the robot's joint order [as logged], or n NaN when it does
    not hold one value per name."""
    eff = m.values(msg.effort)
    return eff[idx] if eff.size == len(msg.name) else np.full(n, np.nan)


class TorqueHold:
    """Joint torque samples held by stamp, as the log reader holds a log's effort
    (:func:`amsfe_sym.logs.sensors.held_effort`): the torque of tick k is the last sample
    stamped before ``t_k + T/2``."""

    def __init__(self, T_ns: int) -> None:
        self._T_ns = T_ns
        self._samples: list[tuple[int, FloatArray]] = []  # by stamp

    def add(self, stamp_ns: int, tau: FloatArray) -> None:
        """A sample [as logged] stamped ``stamp_ns`` [ns] (finite, n values: the caller
        checks)."""
        self._samples.append((stamp_ns, np.array(tau, dtype=float)))
        self._samples.sort(key=lambda s: s[0])

    def at(self, t0_ns: int, k: int) -> FloatArray | None:
        """The torque held at tick ``k`` of the grid starting at ``t0_ns`` [ns], None before
        the first sample; the samples it supersedes are dropped (later ticks cannot use
        them)."""
        limit = 2 * t0_ns + (2 * k + 1) * self._T_ns  # twice t_k + T/2: integers
        i = -1
        for j, (stamp, _) in enumerate(self._samples):
            if 2 * stamp < limit:
                i = j
            else:
                break
        if i < 0:
            return None
        del self._samples[:i]
        return self._samples[0][1]
