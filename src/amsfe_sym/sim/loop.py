"""Closed-loop simulation: plant (truth) -> sensors -> estimator -> controller.

One tick k (t_k = k T):

1. the sensors read the true plant state x_k: encoders every step, the camera exposes
   every l steps and delivers frames d steps later (``amsfe_sym.sim.sensors``);
2. the estimator advances from k-1 to k with u_{k-1}, the encoder sample and the frames
   delivered at k (``amsfe_sym.estimation``);
3. the controller computes u_k (``amsfe_sym.control``);
4. the plant integrates over [t_k, t_k + T] with u_k held (compiled RK4, ``plant_step``),
   with the true theta and optional disturbance torques.

The plant is the continuous-time Spong model, deliberately not the estimator's discrete
map, so the estimator meets model error as on a real arm.  The parts are built by
:mod:`amsfe_sym.sim.builders`; the library comes from the caller
(:func:`amsfe_sym.codegen.library_for` builds the one of a scenario).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.builders import build_run

__all__ = [
    "CAMERA_COUNTERS",
    "DECISION_COUNTERS",
    "DIVERGED_TRACKING_ERROR",
    "REFUSAL_KINDS",
    "RUNTIMES",
    "RunResult",
    "refusal_kind",
    "run",
    "tick_bar",
]

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


@dataclass
class RunResult:
    """Everything a run produced.

    Attributes:
        scenario: The resolved scenario.
        lib: The model library used.
        t: Times [s], shape (K,).
        x_true: True state [q, qd, qm, qmd, theta] at each tick, (K, N).
        x_hat: Posterior estimate x(k|k), (K, N).
        P_diag: Diagonal of P(k|k), (K, N).
        nees: Normalised estimation error squared e^T P^-1 e, (K,).
        q_des: Desired link angles, (K, n).
        u: Motor torques [N m], (K, n).
        z_enc: Encoder samples, (K, 2n).
        tau_d: Disturbance torques [tau_l, tau_m] [N m] applied to the plant over
            [t_k, t_k + T], (K, 2n) (the last row, after the run, is zero): with ``u`` and the
            true theta, ``plant_step`` replays ``x_true`` exactly.
        frames: Delivered camera frames: rows (exposure step, delivery step, u px, v px).
        wall_time_s: Wall time of the loop [s].
        counters: Sensor and estimator counts (frames applied, rejected, and
            ``refused_<kind>``: why frames were refused, see :data:`REFUSAL_KINDS`).
        s: Sliding variable s(k) of eq. (33) per joint, (K, n) (NaN for laws without one).
        bound: The norm inside the gain condition (38) per joint, (K, n) (NaN if none).
        saturated: Whether the actuator limit clipped u(k), (K,).
        diverged_at: Time [s] the loop was stopped because it diverged (the arrays end
            there), or None.
        runtime: Which loop made the run: ``"python"`` (the reference) or ``"compiled"``.
    """

    scenario: Scenario
    lib: ModelLibrary
    t: FloatArray
    x_true: FloatArray
    x_hat: FloatArray
    P_diag: FloatArray
    nees: FloatArray
    q_des: FloatArray
    u: FloatArray
    z_enc: FloatArray
    frames: FloatArray
    wall_time_s: float
    counters: dict[str, int] = field(default_factory=dict)
    s: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    bound: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    saturated: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    diverged_at: float | None = None
    tau_d: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    runtime: str = "python"


#: Why an estimator refused a camera frame, from its report's reason: (kind, words).
REFUSAL_KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("nan", ("NaN or inf",)),
    ("too_late", ("older than the history", "no clone left")),
    ("gated", ("gated out",)),  # outliers, pixels far outside the predicted image point
    ("indefinite", ("indefinite covariance",)),
    ("no_convergence", ("did not converge",)),
    ("unscheduled", ("not a scheduled exposure",)),
)


#: The counters of a run's ``summary.json``, in their order: the estimator's decisions, then
#: what happened to the camera's frames (both runtimes fill the same names).
DECISION_COUNTERS: tuple[str, ...] = (
    "frames_applied",
    "frames_rejected",
    "encoder_rejected",
    *(f"refused_{kind}" for kind, _ in REFUSAL_KINDS),
    "refused_other",
)
CAMERA_COUNTERS = ("frames_exposed", "frames_delivered", "frames_dropped", "frames_out_of_image")


def tick_bar(sc: Scenario, total: int, runtime: str) -> Any:
    """The progress bar of a run of ``total`` ticks."""
    from tqdm import tqdm

    label = "" if runtime == "python" else f", {runtime}"
    return tqdm(
        total=total,
        desc=f"{sc.name} [{sc.estimator}, {sc.controller}{label}]",
        unit="tick",
        mininterval=0.5,
    )


def refusal_kind(reason: str) -> str:
    """The counter (``refused_<kind>`` in ``summary.json``) of one refusal reason."""
    for kind, words in REFUSAL_KINDS:
        if any(w in reason for w in words):
            return kind
    return "other"


#: The runtimes of :func:`run`: the compiled C loop, or this module's Python reference.
RUNTIMES = ("compiled", "python")


def run(
    scenario: Scenario,
    lib: ModelLibrary,
    progress: bool = False,
    runtime: str = "python",
    compiled_estimator: bool = False,
) -> RunResult:
    """Simulate ``scenario`` on the library ``lib`` and return the recorded signals
    (nothing is written; :func:`amsfe_sym.sim.record.write_run` writes a run folder).

    Args:
        scenario: The scenario.
        lib: Its library (:func:`amsfe_sym.codegen.library_for`).
        progress: Show a progress bar.
        runtime: ``"python"``: the readable reference loop below; ``"compiled"``: the same
            loop in the library's C runtime (:func:`amsfe_sym.sim.compiled.run_compiled`),
            which reproduces it (docs/runtime-c.md says how closely).
        compiled_estimator: Python loop only: use the library's C estimator (isolates the
            loop from the estimators' arithmetic when comparing the two runtimes).

    Raises:
        ConfigError: a setting the builders refuse.  A diverging closed loop is not an
            error: the run stops there and ``RunResult.diverged_at`` says when.
    """
    if runtime not in RUNTIMES:
        raise ConfigError(
            describe("runtime", f"one of {list(RUNTIMES)}", repr(runtime), "use 'compiled'")
        )
    if runtime == "compiled":
        from amsfe_sym.sim.compiled import run_compiled  # it builds on this module

        return run_compiled(scenario, lib, progress)
    sc = scenario
    n, N, T = lib.n, lib.N, lib.T
    L = lib.layout
    K = round(sc.duration / T) + 1
    theta_true = lib.theta_true

    parts = build_run(sc, lib, compiled=True) if compiled_estimator else build_run(sc, lib)
    xp, z0, est, ctrl, traj = (
        parts.plant0,
        parts.z0,
        parts.estimator,
        parts.controller,
        parts.trajectory,
    )
    enc, camera = parts.sensors.encoders, parts.sensors.camera
    disturbance = parts.sensors.disturbance
    plant = lib.function("plant_step")

    # ---------------------------------------------------------------- records
    t: FloatArray = np.arange(K, dtype=float) * T
    x_true = np.zeros((K, N))
    x_hat = np.zeros((K, N))
    P_diag = np.zeros((K, N))
    nees = np.zeros(K)
    q_des = traj.evaluate(t).q.reshape(K, n)
    ctrl.prepare(t)
    u_rec = np.zeros((K, n))
    z_rec = np.zeros((K, 2 * n))
    s_rec = np.full((K, n), np.nan)
    bound_rec = np.full((K, n), np.nan)
    saturated = np.zeros(K, dtype=bool)
    frames_rec: list[tuple[float, float, float, float]] = []
    counters = dict.fromkeys(DECISION_COUNTERS, 0)
    diverged_at: float | None = None
    tau_rec = np.zeros((K, 2 * n))

    bar = tick_bar(sc, K, "python") if progress else None
    u = np.zeros(n)
    x_t = np.zeros(N)
    x_t[4 * n :] = theta_true
    t0 = time.perf_counter()
    last = K
    for k in range(K):
        x_t[: 4 * n] = xp
        # 1. sensors at t_k
        z = z0 if k == 0 else enc.measure(xp[L["qm"]], xp[L["qmd"]])
        delivered = camera.tick(k, xp[L["q"]])
        for fr in delivered:
            frames_rec.append((fr.exposure_step, k, float(fr.z[0]), float(fr.z[1])))
        # 2. estimator k-1 -> k
        if k > 0:
            rep = est.step(u, z, delivered)
            counters["frames_applied"] += rep.frames_applied
            counters["frames_rejected"] += rep.frames_rejected
            for reason in rep.rejections:
                counters[f"refused_{refusal_kind(reason)}"] += 1
            counters["encoder_rejected"] += int(not rep.encoder_accepted)
        xh, P = est.x, est.P
        # 3. controller, then the actuator limit
        u, saturated[k] = ctrl.saturate(ctrl.torque(k, float(t[k]), xp, theta_true, xh, z))
        # record
        x_true[k] = x_t
        x_hat[k] = xh
        P_diag[k] = np.diag(P)
        err = x_t - xh
        nees[k] = float(err @ np.linalg.solve(P, err))
        u_rec[k] = u
        z_rec[k] = z
        s_rec[k] = ctrl.s
        bound_rec[k] = ctrl.bound
        if _diverged(xp, q_des[k], u):
            diverged_at, last = float(t[k]), k + 1
            log.warning("%s: the closed loop diverged at t = %.3f s", sc.name, t[k])
            break
        # 4. plant over [t_k, t_k + T]
        if k + 1 < K:
            dist = disturbance.sample()
            tau = np.concatenate([dist.link, dist.motor])
            tau_rec[k] = tau
            xp = plant.call_into(xp, u, theta_true, tau)[0].copy()
        if bar is not None and k % 250 == 0:
            bar.update(min(250, K - bar.n))
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.update(last - bar.n)  # a diverged run ends early, and so does its bar
        bar.close()
    stats = camera.stats
    counters.update(
        {name: int(getattr(stats, name.removeprefix("frames_"))) for name in CAMERA_COUNTERS}
    )
    cut = slice(0, last)
    return RunResult(
        scenario=sc,
        lib=lib,
        t=t[cut],
        x_true=x_true[cut],
        x_hat=x_hat[cut],
        P_diag=P_diag[cut],
        nees=nees[cut],
        q_des=q_des[cut],
        u=u_rec[cut],
        z_enc=z_rec[cut],
        frames=np.array(frames_rec, dtype=float).reshape(-1, 4),
        wall_time_s=wall,
        counters=counters,
        s=s_rec[cut],
        bound=bound_rec[cut],
        saturated=saturated[cut],
        diverged_at=diverged_at,
        tau_d=tau_rec[cut],
    )


#: A tracking error beyond this [rad or m] means the closed loop has lost the arm.
DIVERGED_TRACKING_ERROR = np.pi


def _diverged(xp: FloatArray, q_des: FloatArray, u: FloatArray) -> bool:
    """True when the plant state or the torque is not finite, or the link tracking error
    exceeds :data:`DIVERGED_TRACKING_ERROR`: the run stops there and says so."""
    n = q_des.size
    if not (np.all(np.isfinite(xp)) and np.all(np.isfinite(u))):
        return True
    return bool(np.max(np.abs(xp[:n] - q_des)) > DIVERGED_TRACKING_ERROR)
