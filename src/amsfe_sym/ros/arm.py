"""The simulated arm, one tick at a time: the plant and the sensors of
:func:`amsfe_sym.sim.loop.run`, built by the same builders from the same random streams, so a
seed gives the same samples live as in process (``amsfe sim-node``).

One tick k (t_k = k T): :meth:`SimArm.sense` reads the encoders and the camera at x_k (the
loop's step 1); the command u_k comes from outside; :meth:`SimArm.advance` integrates the
plant over [t_k, t_k + T] with u_k held and the tick's disturbance torques (the loop's step 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.sim.builders import build_sensors, plant_start, scenario_timing

__all__ = ["SimArm", "TickSensors"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TickSensors:
    """What the sensors give at tick k.

    Attributes:
        k: The tick.
        z: The encoder sample [qm [rad], qmd [rad/s]] taken at t_k, shape (2n,).
        frames: Camera frames delivered at k (exposed earlier: ``exposure_step``).
        x_true: The true state [q, qd, qm, qmd, theta] at t_k, shape (N,).
    """

    k: int
    z: FloatArray
    frames: list[CameraFrame]
    x_true: FloatArray


class SimArm:
    """The plant (compiled RK4 ``plant_step``, the true theta) and its sensors.

    Args:
        sc: The scenario (``[plant]``, ``[encoders]``, ``[camera]``, ``seed``, ``duration``).
        lib: Its library.
    """

    def __init__(self, sc: Scenario, lib: ModelLibrary) -> None:
        self.lib = lib
        self.T = lib.T
        #: Ticks of the scenario's duration (``round(duration / T) + 1``).
        self.K = run_ticks(sc, lib.T, lib.n, lib.N)
        # the loop's build_run without the estimator and controller: same order, same streams
        timing = scenario_timing(sc, lib)
        self._x = plant_start(sc, lib)
        self.sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), timing)
        L = lib.layout
        self._qm, self._qmd, self._q = L["qm"], L["qmd"], L["q"]
        self._z0 = self.sensors.encoders.measure(self._x[self._qm], self._x[self._qmd])
        self._plant = lib.function("plant_step")
        self._theta = lib.theta_true
        self.k = 0

    @property
    def state(self) -> FloatArray:
        """The true plant state [q, qd, qm, qmd] at t_k (a copy)."""
        return self._x.copy()

    def sense(self) -> TickSensors:
        """The sensors at the current tick k (call once per tick, before :meth:`advance`)."""
        k, x = self.k, self._x
        z = self._z0 if k == 0 else self.sensors.encoders.measure(x[self._qm], x[self._qmd])
        frames = self.sensors.camera.tick(k, x[self._q])
        return TickSensors(k, np.asarray(z, dtype=float), frames, np.concatenate([x, self._theta]))

    def advance(self, u: FloatArray) -> None:
        """Integrate over [t_k, t_k + T] with the torque ``u`` [N m] held, then k += 1."""
        dist = self.sensors.disturbance.sample()
        tau = np.concatenate([dist.link, dist.motor])
        self._x = self._plant.call_into(self._x, np.asarray(u, dtype=float), self._theta, tau)[
            0
        ].copy()
        self.k += 1
