"""What a closed-loop run produced, and the names both runtimes fill in it: the
:class:`RunResult`, the summary's counters, the refusal kinds, the progress bar.

Shared by the Python reference loop (:mod:`amsfe_sym.sim.loop`) and the compiled one
(:mod:`amsfe_sym.sim.compiled`), so that neither imports the other's module for them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.estimation.base import StepReport
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario

__all__ = [
    "CAMERA_COUNTERS",
    "DECISION_COUNTERS",
    "DIVERGED_TRACKING_ERROR",
    "REFUSAL_KINDS",
    "RUNTIMES",
    "RunResult",
    "count_decisions",
    "refusal_kind",
    "tick_bar",
]

FloatArray = NDArray[np.float64]


#: A tracking error beyond this [rad or m] means the closed loop has lost the arm.
DIVERGED_TRACKING_ERROR = np.pi


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


def count_decisions(counters: dict[str, int], rep: StepReport) -> None:
    """Add one estimator step's decisions to a run's :data:`DECISION_COUNTERS`."""
    counters["frames_applied"] += rep.frames_applied
    counters["frames_rejected"] += rep.frames_rejected
    for reason in rep.rejections:
        counters[f"refused_{refusal_kind(reason)}"] += 1
    counters["encoder_rejected"] += int(not rep.encoder_accepted)


def refusal_kind(reason: str) -> str:
    """The counter (``refused_<kind>`` in ``summary.json``) of one refusal reason."""
    for kind, words in REFUSAL_KINDS:
        if any(w in reason for w in words):
            return kind
    return "other"


#: The runtimes of :func:`run`: the compiled C loop, or this module's Python reference.
RUNTIMES = ("compiled", "python")
