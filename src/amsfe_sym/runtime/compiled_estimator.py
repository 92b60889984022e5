"""The compiled estimators: the C runtime of a generated library driven through ctypes.

:class:`CompiledEstimator` has the interface of the Python estimators
(:class:`~amsfe_sym.estimation.base.Estimator`: ``step(u, z_encoder, frames) -> StepReport``,
``x``, ``P``, ``k``) and the same input checks (it inherits them), but every number is
computed by the library's C runtime (``runtime/c/amsfe_runtime.{c,h}`` over the generated
``est_*`` functions, docs/how-to/runtime-c.md): a step is one ``amsfe_est_tick`` (predict, eqs.
13-14, encoder update, 15-17) and one ``amsfe_est_camera_frame`` per usable frame, in
increasing exposure step.  The Python estimators stay the reference; the tests require both
to agree to 1e-8 with the same decisions.

The C runtime takes diagonal noise covariances (``Qw``, encoder ``R``, camera ``R``): a
full matrix is refused with :class:`~amsfe_sym.errors.ConfigError`.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.values import BACKWARD_MAPS
from amsfe_sym.errors import ConfigError, EstimatorError, describe, unknown_name
from amsfe_sym.estimation.base import Estimator, StepInputs, StepReport
from amsfe_sym.estimation.models import CameraFrame
from amsfe_sym.runtime.cheader import c_struct, header_fields
from amsfe_sym.runtime.effort_params import EffortParts, _diagonal, effort_parts
from amsfe_sym.runtime.models import inverse_not_converged
from amsfe_sym.runtime.stability import NUMERICAL_FAILURES, covariance_hint

__all__ = [
    "COMPILED_ESTIMATORS",
    "STATUS",
    "CompiledEstimator",
    "RuntimeDiagnostics",
    "estimator_log_lines",
    "frame_reason",
    "log_numbers",
    "make_compiled_estimator",
    "write_log",
]

FloatArray = NDArray[np.float64]

#: Status codes of amsfe_runtime.h.
STATUS = {
    "ok": 0,
    "gated": 1,
    "refused_nonfinite": 2,
    "refused_too_old": 3,
    "refused_future": 4,
    "refused_indefinite": 5,
    "refused_no_clone": 6,
    "refused_no_clone_left": 7,
    "refused_full": 8,
    "ignored": 9,
    "refused_no_convergence": 10,
    "refused_duplicate": 11,
}


_Params = c_struct("_Params", "amsfe_runtime.h", "amsfe_params")


class RuntimeDiagnostics(ctypes.Structure):
    """``amsfe_diag`` of amsfe_runtime.h: counters and the outcome of the last calls."""

    _fields_ = header_fields("amsfe_runtime.h", "amsfe_diag")


_Dims = c_struct("_Dims", "amsfe_runtime.h", "amsfe_dims")


_P = ctypes.c_void_p


def _bind(cdll: ctypes.CDLL) -> dict[str, Any]:
    spec: dict[str, tuple[Any, list[Any]]] = {
        "amsfe_dims_get": (None, [_P]),
        "amsfe_est_memory_size": (ctypes.c_size_t, [_P]),
        "amsfe_est_init": (ctypes.c_int, [_P, _P, _P, ctypes.c_size_t]),
        "amsfe_est_reset": (None, [_P]),
        "amsfe_est_tick": (ctypes.c_int, [_P, _P, _P]),
        "amsfe_est_camera_frame": (ctypes.c_int, [_P, _P, ctypes.c_long, _P]),
        "amsfe_est_state": (None, [_P, _P, _P]),
        "amsfe_est_diagnostics": (None, [_P, _P]),
        "amsfe_status_string": (ctypes.c_char_p, [ctypes.c_int]),
        "amsfe_est_set_inverse_tolerance": (ctypes.c_int, [_P, ctypes.c_double]),
        "amsfe_est_inverse_residual": (None, [_P, _P, _P]),
        "amsfe_est_run": (ctypes.c_int, [_P, _P, ctypes.c_long, ctypes.c_long, _P]),
    }
    out = {}
    for name, (restype, argtypes) in spec.items():
        fn = cdll[name]
        fn.restype = restype
        fn.argtypes = argtypes
        out[name] = fn
    return out


class CompiledEstimator(Estimator):
    """An estimator computed by the library's C runtime (see the module docstring).

    Args:
        model: A :class:`~amsfe_sym.runtime.models.CompiledTransition` (its diagonal ``Qw``),
            or an :class:`~amsfe_sym.estimation.effort_models.InputStateTransition` around
            one (a log without the applied torque: the input as states, docs/explanation/effort.md).
        encoder: An :class:`~amsfe_sym.runtime.models.EncoderMeasurement` of the same library,
            or a :class:`~amsfe_sym.estimation.effort_models.SpringTorqueMeasurement`
            (``joint_torque``); padded with input states.
        camera: A :class:`~amsfe_sym.runtime.models.CameraMeasurement` of the same library
            (padded with input states).
        x0, P0, config, k0: As for :class:`~amsfe_sym.estimation.base.Estimator`.
        max_frames_per_step: ``replay``: frames stored per step.

    Raises:
        ConfigError: Other model types, a non-diagonal covariance, or a configuration the
            runtime refuses (e.g. ``cloning`` with more clones in flight than the library's
            clone slots), or oosm's ``backward_map = "inverse"`` with input states or a net
            torque input.
    """

    code: ClassVar[int]

    def __init__(self, *args: Any, max_frames_per_step: int = 4, **kwargs: Any) -> None:
        self._max_frames = max_frames_per_step
        super().__init__(*args, **kwargs)

    def _setup(self) -> None:
        enc = self.encoder
        parts = effort_parts(self.model, enc, self.camera)
        self.effort = parts
        model = parts.model
        cfg = self.config
        if parts.effort:
            self._refuse_with_effort(parts)
        lib = model.lib
        self.lib = lib
        cdll = ctypes.CDLL(str(lib.library_path))
        self._c = _bind(cdll)
        dims = _Dims()
        self._c["amsfe_dims_get"](ctypes.byref(dims))
        self.dims = dims
        self._arrays = [
            parts.qw,
            _diagonal("encoder R", self.R_encoder),
            _diagonal("camera R", self.R_camera),
            self.x.copy(),
            np.asfortranarray(self.P),
        ]
        ptr = [a.ctypes.data for a in self._arrays]
        latency = cfg.camera_max_delay
        self._params = _Params(
            self.code,
            cfg.buffer_steps,
            cfg.camera_iterations,
            cfg.camera_period or 0,
            cfg.camera_phase,
            -1 if latency is None else latency,
            self._max_frames,
            self._gate_camera,
            self._gate_encoder,
            *ptr,
            self.k,
            BACKWARD_MAPS.index(cfg.backward_map),
            parts.input_states,
            parts.input_gain.ctypes.data if parts.input_gain.size else None,
            int(parts.joint_torque),
            parts.ks.ctypes.data if parts.ks.size else None,
            parts.ks_theta.ctypes.data if parts.ks_theta.size else None,
            int(parts.net_torque),
        )
        size = self._c["amsfe_est_memory_size"](ctypes.byref(self._params))
        if size == 0:
            raise ConfigError(
                describe(
                    f"compiled {self.name} configuration",
                    "parameters the C runtime accepts",
                    f"{cfg} (clone slots in the library: {dims.clone_slots})",
                    "check variances > 0, camera_period for cloning, and that "
                    "camera_max_delay // camera_period + 1 <= clone slots",
                )
            )
        self._mem = np.zeros(size // 8 + 4)  # numpy data is 16-byte aligned
        handle = ctypes.c_void_p()
        status = self._c["amsfe_est_init"](
            ctypes.byref(handle), ctypes.byref(self._params), self._mem.ctypes.data, size
        )
        if status != 0:
            raise ConfigError(
                describe("amsfe_est_init", "AMSFE_OK", self.status_string(status), "fix the inputs")
            )
        self._h = handle
        # the same convergence check of eq. (22) as CompiledTransition.inverse
        status = self._c["amsfe_est_set_inverse_tolerance"](handle, float(model.inverse_tol))
        if status != 0:
            raise ConfigError(
                describe(
                    "inverse_tol of the transition model",
                    "a positive tolerance",
                    repr(model.inverse_tol),
                    "build CompiledTransition with inverse_tol > 0",
                )
            )
        self._xbuf = np.zeros(self.nx)
        self._Pbuf = np.zeros((self.nx, self.nx), order="F")
        self._zbuf = np.zeros(int(enc.dim))
        self._ubuf = np.zeros(self.dims.n)
        self._fbuf = np.zeros(2)
        self._nis = ctypes.c_double()
        self._diag = RuntimeDiagnostics()
        self._fetch()

    def _refuse_with_effort(self, parts: EffortParts) -> None:
        """What the C runtime does not compute with input states, joint torques or a net
        torque input, refused in one line naming what works."""
        inverse = self.name == "oosm" and self.config.backward_map != "linearised"
        if inverse and (parts.input_states or parts.net_torque):
            bad = f"oosm with backward_map {self.config.backward_map!r}"
            raise ConfigError(
                describe(
                    f"compiled {bad} on a log without the applied torque",
                    "oosm with backward_map 'linearised', or another estimator",
                    bad,
                    "use 'replay' (docs/explanation/effort.md), or the Python estimator "
                    "(amsfe estimate "
                    "--runtime python; compiled = False)",
                )
            )

    # ------------------------------------------------------------------ C calls
    def status_string(self, status: int) -> str:
        """The runtime's description of a status code."""
        text: bytes = self._c["amsfe_status_string"](status)
        return text.decode()

    def diagnostics(self) -> RuntimeDiagnostics:
        """The runtime's counters (a fresh copy)."""
        diag = RuntimeDiagnostics()
        self._c["amsfe_est_diagnostics"](self._h, ctypes.byref(diag))
        return diag

    def _fetch(self) -> None:
        self._c["amsfe_est_state"](self._h, self._xbuf.ctypes.data, self._Pbuf.ctypes.data)
        self.x = self._xbuf.copy()
        self.P = np.ascontiguousarray(self._Pbuf)

    def _error(self, what: str, status: int) -> EstimatorError:
        fix = (
            "check the inputs and the model at the current state (the runtime must be "
            "reset before it runs again)"
        )
        hint = covariance_hint(self.lib.manifest.raw) if status in NUMERICAL_FAILURES else None
        return EstimatorError(
            describe(
                f"compiled {self.name}: {what} at step {self.k + 1}",
                "a usable numerical result",
                f"status {status}: {self.status_string(status)}",
                hint or fix,
            )
        )

    def _step(self, step: StepInputs, report: StepReport) -> None:
        u, z_encoder, frames = step.u, step.z_encoder, step.frames
        self._ubuf[:] = u
        zp = None
        if z_encoder is not None:
            self._zbuf[:] = z_encoder
            zp = self._zbuf.ctypes.data
        status = self._c["amsfe_est_tick"](self._h, zp, self._ubuf.ctypes.data)
        if status < 0:
            raise self._error("tick", status)
        replayed = 0
        for frame in frames:
            self._report_frame(frame, report)
            self._c["amsfe_est_diagnostics"](self._h, ctypes.byref(self._diag))
            replayed = max(replayed, self._diag.replayed_steps)
        d = self._diag
        self._c["amsfe_est_diagnostics"](self._h, ctypes.byref(d))
        # the reference counts the steps re-filtered beyond the regular k -> k+1 one; the
        # runtime's counter includes that one (its tick ran it before the frame came)
        report.replayed_steps = max(0, replayed - 1)
        report.clones = d.clones
        if z_encoder is not None:
            report.encoder_nis = float(d.encoder_nis)
            report.encoder_accepted = bool(d.encoder_accepted)
            if not d.encoder_accepted:
                report.rejections.append(
                    f"encoder gated out: NIS {d.encoder_nis:.4g} > {self._gate_encoder:.4g}"
                )
        self._fetch()

    def _report_frame(self, frame: CameraFrame, report: StepReport) -> None:
        kappa = frame.exposure_step
        self._fbuf[:] = frame.z
        status = self._c["amsfe_est_camera_frame"](
            self._h, self._fbuf.ctypes.data, kappa, ctypes.byref(self._nis)
        )
        nis = float(self._nis.value)
        if status < 0:
            raise self._error(f"camera frame kappa={kappa}", status)
        if status in (STATUS["ok"], STATUS["gated"]):
            report.frame_result(kappa, status == STATUS["ok"], nis, self._gate_camera)
        else:
            report.reject(frame_reason(self, status, kappa))

    def _check_covariance(self) -> None:
        """Done by the runtime after every call (a failure is an error status)."""

    def reset(self) -> None:
        """Back to ``x0, P0, k0`` with empty history."""
        self._c["amsfe_est_reset"](self._h)
        self._seen.clear()
        self._ungated_outlier = None
        self.k = self.k0
        self._fetch()


