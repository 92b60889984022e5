"""The paper's discrete terminal sliding mode controllers, on the generated laws.

Each class reads its inputs (the fusion estimate, the encoders, or the true state), calls one
generated law of :mod:`amsfe_sym.symbolic.control` (the maths lives there, once), and keeps
the little memory the law needs between ticks.  docs/explanation/control.md derives the laws and
says
why the printed ones fail on the paper's arm.

========================  =======================  ======================================
name                      law                      reads
========================  =======================  ======================================
``amsfe-paper``           (37) as printed          the fusion estimate x(k|k) (printed.py)
``dtsmc-paper``           (54) as printed          motor encoders (printed.py)
``amsfe``                 cascade on (31)-(34)     the fusion estimate x(k|k)
``dtsmc``                 cascade, surface of (54) motor encoders, planned deflection removed
``dtsmc-ekf``             cascade, surface of (54) the run's estimate (``encoders``: no camera)
``truth``                 ``amsfe``                the true state and theta (an oracle)
========================  =======================  ======================================

Gains (``[controller_gains]`` of a scenario; scalars apply to every joint): ``h``, ``lam``,
``Lt``, ``eps`` (eqs. 31-34), ``p`` (the terminal power p1/p2), ``phi`` (boundary-layer width
of sat(s/phi); 0 is the paper's sgn), and for the cascades ``wm`` (motor-loop bandwidth
[rad/s]) and ``tau_max`` (largest spring torque the link loop may ask for [N m]; default the
actuator limit).  They are inputs of the generated code: changing one never recompiles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.control.base import Controller, LawInputs, handed_over, register
from amsfe_sym.control.blend import blend_offsets, blend_through, blend_time, blend_weight
from amsfe_sym.errors import ConfigError, check_known_keys, describe, unknown_name
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.signals.trajectory import Trajectory

__all__ = ["PAPER_GAINS", "Amsfe", "Dtsmc", "DtsmcEstimate", "Truth"]

#: The paper's gains (Sec. 5.1): h, lam, Lt, eps, p = 3/5; phi = 0 is its sgn.
PAPER_GAINS: dict[str, Any] = {
    "h": 2.0,
    "lam": 1.5,
    "Lt": 5.0,
    "eps": 25.0,
    "p": 0.6,
    "phi": 0.0,
    "xi_M": 3.0,  # bounds of (38)-(39), used only to evaluate the conditions along a run
    "xi_F": 1.0,
}
_LAW_GAINS = ("h", "lam", "Lt", "eps", "p", "phi")


class _SlidingBase(Controller):
    """Gain parsing and the call of one generated law."""

    law: ClassVar[str]

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(lib, trajectory, gains)
        n = lib.n
        self.n, self.T = n, lib.T
        self._g: dict[str, FloatArray] = {}
        for key in (*_LAW_GAINS, *self._extra_gains()):
            self._g[key] = self._gain(key, 1 if key == "p" else n)
        p = float(self._g["p"][0])
        if not 0.0 < p <= 1.0:
            raise ConfigError(
                describe(
                    f"controller {self.name!r} gain p",
                    "a terminal power p1/p2 in (0, 1]",
                    repr(p),
                    "use 0.6 (p1 = 3, p2 = 5, Sec. 5.1)",
                )
            )
        self._law = lib.function(self.law)
        self._mm = np.array(lib.manifest.actuators.Mm, dtype=float)
        self._fm = np.array(lib.manifest.actuators.Fm, dtype=float)

    def _extra_gains(self) -> tuple[str, ...]:
        return ()

    def _choice(self, key: str, choices: tuple[str, ...], fix: str) -> None:
        """Refuse a word-valued gain ``key`` that is not one of ``choices``."""
        value = self.gains[key]
        if value not in choices:
            raise unknown_name(f"controller {self.name!r} gain {key}", value, choices, fix)

    def _gain(self, key: str, size: int) -> FloatArray:
        raw = self.gains[key]
        try:
            v = np.broadcast_to(np.asarray(raw, dtype=float), (size,)).copy()
        except (TypeError, ValueError) as exc:
            raise ConfigError(
                describe(
                    f"controller {self.name!r} gain {key}",
                    f"a number or {size} numbers",
                    repr(raw),
                    "give one value, or one per joint",
                )
            ) from exc
        low_ok = v > 0 if key == "wm" else v >= 0
        if not (np.all(np.isfinite(v) | (key == "tau_max")) and np.all(low_ok)):
            raise ConfigError(
                describe(
                    f"controller {self.name!r} gain {key}",
                    "finite values >= 0 (wm > 0)",
                    repr(raw),
                    "see docs/explanation/control.md for each gain",
                )
            )
        return v

    def set_gains(self, **gains: Any) -> None:
        """Change gains at run time (no regeneration: gains are inputs of the compiled law)."""
        check_known_keys(f"controller {self.name!r} gains", gains, self._g)
        self.gains.update(gains)
        for key in gains:
            self._g[key] = self._gain(key, 1 if key == "p" else self.n)

    def law_gains(self) -> dict[str, FloatArray]:
        """The gains as the generated law takes them (per joint; ``p`` one value), copies."""
        return {k: v.copy() for k, v in self._g.items()}

    def c_parameters(self) -> dict[str, Any] | None:
        gains = self.law_gains()
        p = float(gains.pop("p")[0])
        return {
            "gains": gains,
            "p": p,
            "qmd_next_hold": self.gains.get("qmd_next") == "hold",  # the printed laws
            "state_true": self.gains.get("state") == "true",  # amsfe-paper's oracle reading
        }

    #: Whether the generated law takes Lt (the baselines fix it to 0: the surface of (54)).
    has_lt: ClassVar[bool] = True

    def _gain_names(self) -> tuple[str, ...]:
        """The generated law's gain inputs, in its order."""
        return tuple(k for k in (*_LAW_GAINS, *self._extra_gains()) if self.has_lt or k != "Lt")

    def _gain_args(self) -> list[FloatArray]:
        return [self._g[k] for k in self._gain_names()]


