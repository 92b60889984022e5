"""The public API's robots, scenarios and simulations: :func:`generate`,
:func:`load_scenario`, :func:`simulate` and its :class:`SimResult` (docs/api.md)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.codegen.build import GenerateResult, generate
from amsfe_sym.errors import ConfigError, describe

if TYPE_CHECKING:
    from amsfe_sym.logs.read import RobotLog
    from amsfe_sym.scenario import Scenario
    from amsfe_sym.sim.result import RunResult

__all__ = ["LinkAngles", "Robot", "SimResult", "generate", "load_scenario", "simulate"]

FloatArray = NDArray[np.float64]

#: A generated robot: its library folder, manifest and shared library, what the build did
#: and how long it took (:class:`~amsfe_sym.codegen.build.GenerateResult`).
Robot = GenerateResult

_RUNTIMES = {"c": "compiled", "compiled": "compiled", "python": "python"}


def _set_text(value: object) -> str:
    """A Python value as the text of ``--set KEY=VALUE``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, Sequence | np.ndarray):
        return ",".join(repr(float(v)) for v in np.asarray(value, dtype=float).ravel())
    raise ConfigError(
        describe("an override value", "a number, bool, string or list", repr(value), "pass one")
    )


def load_scenario(
    name_or_path: str | os.PathLike[str] | Scenario = "paper-sim",
    overrides: Mapping[str, object] | None = None,
) -> Scenario:
    """A scenario: a shipped one by name, a ``.toml`` file or a run folder, with
    ``overrides`` applied as the command line's ``--set KEY=VALUE`` (docs/reference/scenarios.md).

    Args:
        name_or_path: ``paper-sim``, ``paper-exp``, ``panda-control``, ... or a path (a
            :class:`~amsfe_sym.scenario.Scenario` is taken as it is).
        overrides: Key -> value, e.g. ``{"duration": 2.0, "filter.link_torque_std": 0.5,
            "plant.q0": [0.1, 0.0]}``; ``seed`` and ``estimator`` are accepted too.

    Returns:
        The validated :class:`~amsfe_sym.scenario.Scenario`.

    Raises:
        ConfigError: no such scenario, an unknown key or a value its checks refuse.
    """
    from amsfe_sym.scenario import Scenario, apply_sets
    from amsfe_sym.scenario import load_scenario as _load

    sc = name_or_path if isinstance(name_or_path, Scenario) else _load(name_or_path)
    rest = dict(overrides or {})
    top: dict[str, Any] = {}
    if "seed" in rest:
        seed = rest.pop("seed")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(describe("override seed", "an integer >= 0", repr(seed), "pass 0"))
        top["seed"] = seed
    if "estimator" in rest:
        top["estimator"] = str(rest.pop("estimator"))
    sc = sc.with_overrides(**top)
    return apply_sets(sc, [f"{k}={_set_text(v)}" for k, v in rest.items()])


class LinkAngles:
    """The link angles of a result with ``x_hat``, ``P_diag`` and ``layout`` (eq. 2)."""

    x_hat: FloatArray
    P_diag: FloatArray
    layout: dict[str, slice]

    @property
    def q_hat(self) -> FloatArray:
        """Estimated link angles [rad], (K, n)."""
        return self.x_hat[:, self.layout["q"]]

    @property
    def q_std(self) -> FloatArray:
        """1-sigma of the estimated link angles [rad], (K, n)."""
        return np.sqrt(self.P_diag[:, self.layout["q"]])


@dataclass(frozen=True)
class SimResult(LinkAngles):
    """A simulated closed-loop run (:func:`simulate`), K ticks of T seconds.

    Attributes:
        t: Tick times t_k = k T [s], (K,).
        x_true: The plant's true state [q, qd, qm, qmd, theta] (eq. 2), (K, N).
        x_hat: The estimate x(k|k), (K, N).
        P_diag: The diagonal of its covariance P(k|k) [state unit^2], (K, N).
        u: Motor torque applied over [t_k, t_k+1] [N m], (K, n).
        q_des: Desired link angles [rad], (K, n).
        nis: Normalised innovation squared of each tick's encoder update (eqs. 15-17;
            chi-square with 2 n degrees of freedom when the model fits), (K,); NaN at
            tick 0.
        nees: Normalised estimation error squared e^T P^-1 e against the truth, (K,).
        frames: Delivered camera frames, rows (exposure step, delivery step, u [px],
            v [px]), (F, 4).
        joints: The modelled joints' names, in q order.
        layout: Where each block of the state is: ``x[:, layout["q"]]`` are the link
            angles (keys ``q``, ``qd``, ``qm``, ``qmd``, ``theta``).
        T: Sampling interval [s].
        diverged_at: Time [s] the run stopped because the loop diverged, or None.
        wall_time_s: Wall time of the closed loop [s].
        run: The low-level :class:`~amsfe_sym.sim.result.RunResult` (its scenario, library,
            counters; :func:`amsfe_sym.sim.record.write_run` writes it as a run folder).
    """

    t: FloatArray
    x_true: FloatArray
    x_hat: FloatArray
    P_diag: FloatArray
    u: FloatArray
    q_des: FloatArray
    nis: FloatArray
    nees: FloatArray
    frames: FloatArray
    joints: tuple[str, ...]
    layout: dict[str, slice]
    T: float
    diverged_at: float | None
    wall_time_s: float
    run: RunResult = field(repr=False)

    @property
    def q_true(self) -> FloatArray:
        """True link angles [rad], (K, n)."""
        return self.x_true[:, self.layout["q"]]

    def write_bag(self, path: str | os.PathLike[str], replace: bool = False) -> Path:
        """Write the run as a rosbag2 in MCAP (``amsfe simulate --bag``'s: the URDF, ``/tf``
        of the true and estimated arms, encoders, camera frames, torque, the truth and the
        run's config), which :func:`~amsfe_sym.api.read_log` and ``amsfe estimate`` read.

        Args:
            path: The bag folder (new, or with ``replace`` one amsfe wrote).
            replace: Replace an existing bag that amsfe wrote (never a folder of yours).

        Returns:
            The bag folder.

        Raises:
            RunFolderError: ``path`` holds something amsfe did not write, or exists without
                ``replace``.
        """
        from amsfe_sym.apps.simulate import write_bag
        from amsfe_sym.core.outputs import check_output

        check_output(path, option="path", force=replace)
        return write_bag(self.run, Path(path), replace=replace)


