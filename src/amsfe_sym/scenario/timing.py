"""The camera's timing in steps, resolved from the scenario and the robot spec (paper
Sec. 3.2, eq. 11), checked against the filter's buffer."""

from __future__ import annotations

from dataclasses import dataclass

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.scenario.model import (
    Scenario,
)


@dataclass(frozen=True)
class CameraTiming:
    """The camera's resolved timing (paper Sec. 3.2, eq. 11), all in steps of T.

    Attributes:
        period: l, steps between exposures (>= 1).
        delay: d, steps from exposure to delivery (>= 0; 0 = delivered at once).
        phase: Exposures at steps k with ``k % period == phase``.
        jitter_steps: Largest extra random delay.
    """

    period: int
    delay: int
    phase: int
    jitter_steps: int

    @property
    def max_delay(self) -> int:
        """The largest delay a frame may have: ``delay + jitter_steps``."""
        return self.delay + self.jitter_steps


def camera_timing(
    sc: Scenario, robot_period: int, robot_delay: int, needs_history: bool = True
) -> CameraTiming:
    """The one place a scenario's camera period and delay are resolved and checked.

    ``None`` in the scenario takes the robot's (``robot_period``, ``robot_delay``: the robot
    spec's ``[camera]``, or the library manifest's, which records the same values).  Needs
    no library, so it runs before anything is generated.

    Args:
        sc: The scenario.
        robot_period, robot_delay: The robot's l and d [steps].
        needs_history: Whether the estimator keeps a history for late frames (``replay``,
            ``oosm``, ``cloning``): then ``[filter] buffer_steps`` must cover the largest
            delay.

    Raises:
        ConfigError: period < 1, delay < 0, a phase outside [0, period), or a buffer
            shorter than delay + jitter.
    """
    cam = sc.camera
    period = robot_period if cam.period is None else cam.period
    delay = robot_delay if cam.delay is None else cam.delay
    where = f"{sc.name}: [camera]"
    if period < 1:
        raise ConfigError(
            describe(
                f"{where} period", "an integer >= 1", repr(period), "write period = 125 (steps)"
            )
        )
    if delay < 0 or cam.jitter_steps < 0:
        raise ConfigError(
            describe(
                f"{where} delay / jitter_steps",
                "integers >= 0",
                f"{delay} / {cam.jitter_steps}",
                "use delays in whole steps >= 0 (omit delay for the robot's)",
            )
        )
    if not 0 <= cam.phase < period:
        raise ConfigError(
            describe(
                f"{where} phase",
                f"an integer in [0, {period})",
                repr(cam.phase),
                "write a phase smaller than the period, e.g. phase = 0",
            )
        )
    timing = CameraTiming(period, delay, cam.phase, cam.jitter_steps)
    if needs_history and timing.max_delay > sc.filter.buffer_steps:
        raise ConfigError(
            describe(
                "[filter] buffer_steps",
                f">= camera delay + jitter = {timing.max_delay} steps",
                str(sc.filter.buffer_steps),
                "raise buffer_steps or shorten the delay",
            )
        )
    return timing


#: Largest memory a run's records may take [bytes]: a longer run is refused before anything
#: is built or allocated (split it, or record with a coarser robot period).
MAX_RECORD_BYTES = 4 * 2**30


def record_bytes_per_tick(n: int, N: int) -> int:
    """Bytes the loop records per tick for ``n`` joints and ``N`` states: true and
    estimated state and P's diagonal (3 N), the input, the encoder samples, the torques, the
    sliding variables and bounds, the desired trajectory (10 n), time and NEES (float64)."""
    return 8 * (3 * N + 10 * n + 2)


def run_ticks(sc: Scenario, T: float, n: int, N: int) -> int:
    """The number of ticks K of a run (``round(duration / T) + 1``), checked.

    Args:
        sc: The scenario (its ``duration`` [s]).
        T: The robot's sampling period [s].
        n, N: Joints and states of the robot (the size of the records).

    Raises:
        ConfigError: the duration is shorter than one period (no step to simulate: every
            metric would be NaN) or its records would take more than
            :data:`MAX_RECORD_BYTES` (the message gives the bytes).
    """
    where = str(sc.source) if sc.source is not None else sc.name
    if not sc.duration >= T:
        raise ConfigError(
            describe(
                f"{where}: duration",
                f">= the robot's sample period T = {T:g} s (one step at least)",
                f"{sc.duration!r} s",
                f"simulate at least {T:g} s, e.g. --duration 2",
            )
        )
    K = round(sc.duration / T) + 1
    need = K * record_bytes_per_tick(n, N)
    if need > MAX_RECORD_BYTES:
        longest = (MAX_RECORD_BYTES // record_bytes_per_tick(n, N) - 1) * T
        raise ConfigError(
            describe(
                f"{where}: duration",
                f"records of at most {MAX_RECORD_BYTES / 2**30:.0f} GiB "
                f"(at most {longest:.6g} s at T = {T:g} s)",
                f"{sc.duration!r} s = {K} ticks, {need / 2**30:.3g} GiB of records ({need} bytes)",
                "simulate a shorter time, or split the run",
            )
        )
    return K
