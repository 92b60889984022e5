"""The estimator and the controller tick by tick on samples as they arrive: what
``amsfe node`` computes, without any middleware (so the tests can drive it in process too).

Each encoder sample is placed on the tick grid by its header stamp (k = round((stamp -
stamp_0) / T), the first sample is tick 0).  At tick k > 0 the estimator goes k-1 -> k with
the torque applied over [t_k-1, t_k], the sample, and the camera frames that arrived since the
previous tick (each at its exposure tick, from its stamp): the order of
:func:`amsfe_sym.sim.loop.run` and :func:`amsfe_sym.logs.replay.estimate_log`.  Missing samples
(up to ``max_gap_steps`` in a row) are predicted through, as a log's gaps are.  Then the
controller computes u_k with the project's start-up (``controller.torque`` and
``saturate``, as the loop calls them).  What is skipped is counted under the reasons a log's
reader uses (:mod:`amsfe_sym.logs.read`).

The tick-0 estimate is built from the first sample (``[estimate0] motor = "encoders"``), as
:func:`amsfe_sym.sim.builders.build_estimator` builds it for the loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.control import Controller, LawInputs
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.errors import ConfigError, EstimatorError, describe
from amsfe_sym.estimation import Estimator
from amsfe_sym.estimation.base import StepReport
from amsfe_sym.estimation.effort import EffortSpec, encoder_row
from amsfe_sym.estimation.ekf import gate_threshold
from amsfe_sym.ros.effort import TorqueHold
from amsfe_sym.ros.live_stamps import StampScreen
from amsfe_sym.ros.tick import HoldKind, TickOut, Watched, hold_command
from amsfe_sym.ros.watchdog import Watchdog, WatchdogConfig, WatchdogTick
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.stability import STATUS_NOT_PD
from amsfe_sym.scenario import Scenario, run_ticks
from amsfe_sym.sim.builders import (
    build_controller,
    build_estimator,
    build_sensors,
    motor_params,
    scenario_timing,
)
from amsfe_sym.sim.result import DECISION_COUNTERS, count_decisions
from amsfe_sym.topics.watchdog import WatchdogBounds

__all__ = ["ORACLES", "LiveLoop"]

FloatArray = NDArray[np.float64]

#: Controllers that read the true state: no live node can run them.
ORACLES = ("truth", "truth-ct")


@dataclass
class _Frames:
    pending: list[CameraFrame] = field(default_factory=list)
    sent: list[int | None] = field(default_factory=list)  # source timestamps of ``pending``
    seen: set[int] = field(default_factory=set)


class LiveLoop:
    """The estimator (and the controller) of a scenario fed sample by sample.

    Args:
        sc: The scenario (estimator, ``[filter]``, ``[estimate0]``, controller, gains).
        lib: Its library.
        controller: Run the scenario's controller and produce commands.
        compiled: The library's C estimator (else the Python reference).
        grid_tolerance: How far a stamp may be from the tick grid [T].
        max_gap_steps: Missing encoder samples in a row predicted through.
        effort: What the effort topic is when it is not the applied torque (kinds
            ``joint_torque``, ``none``: :func:`amsfe_sym.ros.effort.live_effort`): the
            estimator is ``amsfe estimate``'s for a log of that kind (the input as states,
            each sample's row :func:`~amsfe_sym.estimation.effort.encoder_row` of the sample
            and the joint torque held at its tick, :meth:`joint_torque`); None: ``applied``.
        watchdog: The watchdogs' bounds (:meth:`watch` judges each sample by them); None:
            the defaults.
        exposure_shift: The camera's time offset in ticks (the topic spec's ``[camera]
            time_offset``): a frame stamped at tick k was exposed at tick k - exposure_shift.

    Raises:
        ConfigError: an oracle controller (it reads the true state), or what the builders
            refuse.
    """

    def __init__(
        self,
        sc: Scenario,
        lib: ModelLibrary,
        *,
        controller: bool,
        compiled: bool = True,
        grid_tolerance: float = 0.25,
        max_gap_steps: int = 5,
        effort: EffortSpec | None = None,
        watchdog: WatchdogBounds | None = None,
        exposure_shift: int = 0,
    ) -> None:
        self.sc, self.lib = sc, lib
        self._exposure_shift = exposure_shift
        self.n, self.N, self.T = lib.n, lib.N, lib.T
        self._T_ns = round(lib.T * 1e9)
        self._tol, self._max_gap = grid_tolerance, max_gap_steps
        self._compiled = compiled
        self.effort_spec = None if effort is None or effort.kind == "applied" else effort
        self._motor = motor_params(lib)
        self._torque = TorqueHold(self._T_ns)
        # the sensors only for R (their noise, quantization): no random number is drawn
        self._sensors = build_sensors(
            sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib)
        )
        self.ctrl: Controller | None = None
        if controller:
            if sc.controller in ORACLES or sc.gains_for().get("state") == "true":
                raise ConfigError(
                    describe(
                        f"controller {sc.controller!r} of a live node",
                        "a controller acting on the estimate or the encoders",
                        "an oracle (it reads the true state)",
                        "use --controller amsfe, dtsmc or dtsmc-ekf",
                    )
                )
            self.ctrl, _ = build_controller(sc, lib)
            K = run_ticks(sc, lib.T, lib.n, lib.N)
            self.ctrl.prepare(np.arange(K, dtype=float) * lib.T)  # the loop's grid
        # built once now (imports, the library's C estimator loaded: ~1 s the first time) and
        # again at the first sample, which then takes ~1 ms instead of holding the samples up
        build_estimator(
            sc, lib, self._sensors, np.zeros(2 * lib.n), compiled=compiled, effort=self.effort_spec
        )
        self.est: Estimator | None = None
        self.k = -1
        self.t0_ns = 0
        #: The torque applied over the last tick [N m] (the effort topic's, or the controller's).
        self.u = np.zeros(lib.n)
        self._frames = _Frames()
        self._effort: dict[int, FloatArray] = {}
        self._cmds: dict[int, FloatArray] = {}
        self._sent: int | None = None
        self._early: list[tuple[int, FloatArray]] = []
        self._early_frames: list[tuple[int, FloatArray, int | None]] = []
        self._sent0: int | None = None  # the first encoder sample's source timestamp [ns]
        self._stamps = StampScreen(lib.T, self._T_ns, max_gap_steps)  # the encoders' stamps
        self.counters: dict[str, int] = dict.fromkeys(DECISION_COUNTERS, 0)
        self.skipped: dict[str, int] = {}
        self._nan = np.full(4 * lib.n, np.nan)
        joint_torque = self.effort_spec is not None and self.effort_spec.kind == "joint_torque"
        #: The watchdogs (:meth:`watch`; ros/watchdog.py).
        self.watchdog = Watchdog(
            WatchdogConfig(
                lib.n,
                lib.N,
                (3 if joint_torque else 2) * lib.n,
                lib.T,
                watchdog or WatchdogBounds(),
                max_gap_steps,
                tuple(lib.manifest.actuators.u_max),
            )
        )
        #: The newest (by tick) applied torque received since the last watched sample: the
        #: watchdog's ``actuation`` check (also when it came too late for the estimator).
        self._wd_applied: tuple[int, FloatArray] | None = None
        self._gate_camera = gate_threshold(sc.filter.gate_probability or None, 2)

    def _skip(self, reason: str, count: int = 1) -> None:
        self.skipped[reason] = self.skipped.get(reason, 0) + count

    def tick_of(self, stamp_ns: int) -> int | None:
        """The tick of a stamp [ns] (None when it is off the grid by more than the
        tolerance); before the first sample: None."""
        if self.k < 0:
            return None
        rel = stamp_ns - self.t0_ns
        k = round(rel / self._T_ns)
        return k if abs(rel - k * self._T_ns) <= self._tol * self._T_ns else None

    def frame(self, exposure_ns: int, z: FloatArray, sent_ns: int | None = None) -> None:
        """A camera frame arrived: pixel ``z`` [px], exposed at ``exposure_ns`` [ns], sent
        by its publisher at ``sent_ns`` (its source timestamp; None: unknown); it is fused at
        the first encoder sample sent at or after it (the next one when either is unknown),
        or skipped, counted by reason.

        A frame sent before the first encoder sample is skipped (the loop fuses no frame at
        tick 0) whichever callback the middleware ran first: DDS does not order callbacks
        across topics, so a frame that arrives before the first sample waits for it (as an
        early torque sample does, :meth:`applied`) and is then judged by its source
        timestamp (unknown: skipped, it came first)."""
        if self.k < 0:
            self._early_frames.append((exposure_ns, np.array(z, dtype=float), sent_ns))
            return
        if sent_ns is not None and self._sent0 is not None and sent_ns <= self._sent0:
            self._skip("frame exposed before the first encoder sample")
            return
        kappa = self.tick_of(exposure_ns)
        if kappa is not None:  # the camera's time offset ([camera] time_offset) in ticks
            kappa -= self._exposure_shift
        if kappa is None:
            self._skip("frame exposure off the tick grid")
        elif kappa < 0:
            self._skip("frame exposed before the first encoder sample")
        elif not np.all(np.isfinite(z)):
            self._skip("frame with a non-finite pixel")
        elif kappa in self._frames.seen:
            self._skip("frame duplicated (an exposure already seen)")
        else:
            self._frames.seen.add(kappa)
            self._frames.pending.append(CameraFrame(kappa, np.array(z, dtype=float)))
            self._frames.sent.append(sent_ns)

    def applied(self, stamp_ns: int, u: FloatArray) -> None:
        """The torque [N m] applied over [t_j, t_j+1], j the tick of ``stamp_ns`` (an effort
        topic of kind ``applied``): the step j -> j+1 uses it rather than the controller's
        command (a command applied late or not at all is what the arm did) if it arrives
        before the sample of j+1 is estimated (after: counted; before the first sample: it
        waits for it)."""
        if self.k < 0:
            self._early.append((stamp_ns, np.array(u, dtype=float)))
            return
        j = self.tick_of(stamp_ns)
        if j is None:
            self._skip("torque sample off the tick grid")
        elif np.size(u) != self.n or not np.all(np.isfinite(u)):
            self._skip("torque sample not n finite values")
        elif j < self.k:
            self._for_watchdog(j, u)
            self._skip("torque sample after its tick was estimated")
        else:
            self._effort[j] = np.array(u, dtype=float)
            self._for_watchdog(j, u)

    def _for_watchdog(self, j: int, u: FloatArray) -> None:
        """Keep the applied torque of tick ``j`` for the watchdog if it is the newest."""
        if j >= 0 and (self._wd_applied is None or j >= self._wd_applied[0]):
            self._wd_applied = (j, np.array(u, dtype=float))

    def effort(self, stamp_ns: int, values: FloatArray) -> None:
        """An effort sample stamped ``stamp_ns`` [ns]: :meth:`joint_torque` for kind
        ``joint_torque``, ignored (counted) for ``none``, else :meth:`applied`."""
        kind = "applied" if self.effort_spec is None else self.effort_spec.kind
        if kind == "joint_torque":
            self.joint_torque(stamp_ns, values)
        elif kind == "none":  # the log reader's reason
            self._skip("not used: effort kind none (say [effort] kind to use it)")
        else:
            self.applied(stamp_ns, values)

    def joint_torque(self, stamp_ns: int, tau: FloatArray) -> None:
        """A measured joint torque [as logged] stamped ``stamp_ns`` (effort kind
        ``joint_torque``): fused with the encoder samples of the ticks it is held at
        (:class:`~amsfe_sym.ros.effort.TorqueHold`)."""
        if np.size(tau) != self.n or not np.all(np.isfinite(tau)):
            self._skip("joint torque sample not n finite values")
        else:
            self._torque.add(stamp_ns, np.asarray(tau, dtype=float))

    def _row(self, z: FloatArray, k: int, t0_ns: int) -> FloatArray | None:
        """The estimator's encoder row of sample ``z`` at tick ``k``
        (:func:`~amsfe_sym.estimation.effort.encoder_row`); None: no joint torque yet."""
        if self.effort_spec is None or self.effort_spec.kind != "joint_torque":
            return z
        tau = self._torque.at(t0_ns, k)
        return None if tau is None else encoder_row(self.effort_spec, z, tau, self._motor)

    def _u_for(self, j: int) -> FloatArray:
        """The torque over [t_j, t_j+1]: the effort topic's of tick j (what the arm says it
        applied), else the controller's command of tick j, else the previous one (held and
        counted)."""
        if self.effort_spec is not None:  # the input is estimated (states): none given
            return np.zeros(self.n)
        if j in self._effort:
            self.u = self._effort.pop(j)
        elif j in self._cmds:
            self.u = self._cmds[j]
        else:
            self._skip("torque held from the previous tick")
        for old in [i for i in self._effort if i < j]:
            del self._effort[old]
        for old in [i for i in self._cmds if i <= j]:
            del self._cmds[old]
        return self.u

    def encoders(self, stamp_ns: int, z: FloatArray, sent_ns: int | None = None) -> TickOut | None:
        """An encoder sample [qm [rad], qmd [rad/s]] stamped ``stamp_ns`` (sent at
        ``sent_ns``: see :meth:`frame`): the estimate (and command) of its tick, or None when
        it is skipped (off the grid, duplicated or older than the last: counted).

        Raises:
            EstimatorError: more than ``max_gap_steps`` samples missing before this one (the
                node holds), or the estimator failed.
        """
        z = np.array(z, dtype=float)
        self._sent = sent_ns
        if self.est is None:
            row = self._row(z, 0, stamp_ns)
            if row is None:  # a log starts at its first effort sample too
                self._skip("encoder sample before the first joint torque sample")
                return None
            self.t0_ns, self.k, self._sent0 = stamp_ns, 0, sent_ns
            self._stamps.last_sent = sent_ns
            self.est = build_estimator(
                self.sc,
                self.lib,
                self._sensors,
                row[: 2 * self.n],
                compiled=self._compiled,
                effort=self.effort_spec,
            )
            self._frames.pending.clear()  # the loop uses no frame at tick 0
            self._frames.sent.clear()
            for early in self._early:
                self.applied(*early)
            self._early.clear()
            for exposure_ns, zf, sent in self._early_frames:
                if sent is None or sent_ns is None:
                    self._skip("frame exposed before the first encoder sample")
                else:
                    self.frame(exposure_ns, zf, sent)
            self._early_frames.clear()
            return self._control(stamp_ns, row[: 2 * self.n], None, 0)
        # named, not "stalled"
        bad = self._stamps.check(stamp_ns, sent_ns, self.t0_ns, self.k, self._skip)
        if bad is not None:
            return None
        k = self.tick_of(stamp_ns)
        if k is None:
            self._skip("encoder sample off the tick grid")
            return None
        if k <= self.k:
            self._skip("encoder sample duplicated")
            return None
        gap = k - self.k - 1
        if gap > self._max_gap:
            raise EstimatorError(
                describe(
                    f"encoder sample at t = {k * self.T:.3f} s",
                    f"at most max_gap_steps = {self._max_gap} missing samples before it",
                    f"{gap} missing",
                    "the arm's encoders stalled: check the driver (or raise [timing] "
                    "max_gap_steps in the topic spec)",
                )
            )
        for _ in range(gap):  # predicted through, as a log's gaps are
            self.k += 1
            count_decisions(
                self.counters, self.est.step(self._u_for(self.k - 1), None, self._due())
            )
        if gap:
            self._skip("encoder samples missing (predicted through)", gap)
        self.k = k
        row = self._row(z, k, self.t0_ns)
        assert row is not None  # the first sample had a torque: it is held from then on
        zk = row if np.all(np.isfinite(row)) else None
        report = self.est.step(self._u_for(k - 1), zk, self._due())
        count_decisions(self.counters, report)
        return self._control(stamp_ns, row[: 2 * self.n], report, gap)

    def watch(
        self,
        stamp_ns: int,
        z: FloatArray,
        sent_ns: int | None = None,
        *,
        taken: float,
        clock: Callable[[], float],
    ) -> Watched:
        """:meth:`encoders`, then the watchdogs' decision on it (ros/watchdog.py): the
        sample was taken at wall clock ``taken`` [s], ``clock()`` [s] (the same clock) is read
        when its command is computed.  An estimator failure, or more than ``max_gap_steps``
        samples missing, is judged as such (a hold) rather than raised; a skipped sample is
        not judged.  More than ``max_gap_steps`` bad stamps in a row raise the stamps'
        :class:`~amsfe_sym.errors.EstimatorError`, which names them.  The
        watchdog's stamp is ``sent_ns`` when known (the deadline is this node's delay, whatever
        the arm's clock), else ``stamp_ns``."""
        k_before = self.k
        k_new = self.tick_of(stamp_ns)
        status = 0
        try:
            out = self.encoders(stamp_ns, z, sent_ns)
        except EstimatorError:
            if self._stamps.bad_run > self._stamps.max_gap:  # the stamps, named (as the C node)
                raise
            out, status = None, self._status()
        done = clock()
        sent = stamp_ns if sent_ns is None else sent_ns
        if out is None and status == 0:
            return Watched(None, self.watchdog.reason)
        # the newest applied torque since the last judged sample (the C node's order)
        applied, self._wd_applied = self._wd_applied, None
        if out is None:  # failed: at the tick of the sample, with the gap it had
            k = k_before + 1 if k_new is None else k_new
            tick = WatchdogTick(k, k - k_before - 1, sent, taken, done, status)
            return Watched(None, self.watchdog.sample(tick), tick)
        rep = out.report
        q_des = handed = None
        if self.ctrl is not None:
            q_des = self.ctrl.reference(out.k, out.t)[0]
            handed = self.ctrl.handed_over(out.k)
        enc = math.nan
        if rep is not None and rep.encoder_accepted and rep.encoder_nis is not None:
            enc = float(rep.encoder_nis)
        frames = () if rep is None else tuple(v for v in rep.frame_nis if v <= self._gate_camera)
        tick = WatchdogTick(
            out.k,
            out.predicted,
            sent,
            taken,
            done,
            0,
            out.x_hat,
            out.P_diag,
            q_des,
            out.u,
            bool(handed),
            enc,
            frames,
            None if applied is None else applied[1],
            -1 if applied is None else applied[0],
        )
        return Watched(out, self.watchdog.sample(tick), tick)

    def _status(self) -> int:
        """The estimator's error status (the C runtime's; the Python reference's failures
        are a covariance that lost definiteness: AMSFE_ERR_NOT_PD)."""
        diagnostics = getattr(self.est, "diagnostics", None)
        if diagnostics is not None:
            status = int(diagnostics().last_error)
            if status < 0:
                return status
        return STATUS_NOT_PD

    def _due(self) -> list[CameraFrame]:
        """The pending frames exposed at or before the current tick and sent before its
        sample, delivered now."""
        due, keep, sent = [], [], []
        for f, s in zip(self._frames.pending, self._frames.sent, strict=True):
            before = s is None or self._sent is None or s <= self._sent
            if f.exposure_step <= self.k and before:
                due.append(CameraFrame(f.exposure_step, f.z, self.k))
            else:
                keep.append(f)
                sent.append(s)
        self._frames.pending, self._frames.sent = keep, sent
        return due

    def _control(
        self, stamp_ns: int, z: FloatArray, report: StepReport | None, gap: int
    ) -> TickOut:
        assert self.est is not None
        N = self.N  # the robot's states (the input states, if any, follow)
        x, P = self.est.x[:N], self.est.P
        P_diag = np.diag(P)[:N].copy()
        t = float(self.k) * self.T
        u = None
        if self.ctrl is not None:
            nis = None if report is None else report.encoder_nis  # the start-up's consistency
            law = LawInputs(self.k, t, self._nan, self._nan[: self.lib.p], x, z, P_diag, nis)
            u, _ = self.ctrl.saturate(self.ctrl.torque(law))
            if self.effort_spec is None:  # else no command is the estimator's input
                self._cmds[self.k] = np.array(u, dtype=float)
        return TickOut(self.k, t, stamp_ns, np.array(x, dtype=float), P_diag, u, report, gap)

    def hold_command(self, kind: HoldKind, last: TickOut | None) -> FloatArray:
        """The fail-safe command (:data:`HoldKind`) at the last finite estimate ``last``."""
        return hold_command(self.lib, kind, last, self.ctrl)
