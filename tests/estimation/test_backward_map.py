"""``oosm``'s two backward maps (eq. (24)) on a linear model: the same filter.

For ``x+ = A x + B u`` the linearised map (about the stored forward pass) and the paper's
inverse map (``L`` applications of ``A^-1 (x - B u)``, jacobian ``A^-L`` at any point) are the
same function, so every estimate, covariance and decision of a whole run must agree to
rounding.  The runs use the randomised system of test_estimation_filters.py.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.estimation.base import FilterConfig
from amsfe_sym.estimation.oosm import backward_inverse
from tests.estimation.test_estimation_filters import (
    Scenario,
    System,
    _NoInverse,
    build,
    make_system,
    simulate,
)

LINEAR_SCENARIOS = [
    Scenario(l=1, d=1),  # one-step lag: A1 exact
    Scenario(l=3, d=3, enc_every=3),  # lag 3, no encoder update inside the lag
    Scenario(l=4, d=4, enc_every=4, n_steps=90),
    Scenario(l=6, d=2, enc_every=2, drop_every=3),  # lost frames
]


@pytest.mark.parametrize("name", ["oosm", "oosm-al1"])
@pytest.mark.parametrize("sc", LINEAR_SCENARIOS, ids=lambda s: f"l{s.l}-d{s.d}-e{s.enc_every}")
def test_the_two_maps_agree_on_a_linear_model(name: str, sc: Scenario) -> None:
    system = make_system(seed=2)
    run = simulate(system, sc, seed=11)
    a = build(name, system, sc)
    b = build(name, system, sc, backward_map="inverse")
    assert a.config.backward_map == "linearised"
    applied = 0
    for k in range(sc.n_steps):
        frames = run.frames.get(k + 1, [])
        ra = a.step(run.u[k], run.z_enc[k + 1], frames)
        rb = b.step(run.u[k], run.z_enc[k + 1], frames)
        assert (ra.frames_applied, ra.frames_rejected) == (rb.frames_applied, rb.frames_rejected)
        np.testing.assert_allclose(ra.frame_nis, rb.frame_nis, rtol=1e-12, atol=0)
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.P, b.P, rtol=0, atol=1e-12)
        applied += ra.frames_applied
    assert applied >= 5  # late frames were used, so the maps ran


def test_backward_inverse_is_the_inverse_and_its_jacobian() -> None:
    """backward_inverse against the closed form: x = A^-L (x_end - sum ...), Phi = A^L."""
    system = make_system(seed=3)
    model, rng = system.model, np.random.default_rng(7)
    us = [rng.standard_normal(2) for _ in range(6)]
    x_start = rng.standard_normal(5)
    x = x_start
    for u in us:
        x = model.step(x, u)[0]
    back = backward_inverse(model, x, us)
    np.testing.assert_allclose(back.x, x_start, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.Phi, np.linalg.matrix_power(model.A, 6), rtol=0, atol=1e-12)


def test_a_non_converged_inverse_refuses_the_frame(caplog: pytest.LogCaptureFixture) -> None:
    """An inverse that raises ConvergenceError: every late frame is refused (counted, with the
    reason), the estimate is the encoders-only one; the linearised map never calls it."""
    system = make_system()
    sc = Scenario(l=3, d=3, enc_every=3)
    run = simulate(system, sc, seed=5)
    m = system.model
    bad = System(_NoInverse(m.A, m.B, m.Q), system.encoder, system.camera, system.x0, system.P0)
    inv, lin = build("oosm", bad, sc, backward_map="inverse"), build("oosm", bad, sc)
    enc = build("encoders", bad, sc)
    refused = applied = 0
    with caplog.at_level(logging.WARNING, logger="amsfe_sym.estimation"):
        for k in range(sc.n_steps):
            frames = run.frames.get(k + 1, [])
            r = inv.step(run.u[k], run.z_enc[k + 1], frames)
            applied += lin.step(run.u[k], run.z_enc[k + 1], frames).frames_applied
            enc.step(run.u[k], run.z_enc[k + 1], frames)
            refused += r.frames_rejected
            assert r.frames_applied == 0
            assert all("did not converge" in msg for msg in r.rejections)
    assert refused >= 15 and applied == refused
    assert np.isfinite(inv.x).all()
    np.testing.assert_array_equal(inv.x, enc.x)
    np.testing.assert_array_equal(inv.P, enc.P)
    assert "did not converge" in caplog.text


def test_filter_config_refuses_an_unknown_map() -> None:
    for bad in ("exact", "", "Inverse", None, 1):
        with pytest.raises(ConfigError, match="backward_map"):
            FilterConfig(backward_map=bad)  # type: ignore[arg-type]
