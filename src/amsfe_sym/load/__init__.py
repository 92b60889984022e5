"""Stage 1 of the pipeline, load: URDF + robot spec -> a validated Pinocchio-based
:class:`Robot` (see :mod:`amsfe_sym.load.robot` for what is refused, and why).

Modules: ``robot`` (:func:`load_robot`), ``types`` (the :class:`Robot` value), ``urdf``
(validation before Pinocchio), ``joints``, ``parameters`` (actuators, theta bindings),
``camera`` (camera defaults), ``checks`` (whole-model checks).
"""

from amsfe_sym.load.robot import load_robot
from amsfe_sym.load.types import CameraModel, JointInfo, Robot, ThetaBinding

__all__ = ["CameraModel", "JointInfo", "Robot", "ThetaBinding", "load_robot"]
