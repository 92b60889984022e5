"""Runtime: load generated libraries and call them with little overhead; no symbols here."""

from amsfe_sym.runtime.library import CompiledFunction, ModelLibrary

__all__ = ["CompiledFunction", "ModelLibrary"]
