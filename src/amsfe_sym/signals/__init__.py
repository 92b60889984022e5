"""Signals: the simulated sensors (motor encoders every step, a slow and late camera,
torque noise) and the desired trajectories.

These produce the measurements of the paper's eqs. (5)-(11) from the TRUE plant state:

* :class:`Encoders` -- the fast motor-side measurement ``z_m = [qm, qmd] + v_m``
  (eqs. 5-6), delivered at every step ``k`` (sampling interval ``T`` [s]).
* :class:`Camera` -- the slow link-side measurement ``z_c = h_c(q) + v_c`` [px]
  (eqs. 7-10): one exposure every ``l`` steps (eq. 11, ``s_m = l s_c``), delivered ``d``
  steps after the exposure.  ``d`` and ``l`` are independent here (the paper's study has
  ``d = l = 125``); ``d > l`` means several frames are in flight at once.
* :class:`Disturbance` -- process noise: torques [N m] on link and motor for the plant.

All randomness comes from ONE :class:`numpy.random.Generator` given to each sensor (the
caller may give every sensor its own generator, e.g. spawned from one seed with
``numpy.random.default_rng(seed).spawn(3)``).  Every sensor draws the same amount of
random numbers per event whatever its configuration (noise, drop and jitter are always
drawn), so changing, say, ``drop_probability`` keeps the pixel-noise realisations of the
frames that survive: runs differ only in what was changed (common random numbers).

Errors follow :mod:`amsfe_sym.errors`: a bad configuration raises
:class:`~amsfe_sym.errors.ConfigError`, a wrongly shaped array
:class:`~amsfe_sym.errors.ShapeError`, a NaN or inf true state
:class:`~amsfe_sym.errors.MeasurementError`.

Modules: ``encoders`` (:class:`Encoders`, :class:`Disturbance`), ``camera``
(:class:`Camera`), ``trajectory`` (the desired trajectories), ``checks`` (shared value checks).
Pure numpy.  May import: errors, core, load.spec (types only).
"""

from amsfe_sym.signals.camera import Camera, CameraConfig, CameraFrame, CameraStats
from amsfe_sym.signals.encoders import Disturbance, EncoderConfig, Encoders, TorqueNoise

__all__ = [
    "Camera",
    "CameraConfig",
    "CameraFrame",
    "CameraStats",
    "Disturbance",
    "EncoderConfig",
    "Encoders",
    "TorqueNoise",
]
