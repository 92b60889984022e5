"""``core.interrupts``: a signal is held inside a ``DeferredSignals`` block and raised by
the handler that was there before, at a checkpoint or when the block ends; the same signal
twice is raised at once; outside a block nothing changes."""

from __future__ import annotations

import os
import signal

import pytest

from amsfe_sym.core.interrupts import DeferredSignals, checkpoint


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
