"""A simulated log of each effort kind played into the node's watchdog, in process, with
faults injected: what the ``innovation`` bound per effort kind is measured and tested on
(docs/watchdogs.md "The innovation bound per effort kind", tools/watchdog_innovation.py,
tests/test_watchdog_effort.py).

A simulated run (the scenario's seed) is logged as an arm with effort kind ``kind`` logs it
(``applied``: the command u; ``joint_torque``: the true spring torque Ks (qm - q) plus
``torque_std`` of noise, a torque sensor's tau_J; ``none``: no torque), with
``positions = "link"`` the link angle (plus the encoder's noise) as the encoders' position (a
Franka's ``/joint_states``).  The node's :class:`~amsfe_sym.ros.live.LiveLoop` (estimator
only, the replay estimator: ``amsfe play LOG`` into ``amsfe node --topic-spec``) takes it
sample by sample, as ``tests/test_ros.py``'s ``test_live_loop_with_a_joint_torque_is_estimate``
does, and its watchdog judges every sample with ``bounds``.  The log's clock is the wall
clock (a lockstep play): nothing here depends on this machine's speed.

Faults (:data:`LOG_FAULTS`), from ``at`` [s] of the log on:

- ``frozen``: the encoders repeat the sample of ``at`` (a frozen driver);
- ``jump``: the encoder positions jump by ``size`` [rad] (a slipped encoder);
- ``torque_zero``: the logged torque reads zero (a dead torque sensor, a drive reporting
  nothing), the arm moving as before;
- ``torque_reversed``: the logged torque has the wrong sign (a sensor or a drive wired
  reversed).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.estimation.effort import EffortSpec
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.ros.watchdog import Hold
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.effort import simulated_effort
from amsfe_sym.sim.loop import run
from amsfe_sym.topics.watchdog import WatchdogBounds

__all__ = ["LOG_FAULTS", "LogFault", "PlayedLog", "play_watched"]

FloatArray = NDArray[np.float64]
LogFault = Literal["none", "frozen", "jump", "torque_zero", "torque_reversed"]
#: The faults :func:`play_watched` injects into a log.
LOG_FAULTS: tuple[LogFault, ...] = ("frozen", "jump", "torque_zero", "torque_reversed")


@dataclass(frozen=True)
class PlayedLog:
    """What a played log gave.

    Attributes:
        means: The window mean of NIS / dimension (ros/watchdog.py's check 8) after each
            sample [-], (K,): nan until the window is full and after the hold.
        hold: The watchdog's hold (None: the log played to its end).
        hold_t: The log time of the sample held at [s] (None: none).
        T: The sample period [s].
    """

    means: FloatArray
    hold: Hold | None
    hold_t: float | None
    T: float


def play_watched(
    sc: Scenario,
    lib: ModelLibrary,
    kind: str,
    positions: str = "motor",
    fault: LogFault = "none",
    at: float = math.inf,
    *,
    size: float = 0.01,
    bounds: WatchdogBounds | None = None,
    torque_std: float = 0.05,
) -> PlayedLog:
    """Play the log of ``sc``'s run with effort ``kind`` and encoder ``positions``, and
    ``fault`` from ``at`` [s] (``size``: the jump [rad]), into the node's loop judged by
    ``bounds`` (None: the defaults), until its end or a hold (module docstring).

    Args:
        sc: The scenario (its seed, duration).
        lib: Its library.
        kind: ``applied``, ``joint_torque`` or ``none``.
        positions: ``motor`` or ``link`` (only with ``joint_torque``).
        fault: What to inject (module docstring).
        at: From this log time [s].
        size: The jump [rad].
        bounds: The watchdogs' bounds.
        torque_std: The joint torque sensor's noise [N m].
    """
    res = run(sc, lib, runtime="compiled")
    n, lay, T = lib.n, lib.layout, lib.T
    T_ns = round(T * 1e9)
    tau = simulated_effort(res, kind, np.random.default_rng(sc.seed + 1), torque_std)
    z_enc = np.array(res.z_enc, dtype=float)
    if positions == "link":
        z_enc[:, :n] += res.x_true[:, lay["q"]] - res.x_true[:, lay["qm"]]
    K = res.t.size
    start = K if math.isinf(at) else min(K, round(at / T))
    if fault == "frozen":
        z_enc[start:] = z_enc[min(start, K - 1)]
    elif fault == "jump":
        z_enc[start:, :n] += size
    elif fault in ("torque_zero", "torque_reversed") and tau is not None:
        tau = tau.copy()
        tau[start:] = 0.0 if fault == "torque_zero" else -tau[start:]
    effort = None if kind == "applied" else EffortSpec(kind, positions=positions)
    loop = LiveLoop(sc.with_overrides(estimator="replay"), lib, controller=False,
                    effort=effort, watchdog=bounds)  # fmt: skip
    frames: dict[int, list[tuple[int, FloatArray]]] = {}
    for kappa, k, u, v in res.frames:
        frames.setdefault(int(k), []).append((int(kappa), np.array([u, v])))
    wd = loop.watchdog
    window: deque[float] = deque(maxlen=wd.config.bounds.innovation_window)
    means = np.full(K, np.nan)
    for k in range(K):
        for kappa, z in frames.get(k, []):
            loop.frame(kappa * T_ns, z)
        if tau is not None:
            loop.effort(k * T_ns, tau[k])
        w = loop.watch(k * T_ns, z_enc[k], taken=k * T, clock=_Now(k * T))
        tick = w.tick
        if tick is not None and tick.status == 0:
            if math.isfinite(tick.encoder_nis):
                window.append(tick.encoder_nis / wd.config.ne)
            window.extend(v / 2.0 for v in tick.frame_nis if math.isfinite(v))
            if len(window) == window.maxlen:
                means[k] = sum(window) / len(window)
        if wd.hold is not None:
            return PlayedLog(means, wd.hold, k * T, T)
    return PlayedLog(means, None, None, T)


@dataclass(frozen=True)
class _Now:
    """A wall clock standing at ``now`` [s] (the log's time: a lockstep play)."""

    now: float

    def __call__(self) -> float:
        return self.now
