"""The compiled controllers and closed loop (``runtime/c/amsfe_loop.{c,h}``) through ctypes.

Two objects over one generated library:

- :class:`CompiledController`: ``amsfe_ctrl``, a controller whose law, memory and actuator
  limit run in C (``torque`` per tick, or inside :class:`CompiledSimulation`);
- :class:`CompiledSimulation`: ``amsfe_sim``, the whole closed loop (plant substeps,
  encoders, camera, disturbance, estimator, controller) for many ticks per call, recording
  into numpy arrays.  The random numbers come in as arrays (:class:`SimulationInputs`) so a
  seed gives the same run as the Python loop.

This layer knows arrays and the C structs only; :mod:`amsfe_sym.sim.compiled` turns a
scenario and its Python parts into these inputs.
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, describe, unknown_name
from amsfe_sym.runtime.compiled_estimator import (
    CompiledEstimator,
    estimator_log_lines,
    log_numbers,
)
from amsfe_sym.runtime.loop_abi import (
    CONTROLLER_CODES,
    CtrlOut,
    CtrlParams,
    SimParams,
    SimRecords,
    SimulationState,
    bind_loop,
)

__all__ = [
    "CONTROLLER_CODES",
    "CompiledController",
    "CompiledSimulation",
    "ControllerParams",
    "SimulationInputs",
    "SimulationRecords",
    "SimulationState",
    "write_loop_log",
]


def _f64(values: Any, size: int | None = None) -> FloatArray:
    arr = np.ascontiguousarray(np.asarray(values, dtype=np.float64).ravel())
    if size is not None and arr.size != size:
        raise ConfigError(describe("compiled loop input", f"{size} values", f"{arr.size}", ""))
    return arr


@dataclass
class ControllerParams:
    """The parameter block of one controller (``amsfe_ctrl_params``), as numpy arrays.

    Per-joint gains have ``n`` entries; ``p`` is the terminal power; ``u_max`` the actuator
    limit [N m] (``inf``: none); ``Mm``, ``Fm``, ``Ks`` the actuator data of the spec,
    ``ks_theta[j]`` the index of theta holding joint j's stiffness (-1: none).
    """

    name: str
    T: float
    gains: dict[str, FloatArray]
    p: float
    u_max: FloatArray
    Mm: FloatArray
    Fm: FloatArray
    Ks: FloatArray
    ks_theta: NDArray[np.int32]
    theta_initial: FloatArray
    qmd_next_hold: bool = False
    state_true: bool = False
    link_bandwidth: float = 0.0
    motor_bandwidth: float = 0.0
    startup_converged: bool = False
    ready_q_std: float = float("inf")
    ready_qd_std: float = float("inf")
    blend_accel: float = float("inf")
    blend_rate: float = float("inf")
    ready_nis: float = float("inf")
    ready_nis_window: float = 50.0
    hold_motor: bool = False
    blend_wf: float = float("inf")
    headroom_tau: float = float("inf")
    blend_lead: float = 0.0
    _keep: list[Any] = field(default_factory=list, repr=False)

    def struct(self) -> ctypes.Structure:
        """The C struct (its arrays are kept alive by this object)."""
        if self.name not in CONTROLLER_CODES:
            raise unknown_name(
                "compiled controller name",
                self.name,
                sorted(CONTROLLER_CODES),
                "use a controller the C runtime has, or --runtime python",
            )
        n = self.u_max.size
        arrays: dict[str, Any] = {}
        for key in ("h", "lam", "Lt", "eps", "phi", "wm", "tau_max", "wf", "vmax"):
            arrays[key] = _f64(self.gains[key], n) if key in self.gains else None
        for key in ("u_max", "Mm", "Fm", "Ks"):
            arrays[key] = _f64(getattr(self, key), n)
        arrays["theta_initial"] = _f64(self.theta_initial)
        arrays["ks_theta"] = np.ascontiguousarray(self.ks_theta, dtype=np.int32)
        self._keep = list(arrays.values())

        def ptr(key: str) -> int | None:
            a = arrays[key]
            return None if a is None else int(a.ctypes.data)

        return CtrlParams(
            CONTROLLER_CODES[self.name],
            self.T,
            *(ptr(k) for k in ("h", "lam", "Lt", "eps", "phi")),
            self.p,
            *(ptr(k) for k in ("wm", "tau_max", "wf", "vmax")),
            int(self.qmd_next_hold),
            int(self.state_true),
            self.link_bandwidth,
            self.motor_bandwidth,
            *(ptr(k) for k in ("u_max", "Mm", "Fm", "Ks", "ks_theta", "theta_initial")),
            int(self.startup_converged),
            float(self.ready_q_std),
            float(self.ready_qd_std),
            float(self.blend_accel),
            float(self.blend_rate),
            float(self.ready_nis),
            float(self.ready_nis_window),
            int(self.hold_motor),
            float(self.blend_wf),
            float(self.headroom_tau),
            float(self.blend_lead),
        )


class CompiledController:
    """A controller running in the library's C runtime (``amsfe_ctrl``).

    Args:
        library_path: The generated library (a full build: it holds amsfe_loop.c).
        params: Its parameter block.
        n: Joints of the library's robot.
    """

    def __init__(self, library_path: str, params: ControllerParams, n: int) -> None:
        self._c = bind_loop(ctypes.CDLL(library_path))
        self.params = params
        self.n = n
        self._struct = params.struct()
        size = int(self._c["amsfe_ctrl_memory_size"](ctypes.byref(self._struct)))
        if size == 0:
            raise ConfigError(
                describe(
                    f"compiled controller {params.name!r}",
                    "parameters the C runtime accepts",
                    "a refused parameter block",
                    "check the gains (0 < p <= 1, T > 0) and the theta indices",
                )
            )
        self._mem = np.zeros(size // 8 + 4)
        handle = ctypes.c_void_p()
        status = self._c["amsfe_ctrl_init"](
            ctypes.byref(handle), ctypes.byref(self._struct), self._mem.ctypes.data, size
        )
        if status != 0:
            raise ConfigError(describe("amsfe_ctrl_init", "AMSFE_OK", f"status {status}", ""))
        self.handle = handle
        self._u = np.zeros(n)
        self.s = np.full(n, np.nan)
        self.bound = np.full(n, np.nan)
        self.tau_d = np.zeros(n)
        self.saturated = False
        self._out = CtrlOut(self.s.ctypes.data, self.bound.ctypes.data, self.tau_d.ctypes.data, 0)

    def reset(self) -> None:
        """Forget the memory between ticks (as a new controller)."""
        self._c["amsfe_ctrl_reset"](self.handle)

    def torque(
        self,
        k: int,
        ref: FloatArray,
        x_hat: FloatArray | None,
        z: FloatArray | None,
        x_true: FloatArray | None = None,
        P: FloatArray | None = None,
        encoder_nis: float | None = None,
    ) -> FloatArray:
        """u(k) [N m] after the actuator limit (``s``, ``bound``, ``saturated`` updated);
        ``P`` (N x N, the estimate's covariance) and ``encoder_nis`` (this tick's encoder
        NIS) for the start-up's test (None: converged; no NIS: consistency not tested)."""
        if encoder_nis is not None:
            self._c["amsfe_ctrl_observe_nis"](self.handle, float(encoder_nis))
        if P is not None:
            Pc = np.ascontiguousarray(P, dtype=np.float64)
            self._c["amsfe_ctrl_observe"](self.handle, Pc.ctypes.data)
        keep = [None if a is None else _f64(a) for a in (ref, x_hat, z, x_true)]
        ptrs = [None if a is None else a.ctypes.data for a in keep]
        status = self._c["amsfe_ctrl_torque"](
            self.handle, k, *ptrs, self._u.ctypes.data, ctypes.byref(self._out)
        )
        if status != 0:
            raise ConfigError(
                describe(
                    f"compiled controller {self.params.name!r} at tick {k}",
                    "AMSFE_OK",
                    self._c["amsfe_status_string"](status).decode(),
                    "pass the inputs the law reads (x_true for the oracles, z for dtsmc)",
                )
            )
        self.saturated = bool(self._out.saturated)
        return self._u.copy()


