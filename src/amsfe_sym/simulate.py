"""The closed-loop simulation, under its historical name.

The code lives in :mod:`amsfe_sym.sim`: :mod:`~amsfe_sym.sim.builders` (plant start,
sensors, estimator, controller), :mod:`~amsfe_sym.sim.loop` (:func:`run`) and
:mod:`~amsfe_sym.sim.record` (run folder).  ``library_for`` moved to
:mod:`amsfe_sym.codegen` (it generates); it is still importable from here, lazily, so that
``import amsfe_sym.simulate`` needs no CasADi.
"""

from __future__ import annotations

from typing import Any

from amsfe_sym.sim.loop import RunResult, run
from amsfe_sym.sim.record import summarize, write_run

__all__ = ["RunResult", "run", "summarize", "write_run"]


def __getattr__(name: str) -> Any:
    if name == "library_for":
        from amsfe_sym.codegen import library_for

        return library_for
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
