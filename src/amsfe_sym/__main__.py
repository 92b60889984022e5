"""``python -m amsfe_sym`` and the ``amsfe`` console script: the command line.

Loading the command line's modules takes seconds on a busy machine; a Ctrl-C or SIGTERM in
that time is one line and exit 130 / 143 too, as in the command (whose handler replaces the
one installed here)."""

import signal
import sys


class _Stopped(KeyboardInterrupt):
    """SIGTERM before the command line has installed its own handler."""


def _stopped(signum: int, frame: object) -> None:
    raise _Stopped


def run() -> int:
    """Install the start-up handlers, load the command line, run it; the exit status."""
    signal.signal(signal.SIGTERM, _stopped)
    try:
        from amsfe_sym.apps.cli import main
    except KeyboardInterrupt as exc:
        how, code = ("SIGTERM", 143) if isinstance(exc, _Stopped) else ("Ctrl-C", 130)
        print(
            f"interrupted: amsfe stopped by {how} while starting; nothing was written",
            file=sys.stderr,
        )
        return code
    return main()


if __name__ == "__main__":
    sys.exit(run())
