"""Desired joint trajectories ``q_d(t)``, ``qd_d(t)``, ``qdd_d(t)`` in closed form.

The controller (eqs. 29-37) needs the desired link angle, rate and acceleration; every
trajectory here gives all three exactly and is vectorised over time:

* ``evaluate(t)`` with a scalar ``t`` [s] returns arrays of shape (n,);
* with a 1-D array of ``m`` times it returns arrays of shape (m, n).

Shipped kinds (also buildable from a scenario's TOML table with :func:`from_config`):

* :class:`Sinusoid` -- ``q_i = offset_i + amplitude_i sin(omega_i t + phase_i)``; the
  paper's simulation study (Sec. 5.1) uses ``q1 = sin(pi t)``, ``q2 = cos(pi t)``
  (:meth:`Sinusoid.paper_sim`).
* :class:`PaperExperiment` -- the 1-link experiment of Sec. 5.2, ``q_d`` linear in time,
  with the printed and the corrected reading of the paper's formula.
* :class:`Constant` -- a set point.
"""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.errors import ConfigError, ShapeError, describe
from amsfe_sym.signals.checks import _flat_floats

__all__ = [
    "KINDS",
    "Constant",
    "PaperExperiment",
    "Sinusoid",
    "Trajectory",
    "TrajectoryPoint",
    "from_config",
    "tip_circle",
]

Reading = Literal["corrected", "printed"]


class TrajectoryPoint(NamedTuple):
    """Desired motion at one or several times (unpacks as ``q, qd, qdd = ...``).

    Attributes:
        q: Desired link angles [rad], shape (n,) or (m, n).
        qd: Desired link rates [rad/s], same shape.
        qdd: Desired link accelerations [rad/s^2], same shape.
    """

    q: FloatArray
    qd: FloatArray
    qdd: FloatArray


def _times(t: float | ArrayLike) -> tuple[FloatArray, bool]:
    """Return times [s] as a 1-D array and whether the input was a scalar."""
    arr = np.asarray(t, dtype=float)
    if arr.ndim > 1:
        raise ShapeError(
            describe(
                "trajectory time t [s]",
                "a scalar or a 1-D array of times",
                f"shape {arr.shape}",
                "flatten the times with np.ravel",
            )
        )
    if not np.all(np.isfinite(arr)):
        raise ConfigError(
            describe("trajectory time t [s]", "finite times", "NaN or inf", "check the clock")
        )
    return np.atleast_1d(arr), arr.ndim == 0


