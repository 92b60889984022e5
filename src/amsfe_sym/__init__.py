"""amsfe_sym: code-generated models, multirate sensor fusion and DTSMC for elastic-joint arms.

The pipeline flows one way; the package's folders are its stages (docs/explanation/architecture.md):
``core`` (foundation: TOML, camera frames, provenance) -> ``load`` (robot.toml + URDF ->
Pinocchio model) -> ``scenario`` (a run's settings) -> ``symbolic`` (CasADi SX) -> ``codegen``
(C + shared library + manifest in ``generated/<name>/``) -> ``runtime`` (load and call the
library; the C runtime) -> ``estimation``, ``control``, ``sim`` (the closed loop) -> ``apps``
(the command line, check, bench, study, sweep, figures).  ``errors`` is the one exception
hierarchy.  Importing the package has no side effects and imports neither CasADi nor
Pinocchio: ``generate``, ``load_library`` and ``library_for`` are resolved on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from amsfe_sym.errors import AmsfeError

if TYPE_CHECKING:
    from amsfe_sym.codegen import generate, library_for, load_library

__version__ = "0.1.0"

__all__ = ["AmsfeError", "__version__", "generate", "library_for", "load_library"]

_LAZY = ("generate", "library_for", "load_library")


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        from amsfe_sym import codegen

        return getattr(codegen, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
