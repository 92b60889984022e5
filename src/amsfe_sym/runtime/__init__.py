"""Runtime: load generated libraries and call them with little overhead; no symbols here.

Imports numpy and ctypes only: never CasADi, Pinocchio or the code generator
(``tests/test_layers.py`` checks it).  Building a library is :mod:`amsfe_sym.codegen`'s job.

May import: errors, and inside the compiled estimators and loop, estimation (they
implement its Estimator interface) and core.camera_frame.
"""

from amsfe_sym.runtime.library import CompiledFunction, ModelLibrary
from amsfe_sym.runtime.manifest import Manifest, read_manifest

__all__ = ["CompiledFunction", "Manifest", "ModelLibrary", "read_manifest"]
