"""The iterated-EKF camera update: equal to the EKF for a linear h, better for a nonlinear h
far from the prior."""

from __future__ import annotations

import numpy as np

from amsfe_sym.estimation import FilterConfig, LinearMeasurement, LinearModel, make_estimator
from amsfe_sym.estimation.models import CameraFrame


class _Polar:
    """Nonlinear 'camera': range and bearing of a 2-D point, x = [px, py]."""

    dim = 2
    R = np.diag([1e-4, 1e-4])

    def predict(self, x):
        r = np.hypot(x[0], x[1])
        z = np.array([r, np.arctan2(x[1], x[0])])
        H = np.array([[x[0] / r, x[1] / r], [-x[1] / r**2, x[0] / r**2]])
        return z, H


def _est(camera, iterations: int, x0, P0):
    model = LinearModel(np.eye(2), np.zeros((2, 1)), 1e-8 * np.eye(2))
    encoder = LinearMeasurement(np.zeros((1, 2)), [[1.0]])
    return make_estimator(
        "naive",
        model=model,
        encoder=encoder,
        camera=camera,
        x0=x0,
        P0=P0,
        config=FilterConfig(gate_probability=None, camera_iterations=iterations),
    )


def test_linear_measurement_iterations_change_nothing() -> None:
    cam = LinearMeasurement([[1.0, 0.5], [0.0, 2.0]], np.diag([0.1, 0.2]))
    outs = []
    for it in (1, 4):
        e = _est(cam, it, [1.0, -1.0], np.diag([2.0, 3.0]))
        e.step(np.zeros(1), None, [CameraFrame(1, np.array([0.3, 0.7]))])
        outs.append((e.x.copy(), e.P.copy()))
    np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(outs[0][1], outs[1][1], rtol=0, atol=1e-12)


def test_iterations_fix_a_large_nonlinear_correction() -> None:
    truth = np.array([1.0, 1.0])
    z = _Polar().predict(truth)[0]  # noise-free
    errors = {}
    for it in (1, 5):
        e = _est(_Polar(), it, [2.0, 0.2], np.diag([1.0, 1.0]))
        e.step(np.zeros(1), None, [CameraFrame(1, z)])
        errors[it] = float(np.linalg.norm(e.x - truth))
    assert errors[5] < 0.2 * errors[1]