def frame_reason(est: CompiledEstimator, status: int, kappa: int) -> str:
    """Why the runtime refused a frame (``status`` of ``amsfe_est_camera_frame``, not ok or
    gated), in the words of the Python estimators (``sim.result.refusal_kind`` counts them)."""
    if status == STATUS["gated"]:
        return f"camera frame kappa={kappa} gated out"
    if status == STATUS["refused_indefinite"]:
        return (
            f"camera frame kappa={kappa} (lag {est.k + 1 - kappa}): the A1 update gives an "
            "indefinite covariance (the one-step retrodiction does not hold over this lag; "
            "use 'replay' or 'cloning')"
        )
    if status == STATUS["refused_no_convergence"]:
        residual, limit = ctypes.c_double(), ctypes.c_double()
        est._c["amsfe_est_inverse_residual"](est._h, ctypes.byref(residual), ctypes.byref(limit))
        return f"camera frame kappa={kappa} (lag {est.k + 1 - kappa}): " + inverse_not_converged(
            residual.value, limit.value
        )
    return f"camera frame kappa={kappa}: {est.status_string(status)}"


def _subclass(name: str, code: int, uses_frames: bool = True) -> type[CompiledEstimator]:
    return type(
        f"Compiled{name.capitalize()}Estimator",
        (CompiledEstimator,),
        {"name": name, "code": code, "uses_frames": uses_frames, "__module__": __name__},
    )


