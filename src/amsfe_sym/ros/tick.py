"""What one encoder sample through the live loop (:class:`amsfe_sym.ros.live.LiveLoop`)
produced: its tick's estimate and command (:class:`TickOut`), the watchdog's decision on it
(:class:`Watched`), and the fail-safe command a node holds with (:func:`hold_command`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.control import Controller
from amsfe_sym.estimation.base import StepReport
from amsfe_sym.ros.watchdog import WatchdogTick
from amsfe_sym.ros.watchdog_reasons import Reason
from amsfe_sym.runtime.library import ModelLibrary

__all__ = ["HoldKind", "TickOut", "Watched", "hold_command"]

FloatArray = NDArray[np.float64]

#: What the fail-safe hold commands: ``gravity``: u = g(q_hat, theta_hat) (the torque that
#: holds the links still where the last finite estimate has them: at rest the motor torque
#: equals the spring torque equals gravity); ``zero``: u = 0 (for drivers that compensate
#: gravity themselves, like Franka's).
HoldKind = Literal["gravity", "zero"]


@dataclass(frozen=True)
class TickOut:
    """What one encoder sample produced.

    Attributes:
        k: Its tick.
        t: t_k = k T from the first sample [s].
        stamp_ns: Its header stamp [ns].
        x_hat: x(k|k), shape (N,).
        P_diag: diag P(k|k), shape (N,).
        u: The command u_k [N m] (saturated), or None without a controller.
        report: The estimator's step report (None at tick 0).
        predicted: Missing ticks predicted through before this one.
    """

    k: int
    t: float
    stamp_ns: int
    x_hat: FloatArray
    P_diag: FloatArray
    u: FloatArray | None
    report: StepReport | None
    predicted: int = 0


@dataclass(frozen=True)
class Watched:
    """An encoder sample through :meth:`LiveLoop.watch`.

    Attributes:
        out: What it produced (None: skipped, or the estimator failed).
        reason: The watchdog's decision (:attr:`~amsfe_sym.ros.watchdog_reasons.Reason.NONE`: go
            on and publish ``out``; else hold).
        tick: What the watchdog judged (None: the sample was skipped, nothing judged).
    """

    out: TickOut | None
    reason: Reason
    tick: WatchdogTick | None = None


def hold_command(
    lib: ModelLibrary, kind: HoldKind, last: TickOut | None, ctrl: Controller | None = None
) -> FloatArray:
    """The hold command [N m]: zero, or g(q_hat, theta_hat) at the last finite estimate
    ``last`` (zero without one), clipped to the actuator limits."""
    n = lib.n
    if kind == "zero" or last is None or not np.all(np.isfinite(last.x_hat)):
        return np.zeros(n)
    L = lib.layout
    x = last.x_hat
    g = np.array(lib.function("gravity")(x[L["q"]], x[L["theta"]])[0], dtype=float)
    limit = np.array(lib.manifest.actuators.u_max or (np.inf,) * n, dtype=float)
    return np.asarray(np.clip(g, -limit, limit), dtype=float)
