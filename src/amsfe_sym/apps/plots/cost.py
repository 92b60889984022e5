"""What a command's figures cost, and the hint to skip them (``--no-plots``) when they take
more than a quarter of the command's time."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["SHARE", "FigureClock", "hint_line"]

#: The share of a command's time past which it suggests ``--no-plots``.
SHARE = 0.25

F = TypeVar("F", bound=Callable[..., Any])


class FigureClock:
    """Wall time [s] spent drawing figures, and since the command started.

    Args:
        started_s: How long the command had already run when the clock was made (e.g. the
            process's age, :func:`~amsfe_sym.apps.phases.command_startup_s`) [s]; None: 0.
    """

    def __init__(self, started_s: float | None = None) -> None:
        self.start = time.perf_counter() - (started_s or 0.0)
        self.seconds = 0.0

    def timed(self, draw: F) -> F:
        """``draw`` with its wall time added to :attr:`seconds`."""

        def run(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return draw(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t

        return run  # type: ignore[return-value]

    def hint(self) -> str | None:
        """One line when the figures took more than :data:`SHARE` of the command so far
        ("figures: 2.1 of 4.0 s (52 %); --no-plots skips them"), else None."""
        return hint_line(self.seconds, time.perf_counter() - self.start)


def hint_line(figures_s: float, total_s: float) -> str | None:
    """ "figures: 2.1 of 4.0 s (52 %); --no-plots skips them" when the figures took more
    than :data:`SHARE` of a command's ``total_s`` [s], else None."""
    if total_s <= 0 or figures_s <= SHARE * total_s:
        return None
    share = 100 * figures_s / total_s
    return f"figures: {figures_s:.1f} of {total_s:.1f} s ({share:.0f} %); --no-plots skips them"