class _Cascade(_SlidingBase):
    """The cascaded laws: terminal sliding mode on the link, motor loop with feedforward."""

    gain_defaults: ClassVar[dict[str, Any]] = {
        **PAPER_GAINS,
        "phi": 5.0,
        "wm": 20.0,
        "tau_max": None,
        "wf": 50.0,
        "vmax": 3.0,
        "startup": "converged",
        "ready_q_std": 0.03,
        "ready_qd_std": float("inf"),
        "ready_nis": float("inf"),
        "ready_nis_window": 50.0,
        "hold": "reference",
        "blend_accel": float("inf"),
        "blend_rate": float("inf"),
        "blend_wf": float("inf"),
        "headroom_tau": float("inf"),
        "blend_lead": 0.0,
    }
    #: The gains ``headroom_tau`` scales by the actuators' headroom (the loops' bandwidths and
    #: the reaching law's gains).
    HEADROOM_GAINS: ClassVar[tuple[str, ...]] = ("h", "eps", "wm", "wf")
    #: The start-ups (docs/explanation/control.md, "Start-up"): ``"first"`` starts the command
    #: filter at
    #: rest on the first command, whatever the estimate (the form the paper's laws imply);
    #: ``"converged"`` waits until the estimate is fit for the law: every link angle's and
    #: rate's posterior standard deviation below ``ready_q_std`` [rad] and ``ready_qd_std``
    #: [rad/s], and the filter consistent: the mean NIS of the encoder innovations over the
    #: last ``ready_nis_window`` ticks (a running mean, then an exponential window of that
    #: many ticks) at most ``ready_nis`` (its expected value is 2n, the encoders' dimension).
    #: Meanwhile the motor is held (``hold``): ``"reference"`` tracks the reference's motor
    #: trajectory offset to where the motor was at the first tick; ``"motor"`` starts from
    #: the motor's own angle and rate (the encoders need no convergence) and joins the
    #: reference's motor trajectory within the blend's budget; ``"auto"``: ``"motor"`` when
    #: the estimator's model is the paper's (``integrator = "paper"``, whose filter takes
    #: ~0.3 s to pass the rate test), else ``"reference"`` (docs/explanation/control.md measures
    #: both).
    #: Then the filter starts at rest on the first trusted command, as it would with the
    #: true state.
    #: With ``blend_accel`` [rad/s^2] finite, the reference then starts from the state the law
    #: acts on and joins q_d within that offset acceleration, and within ``blend_accel *
    #: blend_rate`` of jerk and ``* blend_rate^2`` of snap (:mod:`amsfe_sym.control.blend`).
    #: With ``blend_wf`` [rad/s] below ``wf``, the command filter's bandwidth is ``blend_wf``
    #: at the trusted tick and returns to ``wf`` along the blend (``wf + (blend_wf - wf)
    #: b0(s / Tb)``, b0 the blend's polynomial): the law's first commands, computed from a
    #: rate estimate still ~0.3 rad/s off, reach the motor smoothed
    #: (docs/explanation/control.md "Start-up").
    #: With ``headroom_tau`` [s] finite, the hand-over is saturation-aware: while the blend
    #: runs, with ``r = min_j min(1, u_max_j / |u_j(k-1)|)`` the share of the last tick's
    #: torque demand the actuators could apply (after it, r = 1), ``h``, ``eps``, ``wm`` and
    #: ``wf`` are scaled by ``rho``, which drops to ``r`` at once and returns towards it with
    #: time constant ``headroom_tau`` (``rho += T / headroom_tau (r - rho)``): a demand the
    #: actuators cannot meet lowers the loops' bandwidths on every joint alike, so the law
    #: asks what they can apply instead of winding the flexible mode into a saturated
    #: oscillation (docs/explanation/control.md "Start-up").
    #: With ``blend_lead`` in (0, 1] the blend is planned as if it had started that share of
    #: the wait before the trusted tick (1: at the loop's first tick), through the trusted
    #: estimate at the trusted tick (:func:`~amsfe_sym.control.blend.blend_through`): the
    #: wait spends the blend's flat start instead of adding the offset the arm drifted
    #: meanwhile to the one the blend must return; 0: planned from the trusted tick
    #: (docs/explanation/control.md, "Start-up: the blend planned before the trusted tick").
    STARTUPS: ClassVar[tuple[str, ...]] = ("first", "converged")
    HOLDS: ClassVar[tuple[str, ...]] = ("reference", "motor", "auto")

    def _extra_gains(self) -> tuple[str, ...]:
        return ("wm", "tau_max", "wf", "vmax")

    def __init__(
        self, lib: ModelLibrary, trajectory: Trajectory, gains: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(lib, trajectory, gains)
        self._cf = np.zeros(2 * lib.n)
        self._started = False
        self._ready = False
        self._c_hold: FloatArray | None = None
        self._m_hold: tuple[int, float, FloatArray, FloatArray] | None = None
        self._hold, self._run = np.ones(lib.n), np.zeros(lib.n)  # the law's ``hold`` input
        self._choice("startup", self.STARTUPS, "see docs/explanation/control.md, Start-up")
        self._ready_std = (
            self._scalar("ready_q_std"),
            self._scalar("ready_qd_std"),
        )
        self._ready_nis = self._scalar("ready_nis")
        self._nis_window = self._scalar("ready_nis_window")
        self._nis_mean, self._nis_count = 0.0, 0
        self._choice("hold", self.HOLDS, "see docs/explanation/control.md, Start-up")
        self._mref = lib.function("control_motor_reference")
        if self.gains["hold"] == "auto":  # the motor hold for the paper's model (long waits)
            self.gains["hold"] = "motor" if lib.manifest.integrator == "paper" else "reference"
        self._blend_accel = self._scalar("blend_accel")
        self._blend_rate = self._scalar("blend_rate")
        self._blend_wf = self._scalar("blend_wf")
        lead = self.gains["blend_lead"]
        if isinstance(lead, bool) or not isinstance(lead, int | float) or not 0 <= lead <= 1:
            raise ConfigError(
                describe(
                    f"controller {self.name!r} gain blend_lead",
                    "a number in [0, 1] (0: off)",
                    repr(lead),
                    "see docs/explanation/control.md, Start-up",
                )
            )
        self._blend_lead = float(lead)
        self._k_first: int | None = None  # the loop's first tick (blend_lead)
        # the blend: its first tick k0, s at k0 [s], Tb, d0, d1
        self._blend: tuple[int, float, float, FloatArray, FloatArray] | None = None
        self._headroom_tau = self._scalar("headroom_tau")
        self._rho = 1.0  # the headroom scale of the gains (1: unscaled)
        self._u_demand: FloatArray | None = None  # the law's last torque demand [N m]

    def _blend_gains(self, gains: list[FloatArray], s: float, tb: float) -> list[FloatArray]:
        """``gains`` with the command filter's bandwidth ``wf + (blend_wf - wf) b0(s / Tb)``
        (at most ``wf``, as the headroom scaled it) while the blend runs, ``s`` [s] after it
        started (the C the same)."""
        if not s < tb or math.isinf(self._blend_wf):
            return gains
        w = blend_weight(s / tb)
        wf = gains[len(gains) - 2]  # the headroom's scale included
        out = list(gains)
        out[len(out) - 2] = np.minimum(wf, w * self._blend_wf + (1.0 - w) * wf)
        return out

    def _headroom(self, gains: list[FloatArray], cut: bool = True) -> list[FloatArray]:
        """``gains`` (as :meth:`_gain_args` orders them) with :data:`HEADROOM_GAINS` scaled by
        ``rho``, after updating ``rho`` from the last tick's demand (``cut``: the blend runs;
        else r = 1 and rho only recovers).  The C the same."""
        if math.isinf(self._headroom_tau) or self._u_demand is None:
            return gains
        r = 1.0
        if cut:
            demand = np.abs(self._u_demand)
            r = float(np.min(np.where(demand > self.u_max, self.u_max / demand, 1.0)))
        rho = self._rho
        if rho == 1.0 and r == 1.0:
            return gains
        self._rho = r if r < rho else rho + self.lib.T / self._headroom_tau * (r - rho)
        scaled, names = self.HEADROOM_GAINS, self._gain_names()
        return [g * self._rho if k in scaled else g for k, g in zip(names, gains, strict=True)]

    def _scalar(self, key: str) -> float:
        v = self.gains[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not v > 0 or v != v:
            raise ConfigError(
                describe(
                    f"controller {self.name!r} gain {key}",
                    "a number > 0 (inf: off)",
                    repr(v),
                    "see docs/explanation/control.md, Start-up",
                )
            )
        return float(v)

    def c_parameters(self) -> dict[str, Any] | None:
        own = super().c_parameters()
        assert own is not None
        own["startup_converged"] = self.gains["startup"] == "converged"
        own["ready_q_std"], own["ready_qd_std"] = self._ready_std
        own["ready_nis"], own["ready_nis_window"] = self._ready_nis, self._nis_window
        own["hold_motor"] = self.gains["hold"] == "motor"
        own["blend_accel"] = self._blend_accel
        own["blend_rate"] = self._blend_rate
        own["blend_wf"] = self._blend_wf
        own["headroom_tau"] = self._headroom_tau
        own["blend_lead"] = self._blend_lead
        return own

    def _converged(self, P_diag: FloatArray | None, nis: float | None = None) -> bool:
        """The start-up's test: every link angle's and rate's posterior std below its bound
        and the encoders' mean NIS at most ``ready_nis`` (latched: once trusted, the estimate
        stays trusted).  ``nis``: this tick's encoder NIS (None or NaN: no sample; a caller
        that never gives one is not tested for consistency)."""
        if not self._ready:
            n = self.n
            if nis is not None and math.isfinite(nis):
                self._nis_count += 1
                self._nis_mean += (nis - self._nis_mean) / min(self._nis_count, self._nis_window)
            consistent = math.isinf(self._ready_nis) or self._nis_count == 0
            if not consistent:
                consistent = (
                    self._nis_count >= self._nis_window and self._nis_mean <= self._ready_nis
                )
            self._ready = P_diag is None or bool(
                np.all(np.sqrt(P_diag[:n]) <= self._ready_std[0])
                and np.all(np.sqrt(P_diag[n : 2 * n]) <= self._ready_std[1])
                and consistent
            )
        return self._ready

    def handed_over(self, k: int) -> bool:  # C: amsfe_ctrl_handed_over
        return handed_over(self.gains["startup"], self._started, self._blend, k, self.lib.T)

    def _gain(self, key: str, size: int) -> FloatArray:
        if key == "tau_max" and self.gains.get("tau_max") is None:
            return self.u_max.copy()
        return super()._gain(key, size)

    def prepare(self, t: FloatArray) -> None:
        super().prepare(t)
        jerk, snap = self.trajectory.higher(t)
        grid = self._grid
        self._ref = np.hstack(
            [grid[1], grid[2], grid[3], jerk.reshape(t.size, -1), snap.reshape(t.size, -1)]
        )

    def _ref_at(self, k: int, t: float) -> FloatArray:
        grid = getattr(self, "_grid", None)
        if grid is not None and 0 <= k < grid[0].size and grid[0][k] == t:
            return self._ref[k]
        q, qd, qdd = self.trajectory.evaluate(t)
        j, s = self.trajectory.higher(t)
        return np.concatenate([q, qd, qdd, j, s])

    def _law_inputs(
        self, x_true: FloatArray, theta_true: FloatArray, x_hat: FloatArray, z_enc: FloatArray
    ) -> list[FloatArray]:
        """The law's leading inputs (the state it acts on)."""
        return [x_hat]

    def torque(self, tick: LawInputs) -> FloatArray:
        k, t, x_true, theta_true, x_hat, z_enc = tick[:6]
        n = self.n
        lead = self._law_inputs(x_true, theta_true, x_hat, z_enc)
        ref = self._ref_at(k, t)
        gains = self._gain_args()
        if self._k_first is None:
            self._k_first = k
        if self.gains["startup"] == "converged" and not self._converged(
            tick.P_diag, tick.encoder_nis
        ):
            # wait: the command filter held (no acceleration command from an untrusted
            # estimate); the motor joins the reference's motor trajectory qm_r from its own
            # angle and rate ("motor"), or keeps the offset from qm_r it had ("reference")
            if self.gains["hold"] == "motor":
                if self._m_hold is None:
                    qm_r, qmd_r, _ = self._mref.call_into(ref, lead[0][4 * n :])
                    d0, d1 = z_enc[:n] - qm_r, z_enc[n : 2 * n] - qmd_r
                    tb = blend_time(d0, d1, self._blend_accel, self._blend_rate)
                    self._m_hold = (k, tb, d0.copy(), d1.copy())
                k0, tb, d0, d1 = self._m_hold
                off = blend_offsets((k - k0) * self.lib.T, tb, d0, d1)
                self._cf[:] = off[: 2 * n]
            else:
                if self._c_hold is None:
                    probe = self._law.call_into(*lead, ref, self._cf, *gains, self._hold)
                    self._c_hold = z_enc[:n] - (probe[3] - probe[7])  # qm - qm_r
                self._cf[:n], self._cf[n:] = self._c_hold, 0.0
            out = self._law.call_into(*lead, ref, self._cf, *gains, self._hold)
        else:
            if not self._started and self.gains["startup"] == "converged":
                # the blended reference starts from the state the law acts on
                d0, d1 = lead[0][:n] - ref[:n], lead[0][n : 2 * n] - ref[n : 2 * n]
                # planned as if started s0 ago, through the estimate now (s0 = 0: from now)
                assert self._k_first is not None
                s0 = self._blend_lead * ((k - self._k_first) * self.lib.T)
                tb, d0, d1 = blend_through(d0, d1, s0, self._blend_accel, self._blend_rate)
                self._blend = (k, s0, tb, d0, d1)
            if self._blend is not None:
                k0, s0, tb, d0, d1 = self._blend
                sb = (k - k0) * self.lib.T + s0
                gains = self._headroom(gains, sb < tb)
                ref = ref + blend_offsets(sb, tb, d0, d1)
                gains = self._blend_gains(gains, sb, tb)
            out = self._law.call_into(*lead, ref, self._cf, *gains, self._run)
            if not self._started:  # start at rest on the first trusted command
                self._cf[:n], self._cf[n:] = out[7], 0.0
                self._started = True
                out = self._law.call_into(*lead, ref, self._cf, *gains, self._run)
            self._u_demand = out[0].copy()
        u, s, tau_d, _qm_d, _e_next, bound, cf_next = out[:7]
        self._cf = cf_next.copy()
        self.s, self.bound = s.copy(), bound.copy()
        self.tau_d = tau_d.copy()
        return u.copy()


@register
class Amsfe(_Cascade):
    """``amsfe``: the terminal sliding surface (31)-(33) with the estimation-error term, on
    the fusion estimate, through the flexible-joint cascade (docs/explanation/control.md)."""

    name = "amsfe"
    law = "control_amsfe"


@register
class Truth(_Cascade):
    """``truth``: ``amsfe`` on the true state and the true theta: the bound that estimation
    can approach (an oracle, not a controller one could run on hardware)."""

    name = "truth"
    law = "control_amsfe"

    def _law_inputs(
        self, x_true: FloatArray, theta_true: FloatArray, x_hat: FloatArray, z_enc: FloatArray
    ) -> list[FloatArray]:
        return [np.concatenate([x_true[: 4 * self.n], theta_true])]

    def _converged(self, P_diag: FloatArray | None, nis: float | None = None) -> bool:
        return True  # the true state needs no convergence


@register
class Dtsmc(_Cascade):
    """``dtsmc``: the cascade with the baseline surface of (54) (``Lt = 0``) and no fusion
    estimator.  It reads the motor encoders and removes the spring deflection the plan
    predicts: ``q = qm - (qm_r - q_d)``, ``qd = qmd - (qmd_r - qd_d)`` (``qm_r`` the motor
    angle of the desired motion), computed inside the generated law; theta stays at its
    initial value.  docs/explanation/control.md says why the simpler readings (q = qm, or removing
    the
    deflection commanded one tick before) diverge."""

    name = "dtsmc"
    law = "control_dtsmc"
    has_lt = False

    def _law_inputs(
        self, x_true: FloatArray, theta_true: FloatArray, x_hat: FloatArray, z_enc: FloatArray
    ) -> list[FloatArray]:
        return [z_enc, self.lib.theta_initial]

    def _converged(self, P_diag: FloatArray | None, nis: float | None = None) -> bool:
        return True  # it acts on the encoders, not on an estimate


@register
class DtsmcEstimate(_Cascade):
    """``dtsmc-ekf``: the cascade with the baseline surface of (54) (``Lt = 0``) on the run's
    state estimate.  With ``--estimator encoders`` (an EKF on the motor encoders alone) it is
    the strongest baseline without camera fusion: it isolates what the camera adds.  It calls
    ``control_amsfe`` with ``Lt = 0``, which is the surface of ``control_dtsmc``."""

    name = "dtsmc-ekf"
    law = "control_amsfe"

    def _gain_args(self) -> list[FloatArray]:
        args = super()._gain_args()
        args[_LAW_GAINS.index("Lt")] = np.zeros(self.n)
        return args
