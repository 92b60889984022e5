"""The Python node's wait for the torque applied over the previous tick: the C node's
``await_effort`` (``ros/c/amsfe_node_intake.c``; docs/live-load.md, "Torque and sample").

An arm publishes the torque it applied over tick k-1 on the effort topic (kind ``applied``)
just before sample k; DDS does not order two topics, and a node that estimates tick k before
that torque came uses its own command for tick k-1 (or the last torque) instead.  So before
the step k-1 -> k the node takes every torque already received and, when the effort stream
is live (the torque of tick k-2 came; at ticks 1 and 2, before any came, when the topic has
a publisher) and the torque of k-1 has not come, waits for it on the effort subscription
alone, up to half a period with a controller (the wait delays the command) and 20 periods
without one (an estimator's wait delays no command; a log played at its pace on a loaded
machine needs it).  The waits and the waits in vain are counted and said at the stop, in the
C node's words (:meth:`TorqueWait.line`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["WAIT_PERIODS_CONTROLLER", "WAIT_PERIODS_ESTIMATOR", "SubscriptionWait", "TorqueWait"]

#: The longest wait for the previous tick's torque with a controller [T].
WAIT_PERIODS_CONTROLLER = 0.5
#: The longest wait without a controller [T].
WAIT_PERIODS_ESTIMATOR = 20.0


@dataclass
class TorqueWait:
    """When to wait for the torque of the previous tick, and the counts (the C node's rule).

    Attributes:
        T: The sample period [s].
        controller: The node computes commands (the wait is then T/2, else 20 T).
        last: The newest tick of an applied torque received (-1: none yet).
        waits: Samples that waited for the previous tick's torque.
        missed: Waits that ended without it (the sample estimated without it).
    """

    T: float
    controller: bool
    last: int = -1
    waits: int = 0
    missed: int = 0

    @property
    def bound(self) -> float:
        """The longest wait [s]."""
        periods = WAIT_PERIODS_CONTROLLER if self.controller else WAIT_PERIODS_ESTIMATOR
        return periods * self.T

    def received(self, j: int | None) -> None:
        """An applied torque of tick ``j`` (None: off the grid, or before the first sample)
        was taken."""
        if j is not None and j > self.last:
            self.last = j

    def due(self, k: int | None, k_last: int, has_publisher: Callable[[], bool]) -> bool:
        """Whether sample ``k`` (its tick; None: off the grid or before the first sample)
        waits for the torque of tick k-1, ``k_last`` the last estimated tick: it is the next
        tick, that torque has not come, and the stream is live (the torque of k-2 came, or at
        ticks 1 and 2 before any came, ``has_publisher()``)."""
        if k is None or k_last < 0 or k != k_last + 1 or self.last >= k - 1:
            return False
        live = self.last >= k - 2  # else only at the start, with a publisher
        return live or (self.last < 0 and k <= 2 and has_publisher())

    def wait(
        self,
        k: int,
        block: Callable[[float], None],
        clock: Callable[[], float] = time.monotonic,
        stopped: Callable[[], bool] = lambda: False,
    ) -> None:
        """Wait until the torque of tick k-1 came (``block(seconds)`` waits for the effort
        subscription and takes what came, calling :meth:`received`), at most :attr:`bound`;
        counted, and counted missed when it did not come in time."""
        self.waits += 1
        until = clock() + self.bound
        while self.last < k - 1 and not stopped():
            left = until - clock()
            if left <= 0:
                self.missed += 1
                return
            block(left)

    def line(self) -> str | None:
        """The C node's stop line on the waits (None: no sample waited)."""
        if self.waits == 0:
            return None
        return (
            f"node: waited for the torque applied over the previous tick at {self.waits} "
            f"samples ({self.missed} not within the wait: estimated without it)"
        )


class SubscriptionWait:
    """One rclpy subscription waited on and taken from alone (an ``rcl_wait`` on a wait set
    holding it only, as the C node's ``ws_eff``), outside the executor: the executor's
    other entities (the encoders, the camera) are not spun meanwhile.

    Args:
        ctx: The rclpy context of the subscription's node.
        sub: The subscription (``rclpy.subscription.Subscription``).
        callback: Called with each message taken and its info (a dict with
            ``source_timestamp`` and ``received_timestamp`` [ns]), as the executor would.
    """

    def __init__(self, ctx: Any, sub: Any, callback: Callable[[Any, Any], None]) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        self._ctx, self._sub, self._callback = ctx, sub, callback
        with ctx.handle:
            self._ws = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, ctx.handle)

    def publishers(self) -> int:
        """The publishers matched with the subscription."""
        return int(self._sub.get_publisher_count())

    def take(self) -> int:
        """Take every message already received (each to the callback): how many."""
        count = 0
        with self._sub.handle:
            while True:
                got = self._sub.handle.take_message(self._sub.msg_type, self._sub.raw)
                if got is None:
                    return count
                self._callback(*got)
                count += 1

    def block(self, seconds: float) -> None:
        """Wait up to ``seconds`` [s] for a message on the subscription, then :meth:`take`."""
        with self._sub.handle, self._ctx.handle:
            self._ws.clear_entities()
            self._ws.add_subscription(self._sub.handle)
            self._ws.wait(int(seconds * 1e9) + 1)
        self.take()
