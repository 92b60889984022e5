"""Why a live node's watchdog holds (:mod:`amsfe_sym.ros.watchdog`, docs/watchdogs.md): the
reasons and their stable names, the causes that tell one reason's cases apart, and the one
line of real cause and fix a hold prints for each, the C twin's (``amsfe_watchdog.{h,c}``)
character for character.
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["CAUSE_TEXT", "REASON_NAMES", "Cause", "Reason"]


class Reason(IntEnum):
    """Why the node holds (``enum amsfe_watchdog_reason``)."""

    NONE = 0
    TRACKING = 1
    INNOVATION = 2
    COVARIANCE = 3
    DEADLINE = 4
    COMPUTE = 5
    ENCODER_STALL = 6
    NODE_STALLED = 7
    NONFINITE = 8
    ACTUATION = 9
    LAG = 10


#: The stable names of the reasons (the hold line's, tests match them).
REASON_NAMES = (
    "none",
    "tracking",
    "innovation",
    "covariance",
    "deadline",
    "compute",
    "encoder_stall",
    "node_stalled",
    "nonfinite",
    "actuation",
    "lag",
)


class Cause(IntEnum):
    """Which cause of a reason (``enum amsfe_watchdog_cause``): the text differs."""

    NONE = 0
    BEHIND = 1
    INCONSISTENT = 2
    SILENT = 3
    GONE = 4
    GAP = 5
    LOST = 6
    UNSCHEDULED = 7
    ESTIMATE = 8
    COMMAND = 9
    LATE = 10


#: Each (reason, cause)'s text, the C's (``amsfe_watchdog_cause_text``) character for character:
#: a line ``<reason name> <cause name>:``, then the text, wrapped at spaces (joined by one).
_TEXTS = """
tracking none:
    the arm left its path: a link angle is farther from q_d than tracking_error; check the
    arm (a broken encoder, a torque loss, a collision) and the gains
innovation none:
    the measurements disagree with the model: the mean NIS of the last fused updates is
    above innovation_nis; check the encoders and the camera (a jump, a frozen sample), the
    torque the arm applies and the spec's noise
covariance behind:
    the node fell behind: the covariance lost positive definiteness after a prediction over
    missing samples; give the node CPU (priority, fewer jobs) or a deeper queue
covariance inconsistent:
    model/noise inconsistent: the covariance lost positive definiteness with no sample
    missing; check the robot spec's model and the [filter] noise
deadline none:
    this node is behind (CPU load / priority), not the driver: samples processed later than
    deadline after their stamp; give the node CPU (real-time priority, fewer jobs)
deadline late:
    this node is behind, not the arm: it processed this sample later than deadline after its
    stamp, and what the arm did meanwhile on older commands (its innovations, its path, its
    torque) left a bound; give the node CPU (real-time priority, fewer jobs)
compute none:
    one tick's computation took longer than compute_budget: the machine is too loaded or too
    slow for this loop; give the node CPU or run the C node
encoder_stall silent:
    the arm's driver is silent: its publisher is in the graph but sends no sample; check the
    driver and the arm's hardware
encoder_stall gone:
    the arm's driver is gone: no publisher of the encoders is left; restart the driver
encoder_stall gap:
    the arm's driver paused: more than max_gap_steps samples missing, the next one on time;
    check the driver (or raise [timing] max_gap_steps)
node_stalled lost:
    this node is behind, not the driver: more than max_gap_steps samples lost from its queue
    while it lagged; give the node CPU (priority) or a deeper queue ([qos] depth)
node_stalled unscheduled:
    this node was not scheduled, not the driver: its own loop paused longer than
    encoder_timeout; give the node CPU (real-time priority, fewer jobs)
nonfinite estimate:
    the estimate turned NaN or inf; check the encoder values and the robot spec
nonfinite command:
    the command turned NaN or inf; check the gains and the reference
actuation none:
    the arm does not apply the command (drive fault, e-stop, brakes): the torque it reports
    differs from every command it may have applied by more than actuation_error; check the
    drives
lag none:
    this node is behind on average, not the arm: the mean lateness of the last
    deadline_window samples (each queued while the arm ran on an older command) is above
    lag, so the arm runs on stale commands; give the node CPU (real-time priority, fewer
    jobs) or run the C node
"""


def _parse_texts(table: str) -> dict[tuple[Reason, Cause], str]:
    """:data:`_TEXTS` as a dict (the wrapped lines joined with one space)."""
    out: dict[tuple[Reason, Cause], str] = {}
    key: tuple[Reason, Cause] | None = None
    for line in table.strip().splitlines():
        if not line.startswith(" "):
            reason, cause = line.rstrip(":").split()
            key = (Reason(REASON_NAMES.index(reason)), Cause[cause.upper()])
            out[key] = ""
        elif key is not None:
            out[key] = f"{out[key]} {line.strip()}".strip()
    return out


#: One line per (reason, cause): the real cause and its fix (the C's, character for character).
CAUSE_TEXT: dict[tuple[Reason, Cause], str] = _parse_texts(_TEXTS)
