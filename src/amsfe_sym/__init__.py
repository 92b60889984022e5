"""amsfe_sym: code-generated models, multirate sensor fusion and DTSMC for elastic-joint arms.

The pipeline flows one way (see docs/architecture.md):
``load`` (URDF + spec -> Pinocchio model) -> ``symbolic`` (CasADi SX) -> ``codegen``
(C + shared library + manifest in ``generated/<name>/``) -> ``runtime`` (load and call the
library) -> ``estimation``, ``control``, ``sim`` (the closed loop) -> the apps (``cli``,
``check``, ``bench``, ``study``, ``plots``).  Importing the package has no side effects.
"""

from amsfe_sym.errors import AmsfeError

__version__ = "0.1.0"

__all__ = ["AmsfeError", "__version__"]