#: The compiled estimators by name (the names of ``amsfe_sym.estimation.ESTIMATORS``).
COMPILED_ESTIMATORS: dict[str, type[CompiledEstimator]] = {
    "encoders": _subclass("encoders", 0, uses_frames=False),
    "naive": _subclass("naive", 1),
    "oosm": _subclass("oosm", 2),
    "replay": _subclass("replay", 3),
    "cloning": _subclass("cloning", 4),
}


def make_compiled_estimator(name: str, **kwargs: Any) -> CompiledEstimator:
    """Build the compiled estimator ``name`` with the arguments of ``make_estimator``."""
    if name not in COMPILED_ESTIMATORS:
        raise unknown_name("compiled estimator name", name, COMPILED_ESTIMATORS)
    return COMPILED_ESTIMATORS[name](**kwargs)


def log_numbers(values: Any) -> str:
    """Numbers of a log line: column-major, shortest round-trip repr."""
    return " ".join(repr(float(v)) for v in np.ravel(values, order="F"))


def require_applied_torque(est: CompiledEstimator, what: str, why: str, fix: str) -> None:
    """Refuse an estimator that is not given the applied torque (input states, a joint or
    net torque) where only the applied torque is carried.

    Raises:
        ConfigError: ``what`` expected an estimator of the applied torque (``why``).
    """
    p = est._params
    if p.input_states or p.joint_torque or p.net_torque:
        expected = "an estimator of the applied torque" + (f" ({why})" if why else "")
        raise ConfigError(describe(what, expected, "input states or a joint torque", fix))


