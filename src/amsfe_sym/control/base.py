"""Controller interface and registry."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, check_known_keys, describe
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.signals.trajectory import Trajectory

__all__ = ["CONTROLLERS", "Controller", "LawInputs", "handed_over", "make_controller", "register"]


class LawInputs(NamedTuple):
    """What a control law may read at tick k.

    Attributes:
        k: Tick index.
        t: Time t_k = k T [s].
        x_true: The true plant state [q, qd, qm, qmd] (oracles only), shape (4n,).
        theta_true: The true parameters theta (oracles only), shape (p,).
        x_hat: The estimate x(k|k) (eq. 2), shape (N,).
        z_enc: The encoder sample [qm, qmd] + noise (eq. 5) taken at t_k, shape (2n,).
        P_diag: The diagonal of the estimate's covariance P(k|k), shape (N,), or None (an
            estimate taken as converged): the cascades' start-up waits for it.
        encoder_nis: The NIS of this tick's encoder innovation (the estimator's
            ``StepReport.encoder_nis``), or None (no sample, or not measured): the cascades'
            start-up tests the filter's consistency on it (``ready_nis``).
    """

    k: int
    t: float
    x_true: FloatArray
    theta_true: FloatArray
    x_hat: FloatArray
    z_enc: FloatArray
    P_diag: FloatArray | None = None
    encoder_nis: float | None = None


class Controller(ABC):
    """Computes the motor torque u(k) [N m] applied over [t_k, t_k + T].

    Args:
        lib: The generated library (the controller's model terms come from it).
        trajectory: The desired trajectory q_d(t).
        gains: Controller-specific gains (see each class); unknown keys are an error.
    """

    name: ClassVar[str]
    gain_defaults: ClassVar[dict[str, Any]] = {}

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        self.lib = lib
        self.trajectory = trajectory
        given = dict(gains or {})
        check_known_keys(f"controller {self.name!r} gains", given, self.gain_defaults)
        self.gains = {**self.gain_defaults, **given}

        limits = lib.manifest.actuators.u_max or (np.inf,) * lib.n
        #: Actuator torque limit per joint [N m] (``inf``: none); :meth:`saturate` applies it.
        self.u_max = np.array(limits, dtype=float)
        #: Sliding variable s(k) of eq. (33) of the last tick (NaN for laws without one).
        self.s = np.full(lib.n, np.nan)
        #: |dv - lam e(k+1)^p + lam e^p| of the last tick (the norm inside eq. 38), or NaN.
        self.bound = np.full(lib.n, np.nan)

    def saturate(self, u: FloatArray) -> tuple[FloatArray, bool]:
        """Clip u to the actuator limit; return the applied torque and whether it clipped."""
        clipped = np.clip(u, -self.u_max, self.u_max)
        return clipped, bool(np.any(clipped != u))

    def c_parameters(self) -> dict[str, Any] | None:
        """What the C runtime's parameter block of this controller holds beyond the actuator
        data (``amsfe_ctrl_params`` of amsfe_loop.h: ``gains`` per joint, ``p`` and the
        flags), or ``None`` when the controller has no C counterpart (then only
        ``--runtime python`` runs it)."""
        return None

    def prepare(self, t: FloatArray) -> None:
        """Precompute the desired trajectory on the run's time grid ``t`` [s] (one vectorised
        evaluation instead of one per tick); :meth:`reference` then reads it by tick index."""
        ref = self.trajectory.evaluate(t)
        self._grid = (
            t,
            ref.q.reshape(t.size, -1),
            ref.qd.reshape(t.size, -1),
            ref.qdd.reshape(t.size, -1),
        )

    def reference(self, k: int, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Desired (q, qd, qdd) at tick ``k`` / time ``t`` [s] (from :meth:`prepare` if it
        covers ``k`` at that time, else evaluated now)."""
        grid = getattr(self, "_grid", None)
        if grid is not None and 0 <= k < grid[0].size and grid[0][k] == t:
            return grid[1][k], grid[2][k], grid[3][k]
        ref = self.trajectory.evaluate(t)
        return ref.q, ref.qd, ref.qdd

    def handed_over(self, k: int) -> bool:
        """The law tracks q_d itself at tick ``k`` (its start-up, if any, is over): a live
        node's tracking watchdog judges |q_d - q_hat| from then on (ros/watchdog.py).  Laws
        without a start-up: always."""
        return True

    @abstractmethod
    def torque(self, tick: LawInputs) -> FloatArray:
        """u(k) [N m], before saturation, from what the law may read at tick k
        (:class:`LawInputs`)."""


def handed_over(
    startup: str, started: bool, blend: tuple[Any, ...] | None, k: int, T: float
) -> bool:
    """A cascade's start-up handed over at tick ``k``: ``startup`` is not ``"converged"``, or
    the estimate was trusted (``started``) and the blended start ``blend`` = (k0, s0, Tb, ...)
    of control/blend.py ended, (k - k0) T + s0 >= Tb [s] (the test the law makes; the C's
    ``amsfe_ctrl_handed_over``)."""
    if startup != "converged":
        return True
    if not started or blend is None:
        return started
    k0, s0, tb = blend[:3]
    return not ((k - k0) * T + s0 < tb)


CONTROLLERS: dict[str, type[Controller]] = {}


def register(cls: type[Controller]) -> type[Controller]:
    """Class decorator adding a controller to :data:`CONTROLLERS` under ``cls.name``."""
    CONTROLLERS[cls.name] = cls
    return cls


def check_controller_name(name: str) -> None:
    """Refuse a ``name`` no controller is registered as (ConfigError listing the names)."""
    if name not in CONTROLLERS:
        raise ConfigError(
            describe(
                "controller name",
                f"one of {sorted(CONTROLLERS)}",
                repr(name),
                "use a listed name (scenario controller = ..., or --controller)",
            )
        )


def make_controller(
    name: str, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
) -> Controller:
    """Build the controller registered as ``name`` (ConfigError listing names if unknown)."""
    check_controller_name(name)
    return CONTROLLERS[name](lib, trajectory, gains)