def simulate(
    scenario: str | os.PathLike[str] | Scenario = "paper-sim",
    *,
    controller: str | None = "amsfe",
    estimator: str | None = None,
    seed: int | None = 0,
    duration: float | None = None,
    runtime: str = "c",
) -> SimResult:
    """Simulate a scenario's closed loop (plant, sensors, estimator, controller) in memory.

    The robot's library is generated first if the cache has none (a first run of a 7-DOF
    arm compiles for about a minute).  Nothing is written: ``amsfe simulate`` writes the
    same run as a folder.

    Args:
        scenario: A scenario's name or path, or a :class:`~amsfe_sym.scenario.Scenario`
            (:func:`load_scenario`).
        controller: The control law (``amsfe``, ``dtsmc``, ``dtsmc-ekf``, ``truth``,
            ``truth-ct``, ``pd``...); None: the scenario's.
        estimator: ``oosm``, ``replay``, ``cloning``, ``naive`` or ``encoders``; None: the
            scenario's.
        seed: The random seed of the sensors and the plant's noise; None: the scenario's.
        duration: Simulated time [s]; None: the scenario's.
        runtime: ``"c"`` (the library's compiled loop, the command's default) or
            ``"python"`` (the readable reference; the same numbers to ~1e-9).

    Returns:
        The :class:`SimResult`.

    Raises:
        ConfigError: a bad name or setting (before anything is compiled).
        EstimatorError, MeasurementError: the compiled run failed numerically.
    """
    if runtime not in _RUNTIMES:
        raise ConfigError(describe("runtime", "'c' or 'python'", repr(runtime), "use runtime='c'"))
    from amsfe_sym.codegen import library_for
    from amsfe_sym.sim.loop import run

    sc = load_scenario(scenario).with_overrides(
        controller=controller, estimator=estimator, seed=seed, duration=duration
    )
    from amsfe_sym.scenario import validate

    validate(sc, f"{sc.name} (simulate)")
    lib = library_for(sc)
    res = run(sc, lib, runtime=_RUNTIMES[runtime])
    from amsfe_sym.sim.result import RunResult

    # what the run has under the same name (t, x_true, x_hat, P_diag, u, q_des, nees, frames,
    # diverged_at, wall_time_s) is taken as it is: a field both gain is carried over
    same = {f.name for f in fields(SimResult)} & {f.name for f in fields(RunResult)}
    return SimResult(
        **{name: getattr(res, name) for name in same},
        nis=_run_nis(res),
        joints=tuple(lib.manifest.joints),
        layout=dict(lib.layout),
        T=lib.T,
        run=res,
    )


def _run_log(res: RunResult) -> RobotLog:
    """A run's sensors as a read log (encoders, torque, frames as delivered, the truth)."""
    from amsfe_sym.core.camera_frame import CameraFrame
    from amsfe_sym.logs.read import RobotLog

    frames = [CameraFrame(int(kappa), np.array([u, v]), int(k)) for kappa, k, u, v in res.frames]
    return RobotLog(Path(f"<{res.scenario.name}>"), res.lib.T, 0, res.z_enc, res.u, frames)


def _run_nis(res: RunResult) -> FloatArray:
    """The encoder NIS of each tick of ``res``: its estimator run again over its own sensors
    (the same estimator, the same inputs: the same estimates, and each step's NIS, which
    the loops do not record)."""
    from amsfe_sym.logs.replay import estimate_log
    from amsfe_sym.sim.builders import build_run

    est = build_run(res.scenario, res.lib, compiled=res.runtime == "compiled").estimator
    return estimate_log(_run_log(res), est, progress=False).encoder_nis