@dataclass
class SimulationInputs:
    """Everything random or precomputed a compiled run reads (``amsfe_sim_params``).

    Arrays are row-major, one row per tick ``k = 0 .. K-1`` unless said otherwise.

    Attributes:
        x_plant0: True initial [q, qd, qm, qmd], (4n,).
        theta_true: True theta, (p,).
        ref: Reference [q_d, qd_d, qdd_d, jerk_d, snap_d] per tick, (K, 5n).
        enc_noise: Encoder noise per tick, already scaled [rad, rad/s], (K, 2n); row 0 made
            the first sample.
        enc_resolution: Angle of one count [rad] (0: not quantized).
        tau_d: Disturbance torques [link, motor] per tick [N m], (K, 2n).
        camera: period, phase, delay [steps], width, height [px], pixel_std [px],
            round_to_pixel, drop_probability.
        cam_noise: Standard normals per exposure, (E, 2).
        cam_uniform: Uniforms per exposure (a frame is lost when below drop_probability), (E,).
        cam_jitter: Extra delivery delay per exposure [steps], (E,).
        diverged_error: Stop when a link's tracking error exceeds this [rad].
    """

    x_plant0: FloatArray
    theta_true: FloatArray
    ref: FloatArray
    enc_noise: FloatArray
    enc_resolution: float
    tau_d: FloatArray
    camera: dict[str, Any]
    cam_noise: FloatArray
    cam_uniform: FloatArray
    cam_jitter: NDArray[np.int32]
    diverged_error: float


