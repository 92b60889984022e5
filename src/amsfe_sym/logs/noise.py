"""The encoder noise of a log, measured from the log itself (docs/how-to/logs.md, "The encoder
noise from the log"): a robust noise floor per channel from high-order differences.

For white noise of standard deviation sigma on a sampled channel x[k], the m-th difference
has variance ``C(2m, m) sigma^2`` whatever the sampling rate; a smooth motion's m-th
difference shrinks like ``(w T)^m`` (w: its frequency [rad/s], T: the period [s]).  So each
order m gives ``s_m = 1.4826 MAD(diff(x, m)) / sqrt(C(2m, m))`` (the median absolute
deviation: the few large differences of a step, a start or a stop do not move it), the
motion adds to every s_m and the smallest is the noise floor.  A quantised channel (a
lattice of values) is floored by its resolution ``r / sqrt(12)``, the spread of the rounding
error; a constant channel says nothing about its noise and is left out of the medians.
Rows that repeat the previous row in every channel (a driver republishing its last sample)
and rows of NaN (gaps) are left out of the differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["MAX_ROWS", "ORDERS", "ChannelNoise", "EncoderNoise", "channel_noise", "encoder_noise"]

#: The difference orders tried: 1 (white noise on a channel at rest) to 6 (a moving arm
#: sampled at 30 Hz: a 0.5 Hz motion's 6th difference is (pi / 30)^6 = 1.3e-6 of its
#: amplitude).
ORDERS = (1, 2, 3, 4, 5, 6)

#: 1 / Phi^-1(3/4): the median absolute deviation of a Gaussian times this is its sigma.
_MAD_TO_STD = 1.482602218505602

#: Fewest finite differences an order needs to count.
_MIN_SAMPLES = 16

#: Rows a long log is measured on: :data:`_BLOCKS` contiguous blocks spread over it (a
#: MAD of 20000 samples is within about 1 % of sigma; the measurement of a 60 s, 1 kHz
#: Panda log took 0.38 s on all of its rows, 2-core shared VM).
MAX_ROWS = 20000
_BLOCKS = 8


@dataclass(frozen=True)
class ChannelNoise:
    """The noise floor of one channel.

    Attributes:
        std: Its estimated noise standard deviation [channel unit: rad, rad/s]; 0 for a
            constant channel.
        order: The difference order whose estimate was the smallest (0: none counted, the
            resolution floor or a constant channel).
        resolution: The step of a quantised channel [unit] (its changes are whole multiples
            of it: the encoder's resolution), 0 for a continuous one, NaN when constant.
        constant: Whether the channel never changed (fewer than two distinct values), or is
            too short for any order (fewer than 16 + m finite samples) and not quantised:
            it says nothing about its noise.
    """

    std: float
    order: int
    resolution: float
    constant: bool


@dataclass(frozen=True)
class EncoderNoise:
    """The encoder noise of a log: each joint's position and velocity channel.

    Attributes:
        q: Per joint, the position channel [rad].
        qd: Per joint, the velocity channel [rad/s].
        repeated: Rows left out because they repeat the previous row in every channel.
    """

    q: tuple[ChannelNoise, ...]
    qd: tuple[ChannelNoise, ...]
    repeated: int = 0

    @property
    def q_std(self) -> float | None:
        """Median over the joints' non-constant position channels [rad] (None: all
        constant)."""
        return _median(self.q)

    @property
    def qd_std(self) -> float | None:
        """Median over the joints' non-constant velocity channels [rad/s] (None: all
        constant)."""
        return _median(self.qd)

    def line(self) -> str:
        """What ``amsfe estimate`` prints: the medians and, per channel kind, the range."""

        def part(name: str, chans: tuple[ChannelNoise, ...], med: float | None, unit: str) -> str:
            if med is None:
                return f"{name} constant on every joint"
            live = [c.std for c in chans if not c.constant]
            spread = f", joints {min(live):.1e}..{max(live):.1e}" if len(live) > 1 else ""
            flat = sum(c.constant for c in chans)
            more = f", {flat} constant" if flat else ""
            return f"{name} {med:.1e} {unit}{spread}{more}"

        return (
            f"{part('q', self.q, self.q_std, 'rad')}; "
            f"{part('qd', self.qd, self.qd_std, 'rad/s')} (median over joints)"
        )


def _median(chans: tuple[ChannelNoise, ...]) -> float | None:
    live = [c.std for c in chans if not c.constant]
    return float(np.median(live)) if live else None


def _resolution(x: NDArray[np.float64]) -> float:
    """The step of a quantised channel: the smallest change between consecutive samples
    (changes below 1e-9 of the channel's magnitude ignored: float rounding of one lattice
    point) when at least 90 % of the changes are whole multiples of it (to 1 %); 0 for a
    channel that is not quantised (a continuous one, or one that moves by more than a step
    every sample); NaN when ``x`` never changes."""
    v = x[np.isfinite(x)]
    if v.size < 2:
        return math.nan
    tol = 1e-9 * max(1.0, float(np.max(np.abs(v))))
    d = np.abs(np.diff(x))
    d = d[np.isfinite(d) & (d > tol)]
    if not d.size:
        return math.nan
    step = float(np.min(d))
    ratio = d / step
    whole = np.abs(ratio - np.round(ratio)) < 0.01
    return step if np.mean(whole) >= 0.9 else 0.0


def channel_noise(x: NDArray[np.float64], orders: tuple[int, ...] = ORDERS) -> ChannelNoise:
    """The noise floor of one uniformly sampled channel ``x`` (NaN: a missing sample; the
    differences across it are left out).

    Returns:
        ``min_m s_m`` over ``orders`` (module docstring), floored by ``resolution /
        sqrt(12)`` on a quantised channel; 0 and ``constant`` for a channel that never changes.
    """
    x = np.asarray(x, dtype=np.float64)
    res = _resolution(x)
    if not math.isfinite(res):
        return ChannelNoise(0.0, 0, math.nan, True)
    best, order = math.inf, 0
    for m in orders:
        d = np.diff(x, m)
        d = d[np.isfinite(d)]
        if d.size < _MIN_SAMPLES:
            continue
        mad = float(np.median(np.abs(d - np.median(d))))
        s = _MAD_TO_STD * mad / math.sqrt(math.comb(2 * m, m))
        if s < best:
            best, order = s, m
    floor = res / math.sqrt(12.0)
    if math.isinf(best) and floor == 0.0:  # too short to tell, and not quantised
        return ChannelNoise(0.0, 0, res, True)
    if not best > floor:  # no order counted, or the rounding error dominates
        return ChannelNoise(floor, 0, res, False)
    return ChannelNoise(best, order, res, False)


def _blocks(z: NDArray[np.float64], max_rows: int) -> NDArray[np.float64]:
    """``z`` itself, or (longer than ``max_rows``) :data:`_BLOCKS` contiguous blocks of it
    spread evenly, a NaN row between blocks (no difference spans two)."""
    rows, size = len(z), max_rows // _BLOCKS
    if rows <= max_rows:
        return z
    nan = np.full((1, z.shape[1]), np.nan)
    parts = []
    for start in np.linspace(0, rows - size, _BLOCKS).astype(int):
        parts += [z[start : start + size], nan]
    return np.concatenate(parts)


def encoder_noise(z: NDArray[np.float64], n: int, max_rows: int = MAX_ROWS) -> EncoderNoise:
    """The noise of a log's encoder samples ``z`` = [positions, velocities] per tick,
    (K, 2n) [rad, rad/s] (a row of NaN: no sample): :func:`channel_noise` of each column,
    rows repeating the previous row in every channel left out (``repeated`` counts them
    over the whole log), on at most about ``max_rows`` rows (:func:`_blocks`)."""
    z = np.array(z, dtype=np.float64, copy=True)
    same = np.zeros(len(z), dtype=bool)
    if len(z) > 1:
        same[1:] = np.all(z[1:] == z[:-1], axis=1)
    z[same] = np.nan
    z = _blocks(z, max_rows)
    chans = tuple(channel_noise(z[:, j]) for j in range(2 * n))
    return EncoderNoise(chans[:n], chans[n:], int(same.sum()))
