"""Stage 1 of the pipeline, load: robot.toml + URDF -> a validated Pinocchio-based
:class:`Robot` (see :mod:`amsfe_sym.load.robot` for what is refused, and why).

Modules: ``spec`` (robot.toml -> :class:`~amsfe_sym.load.spec.RobotSpec`, no Pinocchio;
the shipped robots' folder), ``robot`` (:func:`load_robot`), ``types`` (the :class:`Robot`
value), ``urdf`` (validation before Pinocchio), ``joints``, ``parameters`` (actuators, theta
bindings), ``camera`` (camera defaults), ``checks`` (whole-model checks).

May import: errors, core.  Pinocchio and yourdfpy are imported only by the modules that
build the model, so ``amsfe_sym.load.spec`` (read by the scenario and the runtime side) stays
light: the names below are resolved on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from amsfe_sym.load.robot import load_robot
    from amsfe_sym.load.types import CameraModel, JointInfo, Robot, ThetaBinding

__all__ = ["CameraModel", "JointInfo", "Robot", "ThetaBinding", "load_robot"]


def __getattr__(name: str) -> Any:
    if name == "load_robot":
        from amsfe_sym.load.robot import load_robot

        return load_robot
    if name in ("CameraModel", "JointInfo", "Robot", "ThetaBinding"):
        from amsfe_sym.load import types

        return getattr(types, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