def estimator_log_lines(est: CompiledEstimator) -> list[str]:
    """The estimator block of a log (its parameter block as built at construction)."""
    require_applied_torque(
        est,
        "the estimator of a C log (examples/estimate_from_log.c)",
        "the log format has no effort fields",
        "write logs of estimators built with the applied torque",
    )
    p = est._params
    if p.backward_map != 0:  # the log's params line has no field for it
        raise ConfigError(
            describe(
                "backward_map of a logged estimator",
                "'linearised' (the log format records no backward map)",
                repr(BACKWARD_MAPS[p.backward_map]),
                'log a run with [filter] backward_map = "linearised"',
            )
        )
    lines = [
        f"params {p.estimator} {p.buffer_steps} {p.camera_iterations} {p.camera_period} "
        f"{p.camera_phase} {p.camera_max_delay} {p.max_frames_per_step} "
        f"{p.gate_camera!r} {p.gate_encoder!r} {p.k0}",
    ]
    for key, arr in zip(("qw", "r_encoder", "r_camera", "x0", "P0"), est._arrays, strict=True):
        lines.append(f"{key} {log_numbers(arr)}")
    return lines


def write_log(
    path: str | os.PathLike[str],
    est: CompiledEstimator,
    u: FloatArray,
    z: Sequence[FloatArray | None],
    frames: Sequence[Sequence[CameraFrame]],
) -> Path:
    """Write the log read by ``examples/estimate_from_log.c`` (format in its header comment).

    Args:
        path: Output file.
        est: A compiled estimator: its parameter block (as built at construction) is written.
        u: Inputs ``u[j]`` over ``[k0 + j, k0 + j + 1]``, shape ``(K, n)``.
        z: Encoder samples taken at ``k0 + j + 1`` (``None``: none), ``K`` entries.
        frames: Frames delivered at ``k0 + j + 1``, ``K`` entries.

    Returns:
        The path written.
    """
    lines = estimator_log_lines(est)
    ne = est.dims.ne
    for j in range(len(u)):
        zj = z[j]
        zj_or_nan = np.full(ne, np.nan) if zj is None else zj
        lines.append(f"tick {log_numbers(u[j])} {log_numbers(zj_or_nan)}")
        for fr in sorted(frames[j], key=lambda f: f.exposure_step):
            lines.append(f"frame {fr.exposure_step} {log_numbers(fr.z)}")
    out = Path(path)
    out.write_text("\n".join(lines) + "\n")
    return out
