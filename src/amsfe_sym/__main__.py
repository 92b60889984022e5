"""``python -m amsfe_sym`` and the ``amsfe`` console script: the command line.

Loading the command line's modules takes seconds on a busy machine; a Ctrl-C or SIGTERM in
that time is one line and exit 130 / 143 too, as in the command (whose handler replaces the
one installed here). A stdout closed under the command (``amsfe estimate LOG | head``) is
one line on stderr and exit 141, not a traceback.  A fatal signal in the process (a crash in
a compiled extension: rclpy, the middleware) prints the Python stack of every thread on
stderr (:mod:`faulthandler`) before the process dies as it would have."""

import contextlib
import faulthandler
import os
import signal
import sys


class _Stopped(KeyboardInterrupt):
    """SIGTERM before the command line has installed its own handler."""


def _stopped(signum: int, frame: object) -> None:
    raise _Stopped


def run() -> int:
    """Install the start-up handlers, load the command line, run it; the exit status."""
    with contextlib.suppress(AttributeError, ValueError, OSError):  # stderr not a file
        faulthandler.enable()
    signal.signal(signal.SIGTERM, _stopped)
    try:
        from amsfe_sym.apps.cli import BROKEN_PIPE, main
    except KeyboardInterrupt as exc:
        how, code = ("SIGTERM", 143) if isinstance(exc, _Stopped) else ("Ctrl-C", 130)
        print(
            f"interrupted: amsfe stopped by {how} while starting; nothing was written",
            file=sys.stderr,
        )
        return code
    try:
        code = main()
        sys.stdout.flush()  # a pipe's buffer is written here: a closed reader fails here
    except BrokenPipeError:
        print("stopped: amsfe's output was closed (broken pipe)", file=sys.stderr)
        code = BROKEN_PIPE
    if code == BROKEN_PIPE:  # nothing more to this stdout, and no error at exit's flush
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return code


if __name__ == "__main__":
    sys.exit(run())
