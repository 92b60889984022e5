"""The C ABI of ``runtime/c/amsfe_loop.h`` in ctypes: the parameter, output, record and
state structs (field for field as in the header) and the functions' signatures.

Kept apart from :mod:`amsfe_sym.runtime.compiled_loop` (the objects that use them) so the
struct lists can be read beside the header.
"""

from __future__ import annotations

import ctypes
from typing import Any

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.runtime.cheader import c_struct, header_fields

__all__ = [
    "CONTROLLER_CODES",
    "COUNTERS",
    "CtrlOut",
    "CtrlParams",
    "SimParams",
    "SimRecords",
    "SimulationState",
    "bind_loop",
]

_P = ctypes.c_void_p

#: ``enum amsfe_controller`` of amsfe_loop.h, by controller name.
CONTROLLER_CODES = {
    "amsfe": 0,
    "dtsmc": 1,
    "dtsmc-ekf": 2,
    "truth": 3,
    "amsfe-paper": 4,
    "dtsmc-paper": 5,
    "truth-ct": 6,
}


#: The parameter block, outputs and records of ``amsfe_loop.h`` (its own fields).
CtrlParams = c_struct("CtrlParams", "amsfe_loop.h", "amsfe_ctrl_params")
CtrlOut = c_struct("CtrlOut", "amsfe_loop.h", "amsfe_ctrl_out")
SimParams = c_struct("SimParams", "amsfe_loop.h", "amsfe_sim_params")
SimRecords = c_struct("SimRecords", "amsfe_loop.h", "amsfe_sim_records")

COUNTERS = (
    "frames_applied",
    "frames_rejected",
    "encoder_rejected",
    "refused_nan",
    "refused_too_late",
    "refused_gated",
    "refused_indefinite",
    "refused_no_convergence",
    "refused_unscheduled",
    "refused_other",
    "frames_exposed",
    "frames_delivered",
    "frames_dropped",
    "frames_out_of_image",
    "frames_out_of_image_true",
    "frames_out_of_order",
    "frames_recorded",
)


class SimulationState(ctypes.Structure):
    """``amsfe_sim_state``: the next tick, whether the loop diverged, its counters."""

    _fields_ = header_fields("amsfe_loop.h", "amsfe_sim_state")

    def counters(self) -> dict[str, int]:
        """The counters by name (those of ``summary.json``)."""
        return {k: int(getattr(self, k)) for k in COUNTERS}


def bind_loop(cdll: ctypes.CDLL) -> dict[str, Any]:
    spec: dict[str, tuple[Any, list[Any]]] = {
        "amsfe_ctrl_memory_size": (ctypes.c_size_t, [_P]),
        "amsfe_ctrl_init": (ctypes.c_int, [_P, _P, _P, ctypes.c_size_t]),
        "amsfe_ctrl_reset": (None, [_P]),
        "amsfe_ctrl_observe": (None, [_P, _P]),
        "amsfe_ctrl_observe_nis": (None, [_P, ctypes.c_double]),
        "amsfe_ctrl_torque": (ctypes.c_int, [_P, ctypes.c_long, _P, _P, _P, _P, _P, _P]),
        "amsfe_sim_memory_size": (ctypes.c_size_t, [_P]),
        "amsfe_sim_init": (ctypes.c_int, [_P, _P, _P, _P, _P, ctypes.c_size_t]),
        "amsfe_sim_run": (ctypes.c_int, [_P, ctypes.c_long, _P]),
        "amsfe_sim_get_state": (None, [_P, _P]),
        "amsfe_status_string": (ctypes.c_char_p, [ctypes.c_int]),
    }
    out = {}
    for name, (restype, argtypes) in spec.items():
        try:
            fn = cdll[name]
        except AttributeError as exc:
            raise ConfigError(
                describe(
                    "the compiled closed loop",
                    f"{name} in the library",
                    "a library without amsfe_loop.c (a partial or older build)",
                    "regenerate the full library: amsfe generate ROBOT --force",
                )
            ) from exc
        fn.restype = restype
        fn.argtypes = argtypes
        out[name] = fn
    return out