class Trajectory(ABC):
    """A desired motion of ``n`` joints, known in closed form with two derivatives."""

    @property
    @abstractmethod
    def n(self) -> int:
        """Number of joints."""

    @abstractmethod
    def _evaluate(self, t: FloatArray) -> TrajectoryPoint:
        """Evaluate at times ``t`` [s], shape (m,); return arrays of shape (m, n)."""

    def evaluate(self, t: float | ArrayLike) -> TrajectoryPoint:
        """Desired angles [rad], rates [rad/s] and accelerations [rad/s^2] at time(s) ``t``.

        Args:
            t: Time [s]: a scalar, or a 1-D array of ``m`` times.

        Returns:
            ``(q, qd, qdd)``, each of shape (n,) for a scalar ``t`` or (m, n) for an array.

        Raises:
            ShapeError: ``t`` has more than one dimension.
            ConfigError: ``t`` holds NaN or inf.
        """
        times, scalar = _times(t)
        point = self._evaluate(times)
        if scalar:
            return TrajectoryPoint(point.q[0], point.qd[0], point.qdd[0])
        return point

    def _higher(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Jerk and snap at times ``t`` (m,), each (m, n); zero unless a kind overrides it."""
        z = np.zeros((t.size, self.n))
        return z, z.copy()

    def higher(self, t: float | ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Desired jerk [rad/s^3] and snap [rad/s^4] at time(s) ``t`` (shapes as
        :meth:`evaluate`): the smooth feedforward of the cascaded laws needs them to
        differentiate the desired motor angle exactly (amsfe_sym.symbolic.control)."""
        times, scalar = _times(t)
        j, s = self._higher(times)
        return (j[0], s[0]) if scalar else (j, s)


def _vector(value: Any, what: str) -> FloatArray:
    """A finite 1-D float vector from a scalar or a sequence (scalars give shape (1,))."""
    arr = _flat_floats(value, what)
    if not np.all(np.isfinite(arr)):
        raise ConfigError(
            describe(what, "finite numbers", repr(value), "replace nan/inf by finite numbers")
        )
    return arr


class Sinusoid(Trajectory):
    """``q_i(t) = offset_i + amplitude_i sin(omega_i t + phase_i)`` per joint.

    Args:
        amplitude: Amplitudes [rad], one per joint (a scalar broadcasts).
        omega: Angular frequencies [rad/s].
        phase: Phases [rad]; default 0.
        offset: Offsets [rad]; default 0.

    The number of joints is the length of the longest argument; each argument has that
    length or is a scalar / length 1.

    Raises:
        ConfigError: lengths disagree or a value is not finite.
    """

    def __init__(
        self,
        amplitude: float | Sequence[float] | ArrayLike,
        omega: float | Sequence[float] | ArrayLike,
        phase: float | Sequence[float] | ArrayLike = 0.0,
        offset: float | Sequence[float] | ArrayLike = 0.0,
    ) -> None:
        parts = {
            "amplitude [rad]": _vector(amplitude, "Sinusoid amplitude [rad]"),
            "omega [rad/s]": _vector(omega, "Sinusoid omega [rad/s]"),
            "phase [rad]": _vector(phase, "Sinusoid phase [rad]"),
            "offset [rad]": _vector(offset, "Sinusoid offset [rad]"),
        }
        n = max(a.size for a in parts.values())
        bad = {k: a.size for k, a in parts.items() if a.size not in (1, n)}
        if bad:
            raise ConfigError(
                describe(
                    "Sinusoid",
                    f"every argument of length {n} (or a scalar)",
                    f"lengths {bad}",
                    "give one value per joint for each argument",
                )
            )
        full = [np.broadcast_to(a, (n,)).copy() for a in parts.values()]
        self.amplitude, self.omega, self.phase, self.offset = full
        self._n = n

    @classmethod
    def paper_sim(cls) -> Sinusoid:
        """Sec. 5.1: ``q1_d = sin(pi t)``, ``q2_d = cos(pi t) = sin(pi t + pi/2)`` [rad]."""
        return cls(
            amplitude=[1.0, 1.0], omega=[math.pi, math.pi], phase=[0.0, math.pi / 2], offset=0.0
        )

    @property
    def n(self) -> int:
        """Number of joints."""
        return self._n

    def _evaluate(self, t: FloatArray) -> TrajectoryPoint:
        arg = np.outer(t, self.omega) + self.phase
        s, c = np.sin(arg), np.cos(arg)
        q = self.offset + self.amplitude * s
        qd = self.amplitude * self.omega * c
        qdd = -self.amplitude * self.omega**2 * s
        return TrajectoryPoint(q, qd, qdd)

    def _higher(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        arg = np.outer(t, self.omega) + self.phase
        a = self.amplitude
        return -a * self.omega**3 * np.cos(arg), a * self.omega**4 * np.sin(arg)

    def __repr__(self) -> str:
        return (
            f"Sinusoid(amplitude={self.amplitude.tolist()}, omega={self.omega.tolist()}, "
            f"phase={self.phase.tolist()}, offset={self.offset.tolist()})"
        )


class Constant(Trajectory):
    """A set point: ``q_d(t) = q``, ``qd_d = qdd_d = 0``.

    Args:
        q: Desired angles [rad], one per joint (a scalar means one joint).
    """

    def __init__(self, q: float | Sequence[float] | ArrayLike) -> None:
        self.q = _vector(q, "Constant q [rad]")

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.q.size)

    def _evaluate(self, t: FloatArray) -> TrajectoryPoint:
        q = np.tile(self.q, (t.size, 1))
        zero = np.zeros_like(q)
        return TrajectoryPoint(q, zero, zero.copy())

    def __repr__(self) -> str:
        return f"Constant(q={self.q.tolist()})"


READINGS: tuple[str, ...] = ("corrected", "printed")


class PaperExperiment(Trajectory):
    """The 1-link experiment's desired angle (Sec. 5.2), linear in time.

    The paper prints ``q_d = (0.4 - t)/75``.  Two readings are offered:

    * ``"corrected"`` (default): ``q_d = 0.4 - t/75`` [rad].  It starts at 0.4 rad, next to
      the experiment's initial angle 0.35 rad, and sweeps 0.13 rad over 10 s: a slow arc.
    * ``"printed"``: ``q_d = (0.4 - t)/75`` [rad], literally; it starts at 0.0053 rad,
      0.345 rad away from the initial angle, which the paper's figures do not suggest.

    Both have the same rate ``-1/75`` rad/s and zero acceleration; they differ only by a
    constant offset.  The desired tip moves on the circle of radius ``l1`` (see
    :meth:`tip`).

    Args:
        reading: ``"corrected"`` or ``"printed"``.
        l1: Link length [m] used by :meth:`tip` (Sec. 5.2: 0.6 m).

    Raises:
        ConfigError: unknown reading or a non-positive ``l1``.
    """

    RATE: float = -1.0 / 75.0  # [rad/s]

    def __init__(self, reading: str = "corrected", l1: float = 0.6) -> None:
        if reading not in READINGS:
            raise ConfigError(
                describe(
                    "PaperExperiment reading",
                    f"one of {list(READINGS)}",
                    repr(reading),
                    "use 'corrected' (q_d = 0.4 - t/75) or 'printed' (q_d = (0.4 - t)/75)",
                )
            )
        if (
            not isinstance(l1, numbers.Real)
            or isinstance(l1, bool)
            or not (math.isfinite(float(l1)) and float(l1) > 0)
        ):
            raise ConfigError(
                describe("PaperExperiment l1 [m]", "a finite length > 0", repr(l1), "use 0.6")
            )
        self.reading: str = reading
        self.l1: float = float(l1)
        self.q0: float = 0.4 if reading == "corrected" else 0.4 / 75.0  # [rad] at t = 0

    @property
    def n(self) -> int:
        """Number of joints (1)."""
        return 1

    def _evaluate(self, t: FloatArray) -> TrajectoryPoint:
        q = (self.q0 + self.RATE * t)[:, None]
        return TrajectoryPoint(q, np.full_like(q, self.RATE), np.zeros_like(q))

    def tip(self, t: float | ArrayLike) -> FloatArray:
        """Desired tip position ``[x_d, y_d] = l1 [cos q_d, sin q_d]`` [m] at time(s) ``t``.

        Returns:
            Shape (2,) for a scalar ``t``, (m, 2) for ``m`` times.
        """
        q = self.evaluate(t).q[..., 0]
        return tip_circle(q, self.l1)

    def __repr__(self) -> str:
        return f"PaperExperiment(reading={self.reading!r}, l1={self.l1})"


def tip_circle(q: float | ArrayLike, l1: float) -> FloatArray:
    """Tip of a single link of length ``l1`` [m] at angle ``q`` [rad]: ``l1 [cos q, sin q]``.

    Args:
        q: Link angle(s) [rad], any shape ``s``.
        l1: Link length [m].

    Returns:
        ``[x, y]`` [m], shape ``s + (2,)``.
    """
    qa = np.asarray(q, dtype=float)
    return np.stack([l1 * np.cos(qa), l1 * np.sin(qa)], axis=-1)


# --------------------------------------------------------------------------------------
# from a scenario table

KINDS: tuple[str, ...] = ("sinusoid", "paper_sim", "paper_experiment", "constant")
_KEYS: dict[str, tuple[set[str], set[str]]] = {  # kind -> (required, optional) keys
    "sinusoid": ({"amplitude", "omega"}, {"phase", "offset"}),
    "paper_sim": (set(), set()),
    "paper_experiment": (set(), {"reading", "l1"}),
    "constant": ({"q"}, set()),
}


def from_config(config: Mapping[str, Any]) -> Trajectory:
    """Build a trajectory from a scenario's TOML table.

    Examples of tables (TOML inline syntax)::

        {kind = "sinusoid", amplitude = [1, 1], omega = [3.14159, 3.14159],
         phase = [0, 1.5708], offset = [0, 0]}
        {kind = "paper_sim"}                       # Sinusoid.paper_sim()
        {kind = "paper_experiment", reading = "corrected", l1 = 0.6}
        {kind = "constant", q = [0.5, 0.5]}

    Args:
        config: Mapping with ``kind`` (one of :data:`KINDS`) and that kind's keys.

    Returns:
        The trajectory.

    Raises:
        ConfigError: no or unknown ``kind`` (the message lists the kinds), a missing or
            unknown key, or a bad value.
    """
    if not isinstance(config, Mapping):
        raise ConfigError(
            describe(
                "trajectory config",
                'a table such as {kind = "paper_sim"}',
                type(config).__name__,
                "write the trajectory as a TOML table",
            )
        )
    kind = config.get("kind")
    if kind not in KINDS:
        raise ConfigError(
            describe(
                "trajectory kind",
                f"one of {list(KINDS)}",
                repr(kind),
                "set kind to one of the listed trajectory kinds",
            )
        )
    required, optional = _KEYS[kind]
    keys = set(config) - {"kind"}
    missing = required - keys
    unknown = keys - required - optional
    if missing or unknown:
        raise ConfigError(
            describe(
                f"trajectory of kind {kind!r}",
                f"keys {sorted(required)} (optional {sorted(optional)})",
                f"missing {sorted(missing)}, unknown {sorted(unknown)}",
                "fix the key names in the trajectory table",
            )
        )
    if kind == "sinusoid":
        return Sinusoid(
            amplitude=config["amplitude"],
            omega=config["omega"],
            phase=config.get("phase", 0.0),
            offset=config.get("offset", 0.0),
        )
    if kind == "paper_sim":
        return Sinusoid.paper_sim()
    if kind == "paper_experiment":
        return PaperExperiment(reading=config.get("reading", "corrected"), l1=config.get("l1", 0.6))
    return Constant(config["q"])
