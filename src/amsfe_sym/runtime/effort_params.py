"""What the C runtime needs of a log's kind of effort (docs/explanation/effort.md, "Compiled").

The Python estimators take the models :func:`~amsfe_sym.estimation.effort_models.wrap_models`
builds for an :class:`~amsfe_sym.estimation.effort.EffortSpec`; the C runtime takes the same
models as fields of its parameter block (``amsfe_params`` of ``runtime/c/amsfe_runtime.h``):

- the input carried as states (:class:`~amsfe_sym.estimation.effort_models.InputStateTransition`
  around a :class:`~amsfe_sym.runtime.models.CompiledTransition`): ``input_states = n``, the
  trapezoid gain ``T / (2 Mm)`` per joint, ``qw`` extended by the walk's variance per step
  ``input_rate_std^2 T``;
- the joint torque sensors (:class:`~amsfe_sym.estimation.effort_models.SpringTorqueMeasurement`):
  ``joint_torque = 1``, ``Ks`` and the theta index of each joint's stiffness;
- the reconstructed net motor torque of ``none``
  (:class:`~amsfe_sym.estimation.effort_models.NetTorqueTransition`): ``net_torque = 1``, the
  trapezoid gain, ``Ks`` and the theta index of each joint's stiffness.

:func:`effort_parts` reads them off the models, or refuses in one line what the C runtime does
not compute (then the Python estimator, ``compiled = False``, does).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation.effort import MotorParams
from amsfe_sym.estimation.effort_models import (
    InputStateTransition,
    NetTorqueTransition,
    PaddedMeasurement,
    SpringTorqueMeasurement,
)
from amsfe_sym.runtime.models import CameraMeasurement, CompiledTransition, EncoderMeasurement

__all__ = ["EffortParts", "effort_parts"]


@dataclass(frozen=True)
class EffortParts:
    """The models of a compiled estimator, unwrapped, and the effort fields of its parameters.

    Attributes:
        model: The robot's transition (the C runtime's generated step).
        camera: The camera model of the robot's N states.
        qw: Diagonal of the process noise inputs, ``2n + p`` (+ ``n`` with input states:
            ``input_rate_std^2 T`` [N^2 m^2] each).
        input_states: 0, or ``n``: the input carried as states.
        input_gain: ``T / (2 Mm)`` per joint [s / (kg m^2)] (``trapezoid_input_gain``), or
            empty.
        joint_torque: The encoder sample is ``[qm, qmd, tau_J]``.
        ks: The spec's stiffness per joint [N m/rad] (joint_torque, net_torque), or empty.
        ks_theta: Theta index of each joint's stiffness, or -1 (int32), or empty.
        net_torque: The input is the net motor torque (``NetTorqueTransition``).
    """

    model: CompiledTransition
    camera: CameraMeasurement
    qw: FloatArray
    input_states: int
    input_gain: FloatArray
    joint_torque: bool
    ks: FloatArray
    ks_theta: NDArray[np.int32]
    net_torque: bool = False

    @property
    def effort(self) -> bool:
        """Whether any effort field is set (else the applied torque, as before)."""
        return bool(self.input_states or self.joint_torque or self.net_torque)


def _refuse(found: str) -> ConfigError:
    return ConfigError(
        describe(
            "models of a compiled estimator",
            "a CompiledTransition (or an InputStateTransition around one, with the trapezoid "
            "input gain), an EncoderMeasurement or SpringTorqueMeasurement and a "
            "CameraMeasurement, padded for input states",
            found,
            "build them with sim.builders.build_estimator, or use the Python estimator "
            "(compiled = False)",
        )
    )


def _diagonal(name: str, M: Any) -> FloatArray:
    arr = np.asarray(M, dtype=np.float64)
    d = np.diag(arr).copy()
    if not np.array_equal(arr, np.diag(d)):
        raise ConfigError(
            describe(
                name,
                "a diagonal matrix (the C runtime takes its diagonal as a tuning input)",
                "off-diagonal entries",
                "use a diagonal covariance, or the Python estimator",
            )
        )
    return d


def _trapezoid(outer: InputStateTransition | NetTorqueTransition, names: str) -> FloatArray:
    """``T / (2 Mm)`` of the wrapper's motor, as trapezoid_input_gain scales B; refused for
    another input gain."""
    gain = getattr(outer.input_gain, "__qualname__", "")
    if not gain.startswith("trapezoid_input_gain"):
        raise _refuse(f"{names} with the input gain {gain or outer.input_gain!r}")
    m: MotorParams = outer.motor
    return np.asarray(m.T / 2 / m.Mm, dtype=np.float64)


def _stiffness(motor: MotorParams) -> tuple[FloatArray, NDArray[np.int32]]:
    return (
        np.asarray(motor.Ks, dtype=np.float64).copy(),
        np.asarray(motor.stiffness_theta, dtype=np.int32).copy(),
    )


def effort_parts(model: Any, encoder: Any, camera: Any) -> EffortParts:
    """The robot's models under the effort wrappers and the effort fields of ``amsfe_params``.

    Raises:
        ConfigError: A model the C runtime does not compute (a non-diagonal ``Qw``, an input
            gain other than the trapezoid rule, a net-torque transition of ``none`` with
            ``input_model = "reconstruct"``, ...), in one line.
    """
    names = f"{type(model).__name__}, {type(encoder).__name__}, {type(camera).__name__}"
    outer = model if isinstance(model, InputStateTransition) else None
    net = model if isinstance(model, NetTorqueTransition) else None
    gain = np.zeros(0)
    if outer is not None:
        gain = _trapezoid(outer, names)
        if not (isinstance(encoder, PaddedMeasurement) and isinstance(camera, PaddedMeasurement)):
            raise _refuse(names)
        model, encoder, camera = outer.inner, encoder.inner, camera.inner
    if net is not None:
        gain = _trapezoid(net, names)
        model = net.inner
    if not (
        isinstance(model, CompiledTransition)
        and isinstance(encoder, EncoderMeasurement | SpringTorqueMeasurement)
        and isinstance(camera, CameraMeasurement)
    ):
        raise _refuse(names)
    qw = _diagonal("Qw", model.Qw)
    n = int(model.lib.n)
    if outer is not None:
        qw = np.concatenate([qw, np.diag(outer.input_variance)])
    ks, ks_theta = np.zeros(0), np.zeros(0, np.int32)
    torque = isinstance(encoder, SpringTorqueMeasurement)
    if isinstance(encoder, SpringTorqueMeasurement):
        ks, ks_theta = _stiffness(encoder.motor)
    if net is not None:
        ks_n, kst_n = _stiffness(net.motor)
        if torque and not (np.array_equal(ks, ks_n) and np.array_equal(ks_theta, kst_n)):
            raise _refuse(f"{names} with two different stiffness models")
        ks, ks_theta = ks_n, kst_n
    return EffortParts(
        model, camera, qw, n if outer else 0, gain, torque, ks, ks_theta, net is not None
    )
