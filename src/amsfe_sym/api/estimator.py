"""The public API's estimator: :class:`Estimator` over a whole recording
(:meth:`Estimator.run`, ``amsfe estimate``'s numbers) or sample by sample
(:meth:`Estimator.step`, :meth:`Estimator.camera`: the live node's path); docs/api.md."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.api.recordings import LogArrays
from amsfe_sym.api.scenarios import load_scenario
from amsfe_sym.errors import ShapeError, describe

if TYPE_CHECKING:
    from amsfe_sym.ros.live import LiveLoop
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import Scenario
    from amsfe_sym.topics.spec import TopicSpec

__all__ = ["EstimateArrays", "Estimator", "StepResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class EstimateArrays:
    """An estimator over a whole recording (:meth:`Estimator.run`), K ticks.

    Attributes:
        t: Tick times [s], (K,).
        x_hat: The estimate x(k|k) (eq. 2), (K, N).
        P_diag: The diagonal of P(k|k) [state unit^2], (K, N).
        nis: The encoder update's NIS per tick (chi-square with 2 n degrees of freedom
            when the model fits), (K,); NaN where no sample reached it.
        frame_nis: Each camera frame's NIS (2 degrees of freedom), (F,); NaN: not updated.
        frame_fused: Whether each frame was fused, (F,).
        nees: e^T P^-1 e against the log's truth, (K,), or None without one.
        layout: Where each block of the state is (keys ``q``, ``qd``, ``qm``, ``qmd``,
            ``theta``).
        counters: The estimator's decisions (frames applied, refused by reason) and the
            reader's skipped messages.
    """

    t: FloatArray
    x_hat: FloatArray
    P_diag: FloatArray
    nis: FloatArray
    frame_nis: FloatArray
    frame_fused: NDArray[np.bool_]
    nees: FloatArray | None
    layout: dict[str, slice]
    counters: dict[str, int]

    @property
    def q_hat(self) -> FloatArray:
        """Estimated link angles [rad], (K, n)."""
        return self.x_hat[:, self.layout["q"]]

    @property
    def q_std(self) -> FloatArray:
        """1-sigma of the estimated link angles [rad], (K, n)."""
        return np.sqrt(self.P_diag[:, self.layout["q"]])


@dataclass(frozen=True)
class StepResult:
    """One encoder sample through :meth:`Estimator.step`.

    Attributes:
        k: Its tick (0 for the first sample).
        t: t_k = k T from the first sample [s].
        x_hat: x(k|k) (eq. 2), (N,).
        P_diag: diag P(k|k), (N,).
        q_hat: Estimated link angles [rad], (n,).
        nis: The encoder update's NIS, or None (tick 0, a rejected sample).
        frames_applied: Camera frames fused in this step.
        frames_rejected: Camera frames refused in this step.
        predicted: Missing ticks predicted through before this one.
    """

    k: int
    t: float
    x_hat: FloatArray
    P_diag: FloatArray
    q_hat: FloatArray
    nis: float | None
    frames_applied: int
    frames_rejected: int
    predicted: int


class Estimator:
    """The estimator of a scenario or of a robot's recordings: a whole recording in one call
    (:meth:`run`, the compiled batch ``amsfe estimate`` runs) or sample by sample
    (:meth:`step` and :meth:`camera`, for live use).

    Build one with :meth:`for_scenario` or :meth:`for_log`.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        robot_defaults: bool,
        kind: str | None,
        spec: TopicSpec | None,
    ) -> None:
        self.scenario = scenario
        self._robot_defaults = robot_defaults
        self._kind = kind
        self._spec = spec
        self._live: LiveLoop | None = None
        self._lib: ModelLibrary | None = None
        self._q_last: FloatArray | None = None

    @classmethod
    def for_scenario(
        cls, scenario: str | os.PathLike[str] | Scenario = "paper-sim", kind: str = "oosm"
    ) -> Estimator:
        """The estimator of a scenario: its ``[filter]``, its ``[estimate0]`` (motor states
        from the first encoder sample), the sensor noise of its ``[encoders]`` and
        ``[camera]`` as R (``amsfe estimate LOG --scenario FILE --estimator KIND``).

        Args:
            scenario: A scenario's name or path, or a Scenario (:func:`load_scenario`).
            kind: ``oosm`` (the paper's), ``replay``, ``cloning``, ``naive`` or ``encoders``.
        """
        sc = load_scenario(scenario).with_overrides(estimator=kind)
        return cls(sc, robot_defaults=False, kind=kind, spec=None)

    @classmethod
    def for_log(
        cls,
        robot: str | os.PathLike[str],
        kind: str | None = None,
        spec: str | os.PathLike[str] | None = None,
    ) -> Estimator:
        """The estimator ``amsfe estimate LOG --robot ROBOT`` runs: the filter's defaults
        for a real arm's log, started from the recording's first sample.

        Args:
            robot: A shipped robot's name or a ``robot.toml``.
            kind: The estimator (``oosm``, ``replay``, ...); None: ``oosm``, or ``replay``
                when the effort is not the applied torque (as the command chooses).
            spec: A topic spec TOML (``--log-spec``: its ``[effort]``, ``[filter]`` and
                ``[joints]``); None: the log's own (:func:`read_log`'s ``topics``).
        """
        from amsfe_sym.apps.estimate import default_scenario
        from amsfe_sym.topics.spec import read_topic_spec

        sc = default_scenario(str(robot))
        if kind is not None:
            sc = sc.with_overrides(estimator=kind)
        topic_spec = None if spec is None else read_topic_spec(spec)
        return cls(sc, robot_defaults=True, kind=kind, spec=topic_spec)

    # ------------------------------------------------------------------ a whole recording
    def run(self, log: LogArrays) -> EstimateArrays:
        """The estimator over a whole recording: the same numbers as ``amsfe estimate`` on
        it (the filter settled for the log, the compiled estimator in one batch call).

        Args:
            log: The recording (:func:`read_log`, :meth:`LogArrays.from_arrays`).

        Returns:
            The :class:`EstimateArrays`.

        Raises:
            ConfigError: a setting the filter or the builders refuse (e.g. a log of
                another robot's joint count).
            EstimatorError: the estimator failed numerically.
        """
        from amsfe_sym.apps.estimate import effort_options, estimator_for_log
        from amsfe_sym.logs.replay import estimate_log

        spec = self._spec or log.spec
        effort = effort_options(spec, None if spec.source is None else str(spec.source))
        built = estimator_for_log(
            self.scenario,
            log.source,
            spec,
            effort,
            robot_defaults=self._robot_defaults,
            estimator_given=self._kind is not None,
            derived=log.derived,
            compiled=True,
        )
        self._check_joints(built.lib.n, log.q_motor.shape[1])
        res = estimate_log(built.feed, built.estimator, states=built.lib.N, progress=False)
        return EstimateArrays(
            t=log.t,
            x_hat=res.x_hat,
            P_diag=res.P_diag,
            nis=res.encoder_nis,
            frame_nis=res.frame_nis.nis,
            frame_fused=res.frame_nis.fused,
            nees=res.nees,
            layout=dict(built.lib.layout),
            counters=dict(res.counters),
        )

    @staticmethod
    def _check_joints(n: int, found: int) -> None:
        if found != n:
            raise ShapeError(
                describe(
                    "the recording's encoder columns",
                    f"{n} (the robot's joints)",
                    f"{found}",
                    "estimate it with its own robot",
                )
            )

    # ------------------------------------------------------------------ live
    def _loop(self, effort_kind: str) -> LiveLoop:
        if self._live is None:
            from amsfe_sym.apps.estimate_filter import INPUT_UNKNOWN_ESTIMATOR, ROBOT_TORQUE_STD
            from amsfe_sym.codegen import library_for
            from amsfe_sym.ros.effort import live_effort
            from amsfe_sym.ros.live import LiveLoop
            from amsfe_sym.ros.spec_filter import live_filter
            from amsfe_sym.topics.spec import read_topic_spec

            spec = self._spec or read_topic_spec(None)
            if spec.effort_kind is None and effort_kind != "applied":
                spec = replace(spec, effort_kind=effort_kind)  # type: ignore[arg-type]
            kind = spec.effort_kind or "applied"
            sc = self.scenario
            if self._robot_defaults and kind != "applied":
                sc = replace(
                    sc,
                    filter=replace(
                        sc.filter,
                        link_torque_std=ROBOT_TORQUE_STD,
                        motor_torque_std=ROBOT_TORQUE_STD,
                    ),
                )
                if self._kind is None:
                    sc = sc.with_overrides(estimator=INPUT_UNKNOWN_ESTIMATOR)
            sc = live_filter(sc, spec)
            self._lib = library_for(sc)
            self._live = LiveLoop(
                sc,
                self._lib,
                controller=False,
                compiled=True,
                grid_tolerance=spec.grid_tolerance,
                max_gap_steps=spec.max_gap_steps,
                effort=live_effort(spec),
            )
        return self._live

    def step(
        self,
        t: float,
        q_motor: ArrayLike,
        effort: ArrayLike | None = None,
        *,
        qd_motor: ArrayLike | None = None,
        effort_kind: str = "applied",
    ) -> StepResult | None:
        """One encoder sample, as it arrives (the live node's path: ``amsfe node``).

        The first sample is tick 0 (the estimate starts from it); each later one goes on
        the tick grid by its time, missing ticks predicted through, with the camera frames
        given by :meth:`camera` since the last sample.

        Args:
            t: The sample's time [s] (any origin, the clock of :meth:`camera`'s times).
            q_motor: Motor angles [rad], (n,).
            effort: The torque at this sample [N m], (n,), held over [t, t + T]; None: the
                last one held (zero before any).
            qd_motor: Motor rates [rad/s], (n,); None: the difference to the previous sample
                over T (zero at the first).
            effort_kind: What ``effort`` is (``applied``, ``joint_torque``, ``none``); fixed
                by the first call.

        Returns:
            The :class:`StepResult`, or None when the sample was skipped (off the grid,
            duplicated or older than the last).

        Raises:
            EstimatorError: more samples missing in a row than the spec's
                ``max_gap_steps``, or the estimator failed numerically.
        """
        loop = self._loop(effort_kind)
        n = loop.n
        q = np.asarray(q_motor, dtype=np.float64).reshape(-1)
        if q.size != n:
            raise ShapeError(describe("q_motor", f"shape ({n},)", f"shape {q.shape}", "n values"))
        if qd_motor is not None:
            qd = np.asarray(qd_motor, dtype=np.float64).reshape(-1)
        elif loop.est is None or self._q_last is None:
            qd = np.zeros(n)
        else:
            qd = (q - self._q_last) / loop.T
        stamp = round(float(t) * 1e9)
        if effort is not None:
            loop.effort(stamp, np.asarray(effort, dtype=np.float64).reshape(-1))
        out = loop.encoders(stamp, np.concatenate([q, qd]))
        self._q_last = q
        if out is None:
            return None
        L = self._lib.layout if self._lib is not None else {"q": slice(0, n)}
        rep = out.report
        return StepResult(
            k=out.k,
            t=out.t,
            x_hat=out.x_hat,
            P_diag=out.P_diag,
            q_hat=out.x_hat[L["q"]].copy(),
            nis=None if rep is None else rep.encoder_nis,
            frames_applied=0 if rep is None else rep.frames_applied,
            frames_rejected=0 if rep is None else rep.frames_rejected,
            predicted=out.predicted,
        )

    def camera(self, t_exposure: float, uv: ArrayLike) -> None:
        """A camera frame: the pixel ``uv`` [px] of the tracked point, exposed at
        ``t_exposure`` [s] (the clock of :meth:`step`'s times).  It is fused with the next
        encoder sample (late frames are the point of the out-of-sequence update: the
        estimator goes back to the exposure tick)."""
        loop = self._loop("applied")
        z = np.asarray(uv, dtype=np.float64).reshape(-1)
        if z.size != 2:
            raise ShapeError(describe("uv", "shape (2,) [px]", f"shape {z.shape}", "[u, v]"))
        loop.frame(round(float(t_exposure) * 1e9), z)
