"""The blended start's reference offsets (control/blend.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amsfe_sym.control.blend import A0, A1, B0, B1, blend_offsets, blend_time


def _deriv(c: tuple[float, ...], r: int, s: float) -> float:
    return sum(
        ci * math.factorial(i) / math.factorial(i - r) * s ** (i - r)
        for i, ci in enumerate(c)
        if i >= r
    )


@pytest.mark.parametrize("c, start", [(B0, [1, 0, 0, 0, 0]), (B1, [0, 1, 0, 0, 0])])
def test_the_basis_starts_as_asked_and_ends_flat(c: tuple[float, ...], start: list[int]) -> None:
    for r in range(5):
        assert _deriv(c, r, 0.0) == pytest.approx(start[r], abs=1e-12)
        assert _deriv(c, r, 1.0) == pytest.approx(0.0, abs=1e-9)


def test_the_second_derivative_bounds_hold() -> None:
    s = np.linspace(0, 1, 20001)
    for r in (2, 3, 4):
        for c, bound in ((B0, A0[r - 2]), (B1, A1[r - 2])):
            worst = max(abs(_deriv(c, r, x)) for x in s)
            assert bound - 1e-2 < worst <= bound  # a bound, and tight


def test_offsets_start_at_the_state_and_respect_the_acceleration_budget() -> None:
    d0, d1, accel = np.array([0.4, -0.5]), np.array([-3.0, 0.2]), 20.0
    tb = blend_time(d0, d1, accel)
    # the bound is tight on the worst joint
    assert max(abs(d0) * A0[0] / tb**2 + abs(d1) * A1[0] / tb) == pytest.approx(accel)
    o = blend_offsets(0.0, tb, d0, d1)
    np.testing.assert_allclose(o[:2], d0)
    np.testing.assert_allclose(o[2:4], d1)
    np.testing.assert_allclose(o[4:], 0.0, atol=1e-12)  # qdd, jerk, snap: the reference's
    acc = [np.abs(blend_offsets(s, tb, d0, d1)[4:6]).max() for s in np.linspace(0, tb, 400)]
    assert max(acc) <= accel * (1 + 1e-9)
    # continuous at the end, then zero
    near = blend_offsets(tb * (1 - 1e-10), tb, d0, d1)
    np.testing.assert_allclose(near, 0.0, atol=1e-5)
    assert not blend_offsets(tb, tb, d0, d1).any()
    # velocity is the derivative of the angle
    h = 1e-6
    s = 0.3 * tb
    fd = (blend_offsets(s + h, tb, d0, d1)[:2] - blend_offsets(s - h, tb, d0, d1)[:2]) / (2 * h)
    np.testing.assert_allclose(fd, blend_offsets(s, tb, d0, d1)[2:4], rtol=1e-6)


def test_the_rate_bounds_jerk_and_snap() -> None:
    d0, d1, accel, rate = np.array([0.05, 0.0]), np.array([0.5, -0.2]), 20.0, 10.0
    short = blend_time(d0, d1, accel)
    tb = blend_time(d0, d1, accel, rate)
    assert tb > short  # a rate offset over a short blend would have a large snap
    s = np.linspace(0, tb, 2000)
    o = np.array([blend_offsets(x, tb, d0, d1) for x in s])
    for r, lim in ((2, accel), (3, accel * rate), (4, accel * rate**2)):
        assert np.abs(o[:, 2 * r : 2 * r + 2]).max() <= lim * (1 + 1e-9)
    # and one of them is active
    bounds = [
        max(abs(d0) * A0[r - 2] / tb**r + abs(d1) * A1[r - 2] / tb ** (r - 1)) for r in (2, 3, 4)
    ]
    limits = [accel, accel * rate, accel * rate**2]
    assert min(lim / b for b, lim in zip(bounds, limits, strict=True)) == pytest.approx(1.0)


def test_no_budget_or_no_offset_is_no_blend() -> None:
    z = np.zeros(2)
    assert blend_time(np.ones(2), np.ones(2), math.inf) == 0.0
    assert blend_time(z, z, 20.0) == 0.0
    assert not blend_offsets(0.0, 0.0, np.ones(2), np.ones(2)).any()
