"""The simulated motor encoders (paper eqs. 5-6) and the plant's process disturbance.
See :mod:`amsfe_sym.signals` for the conventions shared by every sensor."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from amsfe_sym.arrays import FloatArray
from amsfe_sym.signals.checks import StdLike, _check_std, _per_joint, _positive_int, _vector

__all__ = ["Disturbance", "EncoderConfig", "Encoders", "TorqueNoise"]


# --------------------------------------------------------------------------------------
# encoders, eqs. (5)-(6)


@dataclass(frozen=True)
class EncoderConfig:
    """Motor encoder noise and resolution.

    Attributes:
        q_std: Standard deviation of the motor-angle noise [rad]: a scalar or one value
            per joint.
        qd_std: Standard deviation of the motor-rate noise [rad/s]: scalar or per joint.
        counts_per_rev: Encoder counts per revolution.  When set, the measured motor angle
            is rounded to the nearest multiple of ``2 pi / counts_per_rev`` [rad] (after
            the noise is added, so the output always lies on the count grid).  The rate is
            not quantized (it stands for a filtered or tachometer rate).  ``None``: no
            quantization.

    Raises:
        ConfigError: a negative or non-finite standard deviation, or ``counts_per_rev`` not
            a positive integer.
    """

    q_std: StdLike = 0.0
    qd_std: StdLike = 0.0
    counts_per_rev: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "q_std", _check_std(self.q_std, "EncoderConfig.q_std"))
        object.__setattr__(self, "qd_std", _check_std(self.qd_std, "EncoderConfig.qd_std"))
        if self.counts_per_rev is not None:
            object.__setattr__(
                self,
                "counts_per_rev",
                _positive_int(self.counts_per_rev, "EncoderConfig.counts_per_rev", 1),
            )

    @property
    def resolution(self) -> float | None:
        """Angle of one encoder count, ``2 pi / counts_per_rev`` [rad], or ``None``."""
        if self.counts_per_rev is None:
            return None
        return 2.0 * math.pi / self.counts_per_rev


class Encoders:
    """Motor-side encoders of ``n`` joints: ``z_m(k) = [qm(k), qmd(k)] + v_m(k)``, eqs. (5)-(6).

    A measurement is available at every step.  The noise is zero-mean Gaussian and white;
    with ``counts_per_rev`` set the angle is also quantized (uniform error of variance
    ``res^2 / 12``, which :attr:`variance` includes so an estimator can use it as ``R_m``).

    Args:
        n: Number of joints.
        config: Noise and resolution.
        rng: The only source of randomness.

    Raises:
        ConfigError: ``n`` is not a positive integer.
        ShapeError: a per-joint standard deviation does not have ``n`` entries.
    """

    def __init__(self, n: int, config: EncoderConfig, rng: np.random.Generator) -> None:
        self.n = _positive_int(n, "Encoders n (number of joints)", 1)
        self.config = config
        self._rng = rng
        self._q_std = _per_joint(config.q_std, self.n, "EncoderConfig.q_std")
        self._qd_std = _per_joint(config.qd_std, self.n, "EncoderConfig.qd_std")

    @property
    def variance(self) -> FloatArray:
        """Effective measurement variance, shape (2n,): ``[q_std^2 + res^2/12, qd_std^2]``.

        Units [rad^2] then [rad^2/s^2]; the diagonal of ``R_m`` for the estimator (eq. 6).
        """
        res = self.config.resolution
        quant = 0.0 if res is None else res * res / 12.0
        return np.concatenate([self._q_std**2 + quant, self._qd_std**2])

    def measure(self, qm: ArrayLike, qmd: ArrayLike) -> FloatArray:
        """Measure the true motor angle and rate at the current step.

        Args:
            qm: True motor angles [rad], shape (n,).
            qmd: True motor rates [rad/s], shape (n,).

        Returns:
            ``z_m = [qm + v_q, qmd + v_qd]``, shape (2n,) [rad, rad/s]; the angle part is
            quantized to the count grid when ``counts_per_rev`` is set.

        Raises:
            ShapeError: ``qm`` or ``qmd`` is not of shape (n,).
            MeasurementError: ``qm`` or ``qmd`` holds NaN or inf.
        """
        qm_a = _vector(qm, self.n, "Encoders.measure qm [rad]")
        qmd_a = _vector(qmd, self.n, "Encoders.measure qmd [rad/s]")
        noise = self._rng.standard_normal(2 * self.n)
        z_q = qm_a + self._q_std * noise[: self.n]
        z_qd = qmd_a + self._qd_std * noise[self.n :]
        res = self.config.resolution
        if res is not None:
            z_q = np.round(z_q / res) * res
        return np.concatenate([z_q, z_qd])

    def noise_batch(self, count: int) -> FloatArray:
        """The scaled noise of the next ``count`` calls of :meth:`measure`, drawn in one batch
        from the same stream, shape (count, 2n) [rad, rad/s]: row i is what the i-th call
        adds before quantizing (the compiled loop reads it; the stream is used up)."""
        noise = self._rng.standard_normal(count * 2 * self.n).reshape(count, 2 * self.n)
        n = self.n
        return np.hstack([self._q_std * noise[:, :n], self._qd_std * noise[:, n:]])


# --------------------------------------------------------------------------------------
# process disturbance


@dataclass(frozen=True, eq=False)
class TorqueNoise:
    """One step's disturbance torques.

    Attributes:
        link: Torque on the link side [N m], shape (n,) (adds to ``Ks (qm - q)``, eq. 1b).
        motor: Torque on the motor side [N m], shape (n,) (adds to ``u``, eq. 1d).
    """

    link: FloatArray
    motor: FloatArray


class Disturbance:
    """White Gaussian torque noise for the plant, one sample per step.

    Args:
        n: Number of joints.
        std_link: Standard deviation of the link torque [N m], scalar or per joint.
        std_motor: Standard deviation of the motor torque [N m], scalar or per joint.
        rng: The only source of randomness (draws 2n standard normals per sample, even when
            a standard deviation is zero).

    Raises:
        ConfigError: ``n`` not a positive integer or a negative / non-finite std.
        ShapeError: a per-joint std without ``n`` entries.
    """

    def __init__(
        self, n: int, std_link: StdLike, std_motor: StdLike, rng: np.random.Generator
    ) -> None:
        self.n = _positive_int(n, "Disturbance n (number of joints)", 1)
        self.std_link = _per_joint(
            _check_std(std_link, "Disturbance std_link [N m]"), self.n, "Disturbance std_link"
        )
        self.std_motor = _per_joint(
            _check_std(std_motor, "Disturbance std_motor [N m]"), self.n, "Disturbance std_motor"
        )
        self._rng = rng

    def sample(self) -> TorqueNoise:
        """Draw this step's link and motor torques [N m]."""
        w = self._rng.standard_normal(2 * self.n)
        return TorqueNoise(link=self.std_link * w[: self.n], motor=self.std_motor * w[self.n :])

    def sample_batch(self, count: int) -> FloatArray:
        """The next ``count`` samples in one batch, rows [link, motor] [N m], (count, 2n)."""
        w = self._rng.standard_normal(count * 2 * self.n).reshape(count, 2 * self.n)
        n = self.n
        return np.hstack([self.std_link * w[:, :n], self.std_motor * w[:, n:]])
