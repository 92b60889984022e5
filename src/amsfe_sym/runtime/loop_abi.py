"""The C ABI of ``runtime/c/amsfe_loop.h`` in ctypes: the parameter, output, record and
state structs (field for field as in the header) and the functions' signatures.

Kept apart from :mod:`amsfe_sym.runtime.compiled_loop` (the objects that use them) so the
struct lists can be read beside the header.
"""

from __future__ import annotations

import ctypes
from typing import Any

from amsfe_sym.errors import ConfigError, describe

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


class CtrlParams(ctypes.Structure):
    _fields_ = [
        ("controller", ctypes.c_int),
        ("T", ctypes.c_double),
        *((k, _P) for k in ("h", "lam", "Lt", "eps", "phi")),
        ("p", ctypes.c_double),
        *((k, _P) for k in ("wm", "tau_max", "wf", "vmax")),
        ("qmd_next_hold", ctypes.c_int),
        ("state_true", ctypes.c_int),
        ("link_bandwidth", ctypes.c_double),
        ("motor_bandwidth", ctypes.c_double),
        *((k, _P) for k in ("u_max", "Mm", "Fm", "Ks", "ks_theta", "theta_initial")),
    ]


class CtrlOut(ctypes.Structure):
    _fields_ = [("s", _P), ("bound", _P), ("tau_d", _P), ("saturated", ctypes.c_int)]


class SimParams(ctypes.Structure):
    _fields_ = [
        ("K", ctypes.c_long),
        *((k, _P) for k in ("x_plant0", "theta_true", "ref", "enc_noise")),
        ("enc_resolution", ctypes.c_double),
        ("tau_d", _P),
        *((k, ctypes.c_int) for k in ("cam_period", "cam_phase", "cam_delay")),
        *((k, ctypes.c_double) for k in ("cam_width", "cam_height", "pixel_std")),
        ("round_to_pixel", ctypes.c_int),
        ("drop_probability", ctypes.c_double),
        ("n_exposures", ctypes.c_long),
        *((k, _P) for k in ("cam_noise", "cam_uniform", "cam_jitter")),
        ("max_in_flight", ctypes.c_int),
        ("diverged_error", ctypes.c_double),
    ]


class SimRecords(ctypes.Structure):
    _fields_ = [
        *((k, _P) for k in ("x_true", "x_hat", "P_diag", "nees", "u", "z_enc", "s", "bound")),
        ("saturated", _P),
        ("frames", _P),
        ("frames_capacity", ctypes.c_long),
    ]


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

    _fields_ = [
        ("k", ctypes.c_long),
        ("ticks_done", ctypes.c_long),
        ("diverged", ctypes.c_int),
        ("status", ctypes.c_int),
        *((k, ctypes.c_long) for k in COUNTERS),
        ("plant_nonfinite", ctypes.c_int),
    ]

    def counters(self) -> dict[str, int]:
        """The counters by name (those of ``summary.json``)."""
        return {k: int(getattr(self, k)) for k in COUNTERS}


def bind_loop(cdll: ctypes.CDLL) -> dict[str, Any]:
    spec: dict[str, tuple[Any, list[Any]]] = {
        "amsfe_ctrl_memory_size": (ctypes.c_size_t, [_P]),
        "amsfe_ctrl_init": (ctypes.c_int, [_P, _P, _P, ctypes.c_size_t]),
        "amsfe_ctrl_reset": (None, [_P]),
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
