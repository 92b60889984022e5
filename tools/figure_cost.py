"""What a command's figures cost: the CPU time of its figure functions against the whole
command's, in one run (docs/api.md, "The figures the commands draw").

Runs ``amsfe ARGS...`` in this process (``amsfe_sym.apps.cli.main``) with the figure
functions (``plot_comparison``, ``plot_run``, ``plot_log``) timed by ``time.process_time``,
and prints one line: the process's CPU time (all of it, the interpreter's start-up too) and
its wall time from before the package is imported, and the figures' CPU and wall time with
their share of them.  CPU time is the number to compare on a loaded machine (the wall
time of the same command moves by 2x with the load); the share is within one run.

It also prints the CPU time of matplotlib's import (the figures' first call of
``plots.style.import_matplotlib``), and with ``--profile`` first in ARGS, cProfile's 30
costliest functions (cumulative) and 15 (own time) of the figures alone: where their time
goes (texts, legends, ticks; ``ft2font._render_glyph``'s calls are the glyphs drawn).

With ``--floor`` first in ARGS, the command runs with ``--no-plots`` and then, in the same
process, matplotlib is imported and one panel with one line drawn and written as the
commands write theirs (``plots.style.figure`` / ``save``): the least any figure adds to
that command, and the share of it that would be.

Usage::

    .venv/bin/python tools/figure_cost.py simulate panda-control --no-progress --out S
    .venv/bin/python tools/figure_cost.py estimate LOG --out E
    .venv/bin/python tools/figure_cost.py --profile simulate --no-progress --out P
    .venv/bin/python tools/figure_cost.py --floor simulate --no-progress --out F
"""

from __future__ import annotations

import cProfile
import importlib
import pstats
import resource
import sys
import time
from collections.abc import Callable
from typing import Any

WALL0 = time.perf_counter()

FIGURES = (
    ("amsfe_sym.apps.plots.paper", "plot_comparison"),
    ("amsfe_sym.apps.plots.run", "plot_run"),
    ("amsfe_sym.apps.plots.log", "plot_log"),
)


def _timed(
    draw: Callable[..., Any], spent: dict[str, float], profile: cProfile.Profile | None = None
) -> Callable[..., Any]:
    def run(*args: Any, **kwargs: Any) -> Any:
        cpu, wall = time.process_time(), time.perf_counter()
        if profile is not None:
            profile.enable()
        try:
            return draw(*args, **kwargs)
        finally:
            if profile is not None:
                profile.disable()
            spent["cpu"] += time.process_time() - cpu
            spent["wall"] += time.perf_counter() - wall

    return run


def main(argv: list[str]) -> int:
    from amsfe_sym.apps.cli import main as amsfe
    from amsfe_sym.apps.plots import style

    if argv[:1] == ["--floor"]:
        return floor(argv[1:])
    profile = cProfile.Profile() if argv[:1] == ["--profile"] else None
    argv = argv[1:] if profile is not None else argv
    spent = {"cpu": 0.0, "wall": 0.0}
    for module, name in FIGURES:  # the commands import them by name when they draw
        mod = importlib.import_module(module)
        setattr(mod, name, _timed(getattr(mod, name), spent, profile))
    imported = {"cpu": 0.0, "wall": 0.0}  # the first call imports; later ones find it
    style.import_matplotlib = _timed(style.import_matplotlib, imported)
    code = amsfe(argv)
    use = resource.getrusage(resource.RUSAGE_SELF)
    cpu = use.ru_utime + use.ru_stime
    wall = time.perf_counter() - WALL0
    print(
        f"amsfe {' '.join(argv)}: CPU {cpu:.2f} s, wall {wall:.2f} s; figures CPU "
        f"{spent['cpu']:.2f} s ({100 * spent['cpu'] / cpu:.0f} %), wall {spent['wall']:.2f} s "
        f"({100 * spent['wall'] / wall:.0f} %); of them matplotlib's import CPU "
        f"{imported['cpu']:.2f} s"
    )
    if profile is not None:
        stats = pstats.Stats(profile)
        stats.sort_stats("cumulative").print_stats(30)
        stats.sort_stats("tottime").print_stats(15)
    return code


def floor(argv: list[str]) -> int:
    """``amsfe ARGS --no-plots``, then one panel drawn and written in this process: prints
    the command's CPU time and the panel's (matplotlib's import included) [s]."""
    import tempfile
    from pathlib import Path

    from amsfe_sym.apps.cli import main as amsfe
    from amsfe_sym.apps.plots import style

    code = amsfe([*argv, "--no-plots"])
    cpu = time.process_time()
    style.import_matplotlib()
    fig = style.figure((4.0, 3.0))
    fig.add_subplot().plot([0.0, 1.0], [0.0, 1.0])
    with tempfile.TemporaryDirectory() as tmp:
        style.save(fig, Path(tmp) / "one.png")
    panel = time.process_time() - cpu
    whole = time.process_time()
    print(
        f"amsfe {' '.join(argv)} --no-plots: CPU {whole - panel:.2f} s; one panel, "
        f"matplotlib's import included: CPU {panel:.2f} s ({100 * panel / whole:.0f} % of both)"
    )
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