@dataclass
class SimulationRecords:
    """What a compiled run recorded (rows ``0 .. ticks``; see ``sim.result.RunResult``)."""

    x_true: FloatArray
    x_hat: FloatArray
    P_diag: FloatArray
    nees: FloatArray
    u: FloatArray
    z_enc: FloatArray
    s: FloatArray
    bound: FloatArray
    saturated: NDArray[np.bool_]
    frames: FloatArray
    state: SimulationState


class CompiledSimulation:
    """The closed loop in C (``amsfe_sim``) over a compiled estimator and controller.

    Args:
        library_path: The generated library.
        estimator_handle: An initialised ``amsfe_est *`` (a compiled estimator's handle).
        controller: A :class:`CompiledController` of the same library, freshly built.
        inputs: The run's inputs.
        N: State size of the library's model.
    """

    def __init__(
        self,
        library_path: str,
        estimator_handle: ctypes.c_void_p,
        controller: CompiledController,
        inputs: SimulationInputs,
        N: int,
    ) -> None:
        self._c = bind_loop(ctypes.CDLL(library_path))
        n = controller.n
        K = inputs.ref.shape[0]
        self.K, self.n, self.N = K, n, N
        cam = inputs.camera
        E = inputs.cam_uniform.size
        jitter = np.ascontiguousarray(inputs.cam_jitter, dtype=np.int32)
        self._arrays: list[NDArray[Any]] = [
            _f64(inputs.x_plant0, 4 * n),
            _f64(inputs.theta_true),
            _f64(inputs.ref, K * 5 * n),
            _f64(inputs.enc_noise, K * 2 * n),
            _f64(inputs.tau_d, K * 2 * n),
            _f64(inputs.cam_noise, 2 * E),
            _f64(inputs.cam_uniform, E),
            jitter,
        ]
        a = [arr.ctypes.data for arr in self._arrays]
        max_jitter = int(jitter.max()) if E else 0
        self._params = SimParams(
            K,
            a[0],
            a[1],
            a[2],
            a[3],
            float(inputs.enc_resolution),
            a[4],
            int(cam["period"]),
            int(cam["phase"]),
            int(cam["delay"]),
            float(cam["width"]),
            float(cam["height"]),
            float(cam["pixel_std"]),
            int(bool(cam["round_to_pixel"])),
            float(cam["drop_probability"]),
            E,
            a[5],
            a[6],
            a[7],
            (int(cam["delay"]) + max_jitter) // int(cam["period"]) + 2,
            float(inputs.diverged_error),
        )
        size = int(self._c["amsfe_sim_memory_size"](ctypes.byref(self._params)))
        if size == 0:
            raise ConfigError(
                describe("compiled simulation", "accepted inputs", "a refused block", "")
            )
        self._mem = np.zeros(size // 8 + 4)
        handle = ctypes.c_void_p()
        status = self._c["amsfe_sim_init"](
            ctypes.byref(handle),
            ctypes.byref(self._params),
            estimator_handle,
            controller.handle,
            self._mem.ctypes.data,
            size,
        )
        if status != 0:
            raise ConfigError(describe("amsfe_sim_init", "AMSFE_OK", f"status {status}", ""))
        self._h = handle
        self._controller = controller  # keeps its memory alive
        self.rec = SimulationRecords(
            x_true=np.zeros((K, N)),
            x_hat=np.zeros((K, N)),
            P_diag=np.zeros((K, N)),
            nees=np.zeros(K),
            u=np.zeros((K, n)),
            z_enc=np.zeros((K, 2 * n)),
            s=np.full((K, n), np.nan),
            bound=np.full((K, n), np.nan),
            saturated=np.zeros(K, dtype=bool),
            frames=np.zeros((max(E, 1), 4)),
            state=SimulationState(),
        )
        r = self.rec
        self._records = SimRecords(
            *(
                arr.ctypes.data
                for arr in (r.x_true, r.x_hat, r.P_diag, r.nees, r.u, r.z_enc, r.s, r.bound)
            ),
            r.saturated.ctypes.data,  # numpy bool is one byte, as unsigned char
            r.frames.ctypes.data,
            r.frames.shape[0],
        )

    def run(self, ticks: int) -> SimulationState:
        """Run up to ``ticks`` more ticks; return the state (``status < 0``: an error)."""
        self._c["amsfe_sim_run"](self._h, ticks, ctypes.byref(self._records))
        self._c["amsfe_sim_get_state"](self._h, ctypes.byref(self.rec.state))
        return self.rec.state

    def status_string(self, status: int) -> str:
        """The runtime's description of a status code."""
        text: bytes = self._c["amsfe_status_string"](status)
        return text.decode()


def write_loop_log(
    path: str | os.PathLike[str],
    est: CompiledEstimator,
    params: ControllerParams,
    z: FloatArray,
    ref: FloatArray,
    frames: FloatArray,
) -> Path:
    """Write the log read by ``examples/control_from_log.c`` (format in its header comment).

    Args:
        path: Output file.
        est: A freshly built compiled estimator (its parameter block is written).
        params: The controller's parameter block.
        z: Encoder samples per step, (K, 2n).
        ref: Reference per step [q_d, qd_d, qdd_d, jerk_d, snap_d], (K, 5n).
        frames: Delivered frames, rows (exposure step, delivery step, u, v) as recorded
            by a run; each goes before the step it was delivered at.
    """
    lines = estimator_log_lines(est)
    lines.append(
        f"ctrl {CONTROLLER_CODES[params.name]} {params.T!r} {params.p!r} "
        f"{int(params.qmd_next_hold)} {int(params.state_true)} "
        f"{params.link_bandwidth!r} {params.motor_bandwidth!r} "
        f"{int(params.startup_converged)} {params.ready_q_std!r} {params.ready_qd_std!r} "
        f"{params.blend_accel!r} {params.blend_rate!r} "
        f"{params.ready_nis!r} {params.ready_nis_window!r} {int(params.hold_motor)} "
        f"{params.blend_wf!r} {params.headroom_tau!r} {params.blend_lead!r}"
    )
    n = params.u_max.size
    for key in ("h", "lam", "Lt", "eps", "phi", "wm", "tau_max", "wf", "vmax"):
        lines.append(f"{key} {log_numbers(params.gains.get(key, np.zeros(n)))}")
    for key in ("u_max", "Mm", "Fm", "Ks", "ks_theta", "theta_initial"):
        lines.append(f"{key} {log_numbers(getattr(params, key))}")
    by_step: dict[int, list[FloatArray]] = {}
    for row in np.asarray(frames, dtype=float).reshape(-1, 4):
        by_step.setdefault(int(row[1]), []).append(row)
    for k in range(len(z)):
        for row in by_step.get(k, []):
            lines.append(f"frame {int(row[0])} {log_numbers(row[2:])}")
        lines.append(f"step {log_numbers(z[k])} {log_numbers(ref[k])}")
    out = Path(path)
    out.write_text("\n".join(lines) + "\n")
    return out
