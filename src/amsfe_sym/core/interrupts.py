"""Ctrl-C and SIGTERM held while third-party code runs, delivered at the toolkit's own
checkpoints.

A ``KeyboardInterrupt`` raised inside another library can be lost: trimesh (imported by
yourdfpy) wraps every exception of its optional imports, ``BaseException`` included, and
CasADi's C++ code runs Python callbacks where an exception may be swallowed or, once seen,
crash the process.  So ``amsfe generate`` used to go on to the end after a Ctrl-C in its
first seconds.  :class:`DeferredSignals` replaces the Python handlers of SIGINT and SIGTERM
by one that only records the signal; :func:`checkpoint` (called by the build between its
stages and while it waits for the compiler) and leaving the block call the handler that was
there before (``KeyboardInterrupt``, or the command line's SIGTERM exception), so the
interruption is raised in the toolkit's own code, where every ``finally`` cleans up.

:func:`wait_held` and :func:`result_held` are the waits of the main thread on worker threads
(the image prefetch): a ``KeyboardInterrupt`` raised inside ``threading``'s Python-level lock
protocol can leave a lock held.  The interpreter looks for signals after each call into C,
so a Ctrl-C that came while ``Condition.__enter__`` waited for its lock is raised after the
lock was taken and before the ``with`` block holds it: nothing ever releases it, the worker
that needs it next waits forever, and so does the join at exit (``amsfe estimate`` of a jpeg
log hung on a Ctrl-C: tests/test_interrupts.py reproduces the leak).  Held, the signal is
raised between two waits, where no lock is taken.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from concurrent.futures import Future
from types import FrameType, TracebackType
from typing import Any, TypeVar

__all__ = ["POLL_S", "DeferredSignals", "checkpoint", "result_held", "wait_held"]

T = TypeVar("T")

#: How often [s] a held wait (:func:`wait_held`, :func:`result_held`) delivers a held signal.
POLL_S = 0.05

_Handler = Callable[[int, FrameType | None], Any]

#: The blocks in force, innermost last (:func:`checkpoint` asks the innermost).
_ACTIVE: list[DeferredSignals] = []


class DeferredSignals:
    """Hold ``signums`` inside a ``with`` block; raise them at :meth:`check` or on exit.

    Only Python-level handlers are replaced (a signal that is ignored or has its default
    action is left alone), and only in the main thread (elsewhere the block does nothing).
    The same signal a second time before a checkpoint is delivered at once (a second Ctrl-C
    stops a stage that runs long between checkpoints).
    """

    def __init__(self, signums: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> None:
        self._signums = signums
        self._previous: dict[int, _Handler] = {}  # the real handler, delivered at a check
        self._installed: dict[int, _Handler] = {}  # what to put back on exit
        self._pending: list[int] = []

    def __enter__(self) -> DeferredSignals:
        if threading.current_thread() is threading.main_thread():
            for s in self._signums:
                prev = signal.getsignal(s)
                if callable(prev):
                    self._installed[s] = prev
                    # inside another block: deliver to the handler that block holds back,
                    # not to its hold (which would only record the signal again)
                    outer = getattr(prev, "__self__", None)
                    real = outer._previous.get(s) if isinstance(outer, DeferredSignals) else None
                    self._previous[s] = real or prev
                    signal.signal(s, self._hold)
        _ACTIVE.append(self)
        return self

    def _hold(self, signum: int, frame: FrameType | None) -> None:
        if signum in self._pending:  # asked twice: deliver it now, wherever the code is
            self._pending.remove(signum)
            self._previous[signum](signum, frame)
            return
        self._pending.append(signum)

    @property
    def pending(self) -> bool:
        """A held signal waits to be delivered."""
        return bool(self._pending)

    def check(self) -> None:
        """Deliver the first held signal: call the handler that was in place before the
        block (which raises ``KeyboardInterrupt`` for SIGINT)."""
        if self._pending:
            s = self._pending[0]
            self._pending.clear()
            self._previous[s](s, None)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        _ACTIVE.remove(self)
        for s, prev in self._installed.items():
            signal.signal(s, prev)
        if exc_type is None:
            self.check()


def checkpoint() -> None:
    """Deliver a signal held by a :class:`DeferredSignals` block in force (the innermost
    first; an outer block's too, since its code chose to run the inner one): the place where
    a long computation of the toolkit may be interrupted."""
    for block in reversed(_ACTIVE):
        if block.pending:
            block.check()
            return


def wait_held(ready: Callable[[float], bool], poll: float = POLL_S) -> None:
    """Call ``ready(timeout)`` (``timeout`` = ``poll`` [s]; e.g. a semaphore's ``acquire``)
    until it returns True, with Ctrl-C and SIGTERM held during each call and delivered
    between calls (module docstring: a lock is never left held by an interruption)."""
    with DeferredSignals() as hold:
        while not ready(poll):
            hold.check()


def result_held(fut: Future[T], poll: float = POLL_S) -> T:
    """``fut.result()``, waited for as :func:`wait_held` waits: a Ctrl-C meanwhile is
    raised between two waits of ``poll`` [s], never inside the future's lock."""
    with DeferredSignals() as hold:
        while True:
            try:
                return fut.result(timeout=poll)
            except TimeoutError:
                hold.check()
