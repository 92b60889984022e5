"""amsfe_sym: code-generated models, multirate sensor fusion and DTSMC for elastic-joint arms.

The public API (docs/api.md; :mod:`amsfe_sym.api`)::

    import amsfe_sym as am
    robot = am.generate("paper_2link")                  # the compiled model library
    sc = am.load_scenario("paper-sim", {"duration": 2.0})
    sim = am.simulate(sc)                               # arrays: t, x_true, x_hat, P_diag, u, nis
    log = am.read_log("run/bag", "paper_2link")         # or am.LogArrays.from_arrays(t, qm, ...)
    est = am.Estimator.for_log("paper_2link").run(log)  # amsfe estimate's numbers

The pipeline flows one way; the package's folders are its stages (docs/explanation/architecture.md):
``core`` (foundation: TOML, camera frames, provenance) -> ``load`` (robot.toml + URDF ->
Pinocchio model) -> ``scenario`` (a run's settings) -> ``symbolic`` (CasADi SX) -> ``codegen``
(C + shared library + manifest in ``generated/<name>/``) -> ``runtime`` (load and call the
library; the C runtime) -> ``estimation``, ``control``, ``sim`` (the closed loop) -> ``apps``
(the command line, check, bench, study, sweep, figures), and ``api`` over them.  ``errors`` is
the one exception hierarchy.  Importing the package has no side effects and imports neither
CasADi nor Pinocchio: every public name is resolved on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from amsfe_sym.errors import AmsfeError

if TYPE_CHECKING:
    from amsfe_sym.api import (
        EstimateArrays,
        Estimator,
        LogArrays,
        Model,
        Robot,
        SimResult,
        StepResult,
        generate,
        load_scenario,
        read_log,
        simulate,
    )
    from amsfe_sym.codegen import library_for, load_library

__version__ = "0.1.0"

__all__ = [
    "AmsfeError",
    "EstimateArrays",
    "Estimator",
    "LogArrays",
    "Model",
    "Robot",
    "SimResult",
    "StepResult",
    "__version__",
    "generate",
    "library_for",
    "load_library",
    "load_scenario",
    "read_log",
    "simulate",
]
#: The low-level library loaders (:mod:`amsfe_sym.codegen`), imported on first use.
_CODEGEN = ("library_for", "load_library")
#: The public API (:mod:`amsfe_sym.api`), imported on first use.
_API = tuple(n for n in __all__ if n not in ("AmsfeError", "__version__", *_CODEGEN))


def __getattr__(name: str) -> Any:
    if name in _API:
        from amsfe_sym import api

        return getattr(api, name)
    if name in _CODEGEN:
        from amsfe_sym import codegen

        return getattr(codegen, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
