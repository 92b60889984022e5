"""The public API's compiled model of a scenario: :class:`Model`, the discrete transition
the estimator predicts with, its jacobian and process noise, and the camera map
(docs/api.md)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.api.scenarios import load_scenario
from amsfe_sym.errors import ShapeError, describe

if TYPE_CHECKING:
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.runtime.models import CompiledTransition
    from amsfe_sym.scenario import Scenario

__all__ = ["Model"]

FloatArray = NDArray[np.float64]


class Model:
    """A scenario's compiled model: the discrete transition x(k+1) = F(x(k), u(k)) with the
    scenario's integrator (the paper's eqs. 1a-1d, ``semi_implicit`` or ``rk4``), its
    jacobian, the process noise its filter adds, and the camera map.  These are the
    functions the estimators and ``amsfe simulate`` call, from the same library.

    The state is eq. (2), ``x = [q, qd, qm, qmd, theta]`` (N = 4 n + p): link angles [rad],
    link rates [rad/s], motor angles [rad], motor rates [rad/s], the unknown parameters (in
    their own units); ``u`` is the motor torque [N m], held over one period T.

    Build one with :meth:`for_scenario`.

    Attributes:
        scenario: The scenario it is the model of.
        n: Modelled joints.
        p: Unknown parameters theta.
        N: State size, 4 n + p.
        T: Sampling period [s].
        joints: The joints' names, in q order.
        layout: Where each block of the state is: ``x[layout["q"]]`` are the link angles
            (keys ``q``, ``qd``, ``qm``, ``qmd``, ``theta``).
        theta_true: The parameters' true values (the plant's), (p,).
    """

    def __init__(self, scenario: Scenario, lib: ModelLibrary) -> None:
        from amsfe_sym.runtime.models import CompiledTransition, noise_covariance

        f = scenario.filter
        self.scenario = scenario
        self._lib = lib
        self._transition: CompiledTransition = CompiledTransition(
            lib,
            noise_covariance(lib, f.link_torque_std, f.motor_torque_std, f.theta_rate_std),
        )
        self._camera = lib.function("camera_measure")
        self.n, self.p, self.N, self.T = lib.n, lib.p, lib.N, lib.T
        self.joints: tuple[str, ...] = tuple(lib.manifest.joints)
        self.layout: dict[str, slice] = dict(lib.layout)
        self.theta_true: FloatArray = lib.theta_true

    @classmethod
    def for_scenario(
        cls,
        scenario: str | os.PathLike[str] | Scenario = "paper-sim",
        overrides: Mapping[str, object] | None = None,
    ) -> Model:
        """The model of a scenario, its robot's library generated first if the cache has
        none.

        Args:
            scenario: A scenario's name or path, or a Scenario (:func:`load_scenario`).
            overrides: As :func:`load_scenario`'s, e.g. ``{"integrator": "paper"}``.

        Returns:
            The :class:`Model`.

        Raises:
            ConfigError: no such scenario, an unknown key or a value its checks refuse.
        """
        from amsfe_sym.codegen import library_for

        sc = load_scenario(scenario, overrides)
        return cls(sc, library_for(sc))

    def step(self, x: ArrayLike, u: ArrayLike) -> FloatArray:
        """One period of the model: x(k+1) = F(x(k), u(k)).

        Args:
            x: The state x(k) (eq. 2), (N,).
            u: The motor torque over the period [N m], (n,).

        Returns:
            x(k+1), (N,).
        """
        return self._transition.step(*self._xu(x, u))[0]

    def jacobian(self, x: ArrayLike, u: ArrayLike) -> FloatArray:
        """A = dF/dx at (x, u), (N, N): the EKF's prediction of the covariance (eq. 12)."""
        return self._transition.step(*self._xu(x, u))[1]

    def process_noise(self, x: ArrayLike, u: ArrayLike) -> FloatArray:
        """Qd = Gamma Qw Gamma^T at (x, u), (N, N) [state unit^2]: the covariance the filter
        adds over one period (eqs. 3-4), from the scenario's ``[filter]``
        ``link_torque_std``, ``motor_torque_std`` [N m] and ``theta_rate_std`` [unit/s]."""
        return self._transition.process_noise(*self._xu(x, u))

    def camera(self, q: ArrayLike, theta: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """Where the camera sees the tracked point, and how that moves with q.

        Args:
            q: Link angles [rad], (n,).
            theta: The parameters, (p,); None: :attr:`theta_true`.

        Returns:
            The pixel y = (u, v) [px], (2,), and its jacobian dy/dq [px/rad], (2, n).
        """
        qv = self._vector("q", q, self.n)
        th = self.theta_true if theta is None else self._vector("theta", theta, self.p)
        y, J, _depth = self._camera(qv, th)
        return np.asarray(y, dtype=float).reshape(2), np.asarray(J, dtype=float).reshape(2, -1)

    def _xu(self, x: ArrayLike, u: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._vector("x", x, self.N), self._vector("u", u, self.n)

    @staticmethod
    def _vector(what: str, value: ArrayLike, size: int) -> FloatArray:
        v = np.asarray(value, dtype=float).ravel()
        if v.shape != (size,):
            raise ShapeError(
                describe(what, f"{size} numbers", f"shape {np.shape(value)}", f"pass {size}")
            )
        return v
