"""The ``[watchdog]`` table of the topic spec: the bounds past which a live node holds
(docs/watchdogs.md says what each watches, its cause and fix, and how each default was
measured).

```toml
[watchdog]
tracking_error = 0.1       # [rad] max_j |q_d - q_hat| once the start-up handed over
innovation_nis = 5.0       # mean of NIS / dimension over the window [-] (effort kind
                           # joint_torque or none: 30.0, INNOVATION_NIS)
innovation_window = 50     # fused updates (encoder samples and camera frames)
deadline = 0.05            # [s] a sample processed later than this after its stamp is late
deadline_misses = 50       # hold when more than this many of the window are late
deadline_window = 1000     # [samples]
lag = 0.01                 # [s] hold when the mean lateness of the queued samples of the
                           # window (the others count 0) is above this
compute_budget = 0.1       # [s] one tick's computation
encoder_timeout = 0.5      # [s] wall clock without an encoder sample
actuation_error = 0.01     # [-] |applied - command| / u_max per joint ([N m] without a limit)
actuation_ticks = 5        # consecutive judged ticks past actuation_error
```

A bound of ``inf`` (``tracking_error = inf`` in TOML) switches its check off.  The node's
``--encoder-timeout`` and the ROS parameters ``watchdog.<key>`` override the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "INNOVATION_NIS",
    "MEASURING",
    "WATCHDOG_COUNTS",
    "WATCHDOG_KEYS",
    "WATCHDOG_SWITCHES",
    "WatchdogBounds",
    "for_effort",
    "parse_watchdog",
]


@dataclass(frozen=True)
class WatchdogBounds:
    """The bounds of the watchdogs (the ``[watchdog]`` keys, same names and units).

    Attributes:
        tracking_error: Largest link tracking error max_j |q_d,j - q_hat,j| [rad], judged
            once the controller's start-up handed over (the blend ended); inf: off.
        innovation_nis: Largest mean of NIS / dimension over the last ``innovation_window``
            fused updates (encoder samples: dimension 2n or 3n; camera frames: 2) [-]; inf:
            off.  The default is the effort kind's (:data:`INNOVATION_NIS`, applied by the
            topic spec's parser through :func:`for_effort`); 5.0 here.
        innovation_window: Fused updates in that mean (the check starts once it is full).
        deadline: A sample processed (command computed) later than this after its stamp
            (on the node's wall clock, the stamps shifted by the first sample's offset) is
            late [s]; inf: off.
        deadline_misses: Hold when more than this many of the last ``deadline_window``
            samples were late.
        deadline_window: Samples in that count, and in the mean of ``lag``.
        lag: Largest mean lateness of the last ``deadline_window`` samples [s], a sample
            counting with its lateness (as ``deadline`` measures it, at most ``deadline``)
            when it was queued (due before the previous sample's command was done: the arm
            ran on an older command; never in lockstep) and late, else 0 (also the samples
            before the first); inf: off.  The default is a third of the steady lag at which
            paper-sim's loop leaves its path (30 ms: 0.26 rad; 10 ms: 0.008 rad, under twice a
            clean run's; docs/watchdogs.md).
        compute_budget: Longest computation of one tick (sample taken -> command ready)
            [s]; inf: off.
        encoder_timeout: Longest wall-clock silence of the encoders, and longest gap
            between two calls of the node's own loop [s].
        actuation_error: Largest difference between the torque the arm reports applying
            (effort kind ``applied``) and the command it applied, per joint, as a fraction
            of the joint's actuator limit u_max [-] (a joint without a limit: in [N m]);
            the command is the one of the node's commands up to the effort's tick that
            the arm applied (ros/watchdog.py); inf: off.
        actuation_ticks: Hold when that many judged ticks in a row are past it.
    """

    tracking_error: float = 0.1
    innovation_nis: float = 5.0
    innovation_window: int = 50
    deadline: float = 0.05
    deadline_misses: int = 50
    deadline_window: int = 1000
    lag: float = 0.01
    compute_budget: float = 0.1
    encoder_timeout: float = 0.5
    actuation_error: float = 0.01
    actuation_ticks: int = 5

    def with_timeout(self, encoder_timeout: float | None) -> WatchdogBounds:
        """These bounds with ``encoder_timeout`` [s] (``amsfe node --encoder-timeout``; None:
        as they are)."""
        return self if encoder_timeout is None else replace(self, encoder_timeout=encoder_timeout)


#: The default ``innovation_nis`` per effort kind (``[effort] kind``; docs/watchdogs.md, "The
#: innovation bound per effort kind", tools/watchdog_innovation.py): the filter given the
#: applied torque is consistent (clean window means up to 1.5); given a measured joint torque,
#: or no torque, it carries the input as states and is overconfident (clean window means up
#: to 19.2 on paper-sim), so its bound sits 1.56x above that; a frozen encoder, a 20 mrad
#: jump and a misreported torque still cross it within 30 ms.
INNOVATION_NIS: dict[str, float] = {"applied": 5.0, "joint_torque": 30.0, "none": 30.0}


def for_effort(
    bounds: WatchdogBounds, effort_kind: str | None, explicit: bool = False
) -> WatchdogBounds:
    """``bounds`` with the default ``innovation_nis`` of ``effort_kind``
    (:data:`INNOVATION_NIS`; None: ``applied``), unless the spec set it (``explicit``)."""
    if explicit:
        return bounds
    return replace(bounds, innovation_nis=INNOVATION_NIS[effort_kind or "applied"])


#: The keys of ``[watchdog]`` (the fields of :class:`WatchdogBounds`).
WATCHDOG_KEYS = tuple(f.name for f in fields(WatchdogBounds))
#: The keys that are counts (integers); the others are numbers > 0.
WATCHDOG_COUNTS = ("innovation_window", "deadline_misses", "deadline_window", "actuation_ticks")
#: The bounds that ``inf`` switches off: every number but ``encoder_timeout`` (a node that
#: cannot tell its encoders went silent could not hold for it).
WATCHDOG_SWITCHES = tuple(
    k for k in WATCHDOG_KEYS if k not in WATCHDOG_COUNTS and k != "encoder_timeout"
)
#: Every bound that can be switched off, off (inf): the bounds of the runs that measure the
#: watched quantities over a whole run (tools/watchdog_bounds.py, tools/watchdog_innovation.py).
_OFF: dict[str, Any] = dict.fromkeys(WATCHDOG_SWITCHES, math.inf)
MEASURING = replace(WatchdogBounds(), **_OFF)
_AT_LEAST = {
    "innovation_window": 1,
    "deadline_misses": 0,
    "deadline_window": 1,
    "actuation_ticks": 1,
}


def parse_watchdog(table: dict[str, Any], where: str = "[watchdog]") -> WatchdogBounds:
    """The bounds of a parsed ``[watchdog]`` table (missing keys: the defaults).

    Raises:
        ConfigError: an unknown key, a count that is not an integer at or above its least
            value, a bound that is not a number > 0 (inf allowed, except for
            ``encoder_timeout``).
    """
    bad = sorted(set(table) - set(WATCHDOG_KEYS))
    if bad:
        raise ConfigError(
            describe(where, f"keys among {list(WATCHDOG_KEYS)}", str(bad), "drop them")
        )
    out: dict[str, Any] = {}
    for key, value in table.items():
        at = f"{where} {key}"
        if key in WATCHDOG_COUNTS:
            lo = _AT_LEAST[key]
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise ConfigError(describe(at, f"an integer >= {lo}", repr(value), "fix it"))
            out[key] = int(value)
        else:
            finite = key not in WATCHDOG_SWITCHES
            ok = isinstance(value, int | float) and not isinstance(value, bool) and value > 0
            if not ok or (finite and math.isinf(value)):
                expected = "a number > 0 [s]" if finite else "a number > 0 (inf: off)"
                raise ConfigError(describe(at, expected, repr(value), "fix it"))
            out[key] = float(value)
    return WatchdogBounds(**out)
