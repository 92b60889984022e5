"""The blended start's reference offsets (control/blend.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amsfe_sym.control.blend import A0, A1, B0, B1, blend_offsets, blend_through, blend_time


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


def _budget_used(tb: float, d0: np.ndarray, d1: np.ndarray, accel: float, rate: float) -> float:
    """The largest share of its budget any derivative of the offset uses, on a fine grid."""
    o = np.array([blend_offsets(x, tb, d0, d1) for x in np.linspace(0, tb, 4001)])
    lims = (accel, accel * rate, accel * rate**2)
    return max(np.abs(o[:, 2 * r : 2 * r + 2]).max() / lims[r - 2] for r in (2, 3, 4))


@pytest.mark.parametrize(
    ("e0", "e1", "wait"),
    [
        ((-0.77, 0.27), (-5.95, -2.16), 0.087),  # a moving start trusted after ~85 ms
        ((0.01, 0.0), (0.05, 0.0), 0.087),  # a small offset: the blend is short
        ((0.1, -0.2), (-3.0, 1.0), 0.3),  # the paper model's wait
    ],
)
def test_a_blend_planned_before_passes_through_the_state(
    e0: tuple[float, ...], e1: tuple[float, ...], wait: float
) -> None:
    """blend_through: the blend started ``wait`` ago passes through (e0, e1) then, keeps its
    budgets over its whole length, and is the shortest that does (a shorter one breaks them)."""
    a0, a1, accel, rate = np.array(e0), np.array(e1), 25.0, 5.0
    tb, d0, d1 = blend_through(a0, a1, wait, accel, rate)
    assert tb > wait
    o = blend_offsets(wait, tb, d0, d1)
    np.testing.assert_allclose(o[:2], a0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(o[2:4], a1, rtol=0, atol=1e-12)
    assert _budget_used(tb, d0, d1, accel, rate) <= 1 + 1e-9
    assert blend_time(d0, d1, accel, rate) <= tb
    # the least such duration: 1e-6 s shorter, the solved blend needs longer than that
    from amsfe_sym.control.blend import _through

    short = tb - 1e-6
    s0, s1 = _through(a0, a1, wait, short)
    assert blend_time(s0, s1, accel, rate) > short


def test_the_flat_start_makes_the_plan_the_drift_taken_back() -> None:
    """b0 and b1 are flat to the 4th order at the start, so a wait much shorter than the
    blend gives d0 ~ e0 - e1 wait and d1 ~ e1: the plan the oracle would have made at the
    first tick had the arm moved on at its rate; and it is shorter than one planned now."""
    e0, e1, wait = np.array([-0.88, 0.26]), np.array([-5.8, -1.07]), 0.086
    tb, d0, d1 = blend_through(e0, e1, wait, 25.0, 5.0)
    # to O(tau^4), tau = wait / Tb ~ 0.06: b1'(tau) = 1 - 350 tau^4 + ..., ~0.3 %
    np.testing.assert_allclose(d0, e0 - e1 * wait, rtol=1e-2, atol=1e-3)
    np.testing.assert_allclose(d1, e1, rtol=1e-2)
    assert tb - wait < blend_time(e0, e1, 25.0, 5.0)


def test_no_wait_or_no_offset_is_the_blend_from_now() -> None:
    e0, e1 = np.array([0.3, 0.1]), np.array([0.2, 0.1])
    tb, d0, d1 = blend_through(e0, e1, 0.0, 25.0, 5.0)
    assert tb == blend_time(e0, e1, 25.0, 5.0)
    np.testing.assert_array_equal(d0, e0)
    np.testing.assert_array_equal(d1, e1)
    z = np.zeros(2)
    assert blend_through(z, z, 0.1, 25.0, 5.0)[0] == 0.0
    assert blend_through(e0, e1, 0.1, math.inf)[0] == 0.0
