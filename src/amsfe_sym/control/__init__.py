"""Controllers, selectable by name (``amsfe simulate --controller NAME``).

``amsfe``, ``dtsmc``, ``amsfe-paper``, ``dtsmc-paper`` and ``truth`` are the paper's discrete
terminal sliding mode laws on generated code (:mod:`amsfe_sym.control.sliding`; the laws as
printed in :mod:`amsfe_sym.control.printed`; derived in docs/explanation/control.md); ``truth-ct``
is a
cascaded computed-torque law on the true state.

May import: errors, runtime (the library's laws and manifest), signals.trajectory.
"""

from amsfe_sym.control.base import (
    CONTROLLERS,
    Controller,
    LawInputs,
    check_controller_name,
    make_controller,
)
from amsfe_sym.control.printed import AmsfePaper, DtsmcPaper
from amsfe_sym.control.sliding import Amsfe, Dtsmc, Truth
from amsfe_sym.control.truth import TruthComputedTorque

__all__ = [
    "CONTROLLERS",
    "Amsfe",
    "AmsfePaper",
    "Controller",
    "Dtsmc",
    "DtsmcPaper",
    "LawInputs",
    "Truth",
    "TruthComputedTorque",
    "check_controller_name",
    "make_controller",
]
