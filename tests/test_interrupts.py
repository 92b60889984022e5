"""``core.interrupts``: a signal is held inside a ``DeferredSignals`` block and raised by
the handler that was there before, at a checkpoint or when the block ends; the same signal
twice is raised at once; outside a block nothing changes."""

from __future__ import annotations

import _thread
import fcntl
import os
import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from amsfe_sym.codegen.cache import build_lock
from amsfe_sym.core.interrupts import DeferredSignals, checkpoint, result_held, wait_held


class StoppedError(Exception):
    pass


def _raise(signum: int, frame: object) -> None:
    raise StoppedError(signum)


@pytest.fixture
def usr1():  # type: ignore[no-untyped-def]
    previous = signal.signal(signal.SIGUSR1, _raise)
    yield signal.SIGUSR1
    signal.signal(signal.SIGUSR1, previous)


def test_a_signal_is_held_until_a_checkpoint(usr1: int) -> None:
    with DeferredSignals((usr1,)) as held:
        os.kill(os.getpid(), usr1)
        assert held.pending  # the third-party code in here went on
        with pytest.raises(StoppedError):
            checkpoint()
        assert not held.pending
        checkpoint()  # nothing left
    assert signal.getsignal(usr1) is _raise


def test_a_held_signal_is_raised_when_the_block_ends(usr1: int) -> None:
    ran = []
    with pytest.raises(StoppedError), DeferredSignals((usr1,)):
        os.kill(os.getpid(), usr1)
        ran.append(1)
    assert ran == [1] and signal.getsignal(usr1) is _raise


def test_the_same_signal_twice_is_raised_at_once(usr1: int) -> None:
    with DeferredSignals((usr1,)) as held:
        os.kill(os.getpid(), usr1)
        with pytest.raises(StoppedError):
            os.kill(os.getpid(), usr1)
        assert not held.pending


def test_outside_a_block_checkpoint_does_nothing(usr1: int) -> None:
    checkpoint()
    with pytest.raises(StoppedError):
        os.kill(os.getpid(), usr1)


@pytest.fixture
def sigint():  # type: ignore[no-untyped-def]
    """SIGINT raises :class:`StoppedError` (not KeyboardInterrupt, which would stop pytest)."""
    previous = signal.signal(signal.SIGINT, _raise)
    yield signal.SIGINT
    signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_as_the_lock_is_taken_leaves_no_lock_file(
    sigint: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The signal lands inside ``flock``, right after the lock file was made: it used to be
    raised before the ``try`` that removes the file (CI: ``.ur5.lock`` left behind)."""
    real_flock = fcntl.flock

    def flock_then_ctrl_c(fd: Any, op: int) -> None:
        real_flock(fd, op)
        if op & fcntl.LOCK_EX:
            os.kill(os.getpid(), sigint)

    monkeypatch.setattr(fcntl, "flock", flock_then_ctrl_c)
    lock = tmp_path / "gen" / ".robot.lock"
    ran = []
    with pytest.raises(StoppedError), build_lock(lock):
        ran.append(True)
    assert ran == []  # held, delivered once the lock is taken, before the body
    assert not (tmp_path / "gen").exists()  # neither the file nor the folder it made


def test_a_ctrl_c_while_another_build_holds_the_lock_stops_the_wait(
    sigint: int, tmp_path: Path
) -> None:
    """Waiting for another process's build is interruptible, and the waiter leaves the
    holder's lock file alone (the holder removes it)."""
    lock = tmp_path / ".robot.lock"
    lock.touch()
    with open(lock, "a") as holder:
        fcntl.flock(holder, fcntl.LOCK_EX)  # another open file: a conflicting lock
        timer = threading.Timer(0.2, os.kill, (os.getpid(), sigint))
        timer.start()
        with pytest.raises(StoppedError), build_lock(lock, poll=0.01):
            pytest.fail("the lock was taken while another held it")
        timer.join()
        assert lock.exists()


def test_nested_blocks_deliver_to_the_real_handler(usr1: int) -> None:
    """A block inside another (the build inside the build lock): a checkpoint of the inner
    block raises the handler held back by the outer one, not the outer block's hold (which
    only recorded the signal again, so the build ran to its end); a signal held by the outer
    block before the inner began is delivered at the inner block's checkpoint too."""
    with DeferredSignals((usr1,)), DeferredSignals((usr1,)):
        os.kill(os.getpid(), usr1)
        with pytest.raises(StoppedError):
            checkpoint()
    assert signal.getsignal(usr1) is _raise
    with pytest.raises(StoppedError), DeferredSignals((usr1,)):
        os.kill(os.getpid(), usr1)
        with DeferredSignals((usr1,)):
            checkpoint()
            pytest.fail("the outer block's signal was not delivered")
    assert signal.getsignal(usr1) is _raise


def _hold_then_interrupt(sem: threading.Semaphore, started: threading.Event) -> None:
    """Hold ``sem``'s internal lock while a Ctrl-C comes to the main thread, then let go."""
    sem._cond.acquire()  # type: ignore[attr-defined]
    started.set()
    time.sleep(0.1)  # the main thread now waits to enter that lock
    _thread.interrupt_main()
    time.sleep(0.1)
    sem._cond.release()  # type: ignore[attr-defined]


def _contended(wait: Any) -> bool:
    """``wait(sem)`` interrupted as it enters ``sem``'s lock; whether the lock is left held."""
    sem = threading.Semaphore(0)
    started = threading.Event()
    other = threading.Thread(target=_hold_then_interrupt, args=(sem, started))
    other.start()
    started.wait()
    with pytest.raises(KeyboardInterrupt):
        wait(sem)
    other.join()
    return bool(sem._cond._lock.locked())  # type: ignore[attr-defined]


def test_a_ctrl_c_inside_a_semaphores_lock_leaves_it_held() -> None:
    """The hazard wait_held exists for: Python looks for signals after the C acquire inside
    ``Condition.__enter__``, so the Ctrl-C is raised with the lock taken and no ``with`` to
    release it (a worker then waits for it forever)."""
    assert _contended(lambda sem: sem.acquire(timeout=5.0))


def test_wait_held_raises_the_ctrl_c_with_no_lock_held() -> None:
    assert not _contended(lambda sem: wait_held(lambda t: sem.acquire(timeout=t)))


def test_result_held_returns_the_result_and_raises_a_held_ctrl_c() -> None:
    with ThreadPoolExecutor(1) as pool:
        assert result_held(pool.submit(lambda: 7), poll=0.01) == 7
        slow = pool.submit(time.sleep, 0.3)
        threading.Timer(0.05, _thread.interrupt_main).start()
        with pytest.raises(KeyboardInterrupt):
            result_held(slow, poll=0.01)
        assert slow.running() or slow.done()  # (the worker was left alone)
