"""What a log's effort is, and how the estimator uses it (docs/explanation/effort.md).

Real arms log different things under "effort":

- ``"applied"``: the applied motor torque ``u`` [N m] (what this toolkit's own logs hold): it
  is the input of ``F(x, u)`` (paper eqs. (1a)-(1d), (4)), as before.
- ``"joint_torque"``: the measured joint (spring) torque ``tau_J = Ks (qm - q)`` [N m] of a
  torque sensor on the link side of the elastic element (Franka Panda, KUKA iiwa).  It is a
  measurement of the state, fused with the encoders: ``z = [qm, qmd, tau_J]``
  (``effort_models.SpringTorqueMeasurement``; when ``Ks`` is a theta parameter the
  product ``Ks (qm - q)`` is bilinear and its jacobian is exact).  ``u`` is not logged.
- ``"none"``: encoders only; ``u`` is unknown.

Without ``u`` the estimator gets its input one of two ways (:data:`INPUT_MODELS`):

- ``"state"`` (the default): ``u`` is carried as ``n`` extra states, a random walk
  (``effort_models.InputStateTransition``; the measurements see the first N states
  through ``effort_models.PaddedMeasurement``).
- ``"reconstruct"``: ``u`` from the motor rows of eq. (1b) with the trapezoid rule over the
  step (:func:`reconstruct_input`)::

      u(k) = Mm (qmd(k+1) - qmd(k)) / T + Fm (qmd(k) + qmd(k+1)) / 2
             + (tau_J(k) + tau_J(k+1)) / 2

  its noise carried in the filter's motor-torque process noise (:func:`input_noise_std`).  It
  uses the sample at ``k+1``; the estimator's step ``k -> k+1`` runs when that sample arrives,
  so live it costs no latency.  For ``none`` only the *net* motor torque
  ``u - Ks (qm - q) = Mm qmdd + Fm qmd`` is reconstructed (no ``tau_J`` term) and
  ``effort_models.NetTorqueTransition`` adds the spring torque of the state being
  predicted.

:func:`~amsfe_sym.estimation.effort_models.wrap_models` builds the estimator's models for a
kind of effort (the models are in :mod:`amsfe_sym.estimation.effort_models`), and
:func:`estimator_inputs` what to feed it.  docs/explanation/effort.md measures each design (and why
the
simplest one, ``u = 0`` with the motor torque in the process noise, diverges).

Pure numpy: the robot enters through :class:`MotorParams` (the actuators of eq. (1b)).
docs/explanation/effort.md has the design and the measured consistency of each mode.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.arrays import FloatArray
from amsfe_sym.core.values import EFFORT_KINDS, require_positive
from amsfe_sym.errors import ConfigError, ShapeError, check_known_keys, describe, unknown_name

__all__ = [
    "DEFAULT_JOINT_TORQUE_STD",
    "EFFORT_KINDS",
    "INPUT_MODELS",
    "EffortSpec",
    "EstimatorInputs",
    "MotorParams",
    "effort_spec",
    "encoder_dim",
    "encoder_row",
    "estimator_inputs",
    "input_noise_std",
    "reconstruct_input",
]


#: How an estimator without the applied torque gets its input (``joint_torque``, ``none``):
#: ``"state"``: u is n extra states, a random walk (``effort_models.InputStateTransition``);
#: ``"reconstruct"``: u from the encoders (and tau_J), its noise in Q (module docstring).
INPUT_MODELS = ("state", "reconstruct")

#: The word-valued settings of :class:`EffortSpec`: where a user writes them, their choices,
#: and what the choices mean (the fix an error names).
_CHOICES: dict[str, tuple[str, tuple[str, ...], str]] = {
    "kind": (
        "[effort] kind",
        EFFORT_KINDS,
        '"applied" (motor torque), "joint_torque" (torque sensors) or "none"',
    ),
    "input_model": ("[effort] input_model", INPUT_MODELS, '"state" (the default) or "reconstruct"'),
    "positions": (
        "positions",
        ("motor", "link"),
        '"link" (the link angle q) for a Franka\'s /joint_states, else leave it out (the motor '
        "angle qm)",
    ),
}

#: Default diffusion of the input random walk [N m / sqrt(s)]: 3.2 N m a step at 1 kHz
#: (chosen on seed 100 of paper-sim and panda-control, docs/explanation/effort.md).
DEFAULT_INPUT_RATE_STD = 100.0

#: Default 1-sigma of the initial input state [N m].
DEFAULT_INPUT_STD0 = 50.0

#: Default 1-sigma of a joint torque sensor [N m]: the order of the Franka Panda's measured
#: ``tau_J`` at rest (a few hundredths of a N m); ours, not a datasheet value.
DEFAULT_JOINT_TORQUE_STD = 0.05


@dataclass(frozen=True)
class EffortSpec:
    """What a log's effort column is, and the noise the estimator assumes for it.

    Attributes:
        kind: One of :data:`EFFORT_KINDS`.
        joint_torque_std: ``joint_torque``: 1-sigma of the measured joint torque [N m].
        input_model: ``joint_torque`` and ``none``: one of :data:`INPUT_MODELS`.
        input_rate_std: ``"state"``: diffusion of the input random walk [N m / sqrt(s)]:
            each step adds a variance ``input_rate_std^2 T``.
        input_std0: ``"state"``: 1-sigma of the initial input [N m].
        scale: The logged effort times ``scale`` is the effort in N m (a UR logs motor
            currents [A]: ``scale`` is the torque constant times the gear ratio [N m/A]).
        positions: What the logged positions are: ``"motor"`` (qm of eq. (2)) or ``"link"``
            (q, as franka_ros logs libfranka's ``q``).  ``"link"`` with ``joint_torque``:
            the encoder angle given to the estimator is ``qm = q + tau_J / Ks`` (eq. (1b)'s
            spring, Ks the spec's value); the rates are taken as they are (the spring's rate
            ``d tau_J / dt / Ks`` is not added).  With the other kinds qm cannot be formed
            and the positions are used as they are.
    """

    kind: str = "applied"
    joint_torque_std: float = DEFAULT_JOINT_TORQUE_STD
    input_model: str = "state"
    input_rate_std: float = DEFAULT_INPUT_RATE_STD
    input_std0: float = DEFAULT_INPUT_STD0
    scale: float = 1.0
    positions: str = "motor"

    @property
    def input_as_state(self) -> bool:
        """Whether the estimator carries the input as states
        (``effort_models.InputStateTransition``)."""
        return self.kind != "applied" and self.input_model == "state"

    def __post_init__(self) -> None:
        for key, (where, known, fix) in _CHOICES.items():
            if getattr(self, key) not in known:
                raise unknown_name(where, getattr(self, key), known, fix)
        for name in ("input_rate_std", "input_std0", "scale"):
            require_positive(
                float(getattr(self, name)),
                f"[effort] {name}",
                "a positive, finite standard deviation",
                "leave it out for the default",
                ConfigError,
            )
        require_positive(
            float(self.joint_torque_std),
            "[effort] joint_torque_std",
            "a positive, finite standard deviation [N m]",
            "give the torque sensor's noise, e.g. 0.05",
            ConfigError,
        )


def effort_spec(table: Mapping[str, object], where: str = "[effort]") -> EffortSpec:
    """The :class:`EffortSpec` of a log spec's ``[effort]`` table (keys: ``kind``,
    ``joint_torque_std`` [N m], ``input_model``, ``input_rate_std`` [N m/sqrt(s)],
    ``input_std0`` [N m], ``scale`` [N m per logged unit]; each optional).

    Raises:
        ConfigError: An unknown key, or a value :class:`EffortSpec` refuses.
    """
    fields = ("kind", "joint_torque_std", "input_model", "input_rate_std", "input_std0", "scale")
    check_known_keys(
        where, table.keys(), fields, "remove or rename them (docs/explanation/effort.md)"
    )
    kw: dict[str, object] = {}
    for key, value in table.items():
        if key in ("kind", "input_model"):
            if not isinstance(value, str):
                raise ConfigError(
                    describe(f"{where} {key}", "a string", repr(value), "quote the value")
                )
            kw[key] = value
        elif isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(
                describe(f"{where} {key}", "a number", repr(value), "give it in SI units")
            )
        else:
            kw[key] = float(value)
    return EffortSpec(**kw)  # type: ignore[arg-type]


@dataclass(frozen=True)
class MotorParams:
    """The actuator side of eq. (1b) and the state layout of eq. (2).

    Attributes:
        Ks: Spring stiffness per joint [N m/rad] (the spec's value; see ``stiffness_theta``).
        Mm: Motor inertia, link side of the gear [kg m^2].
        Fm: Motor viscous friction [N m s/rad].
        T: Sample time [s].
        p: Number of theta parameters.
        stiffness_theta: Per joint, the index of the theta entry that holds its stiffness,
            or -1 (then ``Ks`` is used).
        u_max: Torque limit per joint [N m] (``inf``: none).
    """

    Ks: FloatArray
    Mm: FloatArray
    Fm: FloatArray
    T: float
    p: int = 0
    stiffness_theta: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))
    u_max: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        n = np.asarray(self.Ks).size
        for name in ("Ks", "Mm", "Fm"):
            arr = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if arr.size != n:
                raise ShapeError(
                    describe(f"MotorParams.{name}", f"{n} values", f"{arr.size}", "one per joint")
                )
            object.__setattr__(self, name, arr)
        idx = np.asarray(self.stiffness_theta, dtype=np.int32).reshape(-1)
        if idx.size == 0:
            idx = np.full(n, -1, dtype=np.int32)
        if idx.size != n or np.any(idx >= self.p) or np.any(idx < -1):
            raise ShapeError(
                describe(
                    "MotorParams.stiffness_theta",
                    f"{n} indices in [-1, {self.p - 1}]",
                    repr(idx.tolist()),
                    "use ModelLibrary.stiffness_theta_index",
                )
            )
        object.__setattr__(self, "stiffness_theta", idx)
        umax = np.asarray(self.u_max, dtype=float).reshape(-1)
        object.__setattr__(self, "u_max", np.full(n, np.inf) if umax.size == 0 else umax)
        require_positive(
            float(self.T), "MotorParams.T", "a positive sample time [s]", "use lib.T", ConfigError
        )

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.Ks.size)

    @property
    def N(self) -> int:
        """State size ``4n + p`` (eq. 2)."""
        return 4 * self.n + self.p

    def stiffness(self, theta: FloatArray) -> FloatArray:
        """``Ks`` [N m/rad] with the joint-stiffness parameters read from ``theta``."""
        Ks = self.Ks.copy()
        mask = self.stiffness_theta >= 0
        Ks[mask] = theta[self.stiffness_theta[mask]]
        return Ks


def encoder_dim(kind: str, n: int) -> int:
    """Entries of the encoder measurement the estimator gets each step: ``2n`` ([qm, qmd]),
    ``3n`` for ``joint_torque`` ([qm, qmd, tau_J])."""
    return 3 * n if kind == "joint_torque" else 2 * n


def input_noise_std(
    spec: EffortSpec, motor: MotorParams, qd_std: ArrayLike, tau_std: float | None = None
) -> FloatArray:
    """1-sigma [N m] of the error of the input the estimator is given, per joint.

    Add it in quadrature to the filter's motor-torque noise (eq. (3)): it enters the motor
    rows of eq. (1b) exactly where a motor torque disturbance does.

    - ``applied``, or the input carried as states: 0 (the logged u is the input; the
      input states have their own random walk).
    - ``joint_torque``: the trapezoid reconstruction of the module docstring with encoder
      rate noise ``qd_std`` [rad/s] and torque noise ``tau_std`` [N m] (default
      ``spec.joint_torque_std``): ``var = ((Mm/T + Fm/2)^2 + (Mm/T - Fm/2)^2) qd_std^2
      + tau_std^2 / 2`` (successive inputs share samples; that correlation is not carried).
    - ``none``: the same without the torque term (the net torque of
      ``effort_models.NetTorqueTransition``).
    """
    n = motor.n
    if spec.kind == "applied" or spec.input_as_state:
        return np.zeros(n)
    sv = np.broadcast_to(np.asarray(qd_std, dtype=float), (n,))
    st = 0.0 if spec.kind == "none" else spec.joint_torque_std if tau_std is None else tau_std
    a = motor.Mm / motor.T
    var = ((a + motor.Fm / 2) ** 2 + (a - motor.Fm / 2) ** 2) * sv**2 + st**2 / 2
    return np.sqrt(var)


def reconstruct_input(qmd: FloatArray, tau_j: FloatArray, motor: MotorParams) -> FloatArray:
    """The motor torque ``u(k)`` over ``[k, k+1]`` from the motor rows of eq. (1b).

    ``u(k) = Mm (qmd(k+1) - qmd(k)) / T + Fm (qmd(k) + qmd(k+1)) / 2 + (tau(k) + tau(k+1)) / 2``
    (the trapezoid rule on ``Mm qmdd = u - Fm qmd - tau``: second order in T).

    Args:
        qmd: Motor rates [rad/s], shape (K, n).
        tau_j: Spring torques [N m], shape (K, n).
        motor: The actuators.

    Returns:
        u [N m], shape (K, n); the last row (no sample after it) repeats the one before: it
        never enters an estimator step.  A row that a missing sample (NaN) leaves undefined
        holds the last defined row (zero before the first).
    """
    if qmd.shape != tau_j.shape or qmd.ndim != 2 or qmd.shape[1] != motor.n:
        raise ShapeError(
            describe(
                "reconstruct_input",
                f"qmd and tau_J of one shape (K, {motor.n})",
                f"{qmd.shape} and {tau_j.shape}",
                "pass one row per sample, one column per joint",
            )
        )
    K = qmd.shape[0]
    u = np.zeros_like(qmd)
    if K >= 2:
        a, b = qmd[:-1], qmd[1:]
        u[:-1] = (
            motor.Mm * (b - a) / motor.T + motor.Fm * (a + b) / 2 + (tau_j[:-1] + tau_j[1:]) / 2
        )
        u[-1] = u[-2]
    for k in np.flatnonzero(~np.isfinite(u).all(axis=1)):  # in order: a forward fill
        u[k] = u[k - 1] if k > 0 else 0.0
    return u


@dataclass(frozen=True)
class EstimatorInputs:
    """What an estimator is given for a log with a given kind of effort.

    Step ``k -> k+1`` is ``est.step(u[k], z_encoder[k+1], frames delivered at k+1)``.

    Attributes:
        kind: The effort kind.
        u: Input over ``[k, k+1]`` [N m], shape (K, n) (``none``: the net motor torque,
            the input of ``effort_models.NetTorqueTransition``).
        z_encoder: Encoder measurement at ``k``: ``[qm, qmd]`` (K, 2n), or
            ``[qm, qmd, tau_J]`` (K, 3n) for ``joint_torque``.
        input_std: :func:`input_noise_std` [N m], (n,): add it in quadrature to the filter's
            motor-torque noise.
    """

    kind: str
    u: FloatArray
    z_encoder: FloatArray
    input_std: FloatArray


def encoder_row(
    spec: EffortSpec, z: ArrayLike, effort: ArrayLike | None, motor: MotorParams
) -> FloatArray:
    """The encoder measurement the estimator is given for one sample (or a stack of them):
    what a log's rows (:func:`estimator_inputs`) and a live node's samples
    (:class:`amsfe_sym.ros.live.LiveLoop`) both go through.

    Args:
        spec: What the effort is.
        z: The sample ``[position, velocity]`` [rad, rad/s], (2n,) or (K, 2n).
        effort: The effort of the same tick as logged (times ``spec.scale``: N m), (n,) or
            (K, n); used for ``joint_torque`` only (else may be None).
        motor: The robot's actuators (``Ks`` for ``positions = "link"``).

    Returns:
        ``[qm, qmd]`` for ``applied`` and ``none`` (the sample as it is);
        ``[qm, qmd, tau_J]`` for ``joint_torque``, with ``qm = q + tau_J / Ks`` (eq. (1b)'s
        spring) when ``spec.positions == "link"``.  A new array.

    Raises:
        ShapeError: ``joint_torque`` without an effort.
    """
    n = motor.n
    z_arr = np.array(z, dtype=float)
    if spec.kind != "joint_torque":
        return z_arr
    if effort is None:
        raise ShapeError(
            describe(
                "effort of kind 'joint_torque'",
                f"{n} joint torques per sample",
                "none",
                'log the effort, or say [effort] kind = "none"',
            )
        )
    e = np.asarray(effort, dtype=float) * spec.scale
    if spec.positions == "link":  # qm = q + tau_J / Ks: the motor angle the model measures
        z_arr[..., :n] += e / motor.Ks
    return np.concatenate([z_arr, e], axis=-1)


def estimator_inputs(
    spec: EffortSpec,
    z: ArrayLike,
    effort: ArrayLike | None,
    motor: MotorParams,
    qd_std: ArrayLike,
) -> EstimatorInputs:
    """The estimator's inputs and encoder measurements for a log.

    Args:
        spec: What the effort is (:class:`EffortSpec`).
        z: Encoder samples ``[qm, qmd]`` [rad, rad/s], shape (K, 2n), one row per step.
        effort: The logged effort, (K, n), in N m once multiplied by ``spec.scale``: the
            applied torque (``applied``), the joint torque (``joint_torque``); ``None`` for
            ``none`` (ignored if given).
        motor: The robot's actuators (:class:`MotorParams`).
        qd_std: 1-sigma of the encoder rate [rad/s] (the filter's encoder R).

    Returns:
        :class:`EstimatorInputs`.

    Raises:
        ShapeError: ``z`` or ``effort`` of the wrong shape, or ``effort`` missing.
    """
    n = motor.n
    z_arr = np.asarray(z, dtype=float)
    if z_arr.ndim != 2 or z_arr.shape[1] != 2 * n:
        raise ShapeError(
            describe("encoder samples", f"shape (K, {2 * n})", f"{z_arr.shape}", "[qm, qmd] rows")
        )
    K = z_arr.shape[0]
    std = input_noise_std(spec, motor, qd_std)
    if spec.kind == "none":
        if spec.input_as_state:
            return EstimatorInputs(spec.kind, np.zeros((K, n)), z_arr, np.zeros(n))
        u_net = reconstruct_input(z_arr[:, n:], np.zeros((K, n)), motor)
        return EstimatorInputs(spec.kind, u_net, z_arr, std)
    if effort is None:
        raise ShapeError(
            describe(
                f"effort of kind {spec.kind!r}",
                f"an array of shape ({K}, {n})",
                "none",
                'log the effort, or say [effort] kind = "none"',
            )
        )
    e = np.asarray(effort, dtype=float) * spec.scale
    if e.shape != (K, n):
        raise ShapeError(
            describe("effort", f"shape ({K}, {n})", f"{e.shape}", "one row per encoder sample")
        )
    if spec.kind == "applied":
        return EstimatorInputs(spec.kind, e, z_arr, std)
    z_aug = encoder_row(spec, z_arr, effort, motor)
    z_arr = z_aug[:, : 2 * n]
    if spec.input_as_state:
        return EstimatorInputs(spec.kind, np.zeros((K, n)), z_aug, np.zeros(n))
    u = reconstruct_input(z_arr[:, n:], e, motor)
    return EstimatorInputs(spec.kind, u, z_aug, std)
