"""Controllers, selectable by name.  Until the DTSMC issue lands, ``truth-ct`` (a cascaded
computed-torque law on the true state and true model) drives the plant."""

from amsfe_sym.control.base import CONTROLLERS, Controller, make_controller
from amsfe_sym.control.truth import TruthComputedTorque

__all__ = ["CONTROLLERS", "Controller", "TruthComputedTorque", "make_controller"]
