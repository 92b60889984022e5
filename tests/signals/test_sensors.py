"""Tests of the simulated sensors: encoders, camera timing / loss / visibility, torque noise."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, MeasurementError, ShapeError
from amsfe_sym.load.spec import CameraSpec
from amsfe_sym.signals import (
    Camera,
    CameraConfig,
    CameraFrame,
    Disturbance,
    EncoderConfig,
    Encoders,
)


def linear_projection(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """A toy camera: pixel = (320 + 100 q0, 256 + 100 q1)."""
    return np.array([320.0 + 100.0 * q[0], 256.0 + 100.0 * q[1]])


def run_camera(cam: Camera, steps: int, q: Any = (0.0, 0.0)) -> list[CameraFrame]:
    frames: list[CameraFrame] = []
    for k in range(steps):
        frames.extend(cam.tick(k, np.asarray(q, dtype=float)))
    return frames


# --------------------------------------------------------------------------------------
# encoders


def test_encoders_noise_free_returns_truth() -> None:
    enc = Encoders(2, EncoderConfig(), np.random.default_rng(0))
    z = enc.measure([0.1, -0.2], [1.0, 2.0])
    assert z.shape == (4,)
    np.testing.assert_array_equal(z, [0.1, -0.2, 1.0, 2.0])


def test_encoders_noise_statistics_per_joint() -> None:
    cfg = EncoderConfig(q_std=[1e-3, 2e-3], qd_std=0.05)
    enc = Encoders(2, cfg, np.random.default_rng(1))
    z = np.array([enc.measure([0.0, 0.0], [0.0, 0.0]) for _ in range(20000)])
    std = z.std(axis=0)
    np.testing.assert_allclose(std, [1e-3, 2e-3, 0.05, 0.05], rtol=0.03)
    assert np.all(np.abs(z.mean(axis=0)) < 4 * std / math.sqrt(len(z)))
    np.testing.assert_allclose(enc.variance, [1e-6, 4e-6, 0.0025, 0.0025])


def test_encoders_quantize_angle_only() -> None:
    cfg = EncoderConfig(q_std=0.0, qd_std=0.0, counts_per_rev=4096)
    enc = Encoders(1, cfg, np.random.default_rng(2))
    res = 2 * math.pi / 4096
    assert cfg.resolution == pytest.approx(res)
    qs = np.linspace(-3.0, 3.0, 997)
    for q in qs:
        z = enc.measure([q], [0.123456])
        assert z[1] == 0.123456  # rate not quantized
        counts = z[0] / res
        assert counts == pytest.approx(round(counts), abs=1e-9)
        assert abs(z[0] - q) <= res / 2 + 1e-12
    np.testing.assert_allclose(enc.variance, [res**2 / 12, 0.0])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"q_std": -1.0},
        {"qd_std": float("nan")},
        {"q_std": [1e-3, -1e-3]},
        {"q_std": [[1e-3]]},
        {"q_std": "abc"},
        {"counts_per_rev": 0},
        {"counts_per_rev": 2.5},
        {"counts_per_rev": True},
    ],
)
def test_encoder_config_rejects_bad_values(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ConfigError, match="Fix:"):
        EncoderConfig(**kwargs)


def test_encoders_shape_and_value_errors() -> None:
    with pytest.raises(ShapeError, match=r"2 values"):
        Encoders(3, EncoderConfig(q_std=[1.0, 2.0]), np.random.default_rng(0))
    with pytest.raises(ConfigError):
        Encoders(0, EncoderConfig(), np.random.default_rng(0))
    enc = Encoders(2, EncoderConfig(q_std=0.1), np.random.default_rng(0))
    with pytest.raises(ShapeError, match=r"expected shape \(2,\), found shape \(3,\)"):
        enc.measure([0.0, 0.0, 0.0], [0.0, 0.0])
    with pytest.raises(MeasurementError, match="finite"):
        enc.measure([0.0, np.nan], [0.0, 0.0])
    with pytest.raises(ValueError):  # errors also inherit the builtin
        enc.measure([0.0, 0.0], [np.inf, 0.0])


def test_encoders_deterministic_given_seed() -> None:
    cfg = EncoderConfig(q_std=1e-3, qd_std=1e-2, counts_per_rev=10000)

    def stream(seed: int) -> NDArray[np.float64]:
        enc = Encoders(2, cfg, np.random.default_rng(seed))
        return np.array([enc.measure([0.3 * k, 0.1], [1.0, -1.0]) for k in range(50)])

    np.testing.assert_array_equal(stream(7), stream(7))
    assert not np.array_equal(stream(7), stream(8))


# --------------------------------------------------------------------------------------
# camera configuration


@pytest.mark.parametrize(
    "kwargs",
    [
        {"period": 0},
        {"period": 2.0},
        {"delay": -1},
        {"pixel_std": -0.1},
        {"pixel_std": float("inf")},
        {"drop_probability": 1.0},
        {"drop_probability": -0.1},
        {"jitter_steps": -1},
        {"phase": 5},
        {"phase": -1},
        {"width": 0},
        {"round_to_pixel": 1},
    ],
)
def test_camera_config_rejects_bad_values(kwargs: dict[str, Any]) -> None:
    base: dict[str, Any] = {"period": 5, "delay": 3, "pixel_std": 1.0}
    base.update(kwargs)
    with pytest.raises(ConfigError, match=r"expected .* found .* Fix:"):
        CameraConfig(**base)


def test_camera_config_from_spec_and_variance() -> None:
    cfg = CameraConfig.from_spec(CameraSpec(), pixel_std=2.0, phase=3)
    assert (cfg.period, cfg.delay, cfg.width, cfg.height, cfg.phase) == (125, 125, 640, 512, 3)
    assert cfg.variance == pytest.approx(4.0 + 1.0 / 12.0)
    raw = CameraConfig(period=1, delay=0, pixel_std=2.0, round_to_pixel=False)
    assert raw.variance == pytest.approx(4.0)


# --------------------------------------------------------------------------------------
# camera timing


@pytest.mark.parametrize(
    ("period", "phase", "delay"),
    [(5, 0, 3), (5, 2, 5), (4, 1, 11), (1, 0, 0), (125, 0, 125), (3, 2, 0)],
)
def test_camera_schedule(period: int, phase: int, delay: int) -> None:
    cfg = CameraConfig(period=period, phase=phase, delay=delay, pixel_std=0.0)
    cam = Camera(cfg, linear_projection, np.random.default_rng(0))
    steps = 400
    seen: list[tuple[int, int]] = []
    for k in range(steps):
        for f in cam.tick(k, np.zeros(2)):
            assert f.delivery_step == k
            seen.append((f.exposure_step, k))
    expected = [(e, e + delay) for e in range(steps) if e % period == phase and e + delay < steps]
    assert seen == expected
    assert all(f_delay == delay for f_delay in (d - e for e, d in seen))
    # frames in flight at the end: exposures whose delivery is beyond the horizon
    in_flight = sum(1 for e in range(steps) if e % period == phase and e + delay >= steps)
    assert cam.in_flight == in_flight
    assert cam.stats.exposed == cam.stats.delivered + in_flight


def test_camera_delay_longer_than_period_has_several_frames_in_flight() -> None:
    cfg = CameraConfig(period=2, delay=7, pixel_std=0.0)
    cam = Camera(cfg, linear_projection, np.random.default_rng(0))
    for k in range(7):
        assert cam.tick(k, np.zeros(2)) == []
    assert cam.in_flight == 4  # exposures at 0, 2, 4, 6
    frames = cam.tick(7, np.zeros(2))
    assert [f.exposure_step for f in frames] == [0]
    assert frames[0].delay == 7


def test_camera_zero_delay_delivers_in_same_tick_with_correct_pixel() -> None:
    cfg = CameraConfig(period=3, delay=0, pixel_std=0.0)
    cam = Camera(cfg, linear_projection, np.random.default_rng(0))
    q = np.array([0.5, -0.25])
    frames = cam.tick(0, q)
    assert len(frames) == 1
    np.testing.assert_array_equal(frames[0].z, [370.0, 231.0])
    assert frames[0].exposure_step == 0
    assert cam.tick(1, q) == []


def test_camera_frame_is_immutable() -> None:
    cam = Camera(
        CameraConfig(period=1, delay=0, pixel_std=1.0), linear_projection, np.random.default_rng(0)
    )
    frame = cam.tick(0, np.zeros(2))[0]
    with pytest.raises(AttributeError):
        frame.exposure_step = 3  # type: ignore[misc]
    with pytest.raises(ValueError):
        frame.z[0] = 0.0


def test_camera_uses_q_at_exposure_not_delivery() -> None:
    cfg = CameraConfig(period=10, delay=10, pixel_std=0.0)
    cam = Camera(cfg, linear_projection, np.random.default_rng(0))
    delivered: list[CameraFrame] = []
    for k in range(40):
        q = np.array([0.01 * k, 0.0])
        delivered.extend(cam.tick(k, q))
    for f in delivered:
        assert f.z[0] == pytest.approx(round(320.0 + 100.0 * 0.01 * f.exposure_step))


def test_camera_steps_must_increase() -> None:
    cam = Camera(
        CameraConfig(period=2, delay=1, pixel_std=0.0), linear_projection, np.random.default_rng(0)
    )
    cam.tick(0, np.zeros(2))
    with pytest.raises(ConfigError, match="increasing"):
        cam.tick(0, np.zeros(2))
    with pytest.raises(ConfigError):
        cam.tick(1.5, np.zeros(2))  # type: ignore[arg-type]
    # skipping steps is allowed: due frames arrive at the next tick
    cam2 = Camera(
        CameraConfig(period=2, delay=1, pixel_std=0.0), linear_projection, np.random.default_rng(0)
    )
    cam2.tick(0, np.zeros(2))
    frames = cam2.tick(5, np.zeros(2))
    assert [(f.exposure_step, f.delivery_step) for f in frames] == [(0, 5)]


# --------------------------------------------------------------------------------------
# camera noise, rounding, loss, visibility


def test_camera_pixel_noise_statistics_and_rounding() -> None:
    cfg = CameraConfig(period=1, delay=0, pixel_std=2.0, round_to_pixel=False)
    cam = Camera(cfg, linear_projection, np.random.default_rng(3))
    z = np.array([f.z for f in run_camera(cam, 20000)])
    np.testing.assert_allclose(z.std(axis=0), 2.0, rtol=0.03)
    np.testing.assert_allclose(z.mean(axis=0), [320.0, 256.0], atol=0.06)

    cfg_r = CameraConfig(period=1, delay=0, pixel_std=2.0)
    cam_r = Camera(cfg_r, lambda q: np.array([320.3, 256.6]), np.random.default_rng(3))
    zr = np.array([f.z for f in run_camera(cam_r, 2000)])
    np.testing.assert_array_equal(zr, np.round(zr))
    np.testing.assert_allclose(zr.var(axis=0), cfg_r.variance, rtol=0.1)


def test_camera_drop_probability() -> None:
    cfg = CameraConfig(period=1, delay=0, pixel_std=0.0, drop_probability=0.3)
    cam = Camera(cfg, linear_projection, np.random.default_rng(4))
    frames = run_camera(cam, 10000)
    s = cam.stats
    assert s.exposed == 10000
    assert s.delivered == len(frames)
    assert s.delivered + s.dropped == s.exposed
    assert s.dropped / s.exposed == pytest.approx(0.3, abs=0.015)


def test_common_random_numbers_across_drop_settings() -> None:
    """Dropping frames does not change the noise of the frames that survive."""

    def frames(p: float) -> dict[int, NDArray[np.float64]]:
        cfg = CameraConfig(period=3, delay=2, pixel_std=1.5, drop_probability=p)
        cam = Camera(cfg, linear_projection, np.random.default_rng(11))
        return {f.exposure_step: f.z for f in run_camera(cam, 300)}

    all_frames, some = frames(0.0), frames(0.5)
    assert 0 < len(some) < len(all_frames)
    for k, z in some.items():
        np.testing.assert_array_equal(z, all_frames[k])


def test_camera_out_of_image_true_projection_and_nan() -> None:
    cfg = CameraConfig(period=1, delay=0, pixel_std=0.0, width=100, height=50)
    pixels = iter(
        [
            [10.0, 10.0],  # inside
            [100.0, 10.0],  # u == width: outside
            [-0.1, 10.0],  # outside
            [10.0, 50.0],  # v == height: outside
            [np.nan, 10.0],  # not visible (behind the camera)
            [0.0, 0.0],  # inside (corner)
            [99.4, 49.4],  # inside
        ]
    )
    cam = Camera(cfg, lambda q: np.array(next(pixels)), np.random.default_rng(0))
    got = [len(cam.tick(k, np.zeros(1))) for k in range(7)]
    assert got == [1, 0, 0, 0, 0, 1, 1]
    assert cam.stats.out_of_image == 4
    assert cam.stats.out_of_image_true == 4
    assert cam.stats.exposed == 7


def test_camera_out_of_image_after_noise() -> None:
    """A point on the border: noise pushes about half the measured pixels outside."""
    cfg = CameraConfig(period=1, delay=0, pixel_std=3.0, width=100, height=100)
    cam = Camera(cfg, lambda q: np.array([0.0, 50.0]), np.random.default_rng(5))
    frames = run_camera(cam, 2000, q=[0.0])
    s = cam.stats
    assert s.out_of_image_true == 0
    assert 0.3 < s.out_of_image / s.exposed < 0.7
    assert s.delivered == len(frames) == s.exposed - s.out_of_image
    assert all(0.0 <= f.z[0] < 100.0 for f in frames)


def test_camera_projection_shape_and_state_errors() -> None:
    cfg = CameraConfig(period=1, delay=0, pixel_std=0.0)
    cam = Camera(cfg, lambda q: np.zeros(3), np.random.default_rng(0))
    with pytest.raises(ShapeError, match=r"shape \(2,\)"):
        cam.tick(0, np.zeros(2))
    cam = Camera(cfg, linear_projection, np.random.default_rng(0))
    with pytest.raises(MeasurementError):
        cam.tick(0, np.array([np.nan, 0.0]))
    with pytest.raises(ShapeError):
        cam.tick(1, np.zeros((2, 2)))


def test_camera_jitter_out_of_order_delivery() -> None:
    cfg = CameraConfig(period=2, delay=3, pixel_std=0.0, jitter_steps=8)
    cam = Camera(cfg, linear_projection, np.random.default_rng(6))
    order: list[int] = []
    for k in range(2000):
        frames = cam.tick(k, np.zeros(2))
        steps = [f.exposure_step for f in frames]
        assert steps == sorted(steps)  # sorted within a step
        for f in frames:
            assert 3 <= f.delay <= 11
        order.extend(steps)
    assert cam.stats.out_of_order > 0
    assert order != sorted(order)
    assert sorted(order) == sorted(set(order))  # each frame delivered once
    inversions = sum(1 for a, b in itertools.pairwise(order) if b < a)
    assert inversions <= cam.stats.out_of_order


@settings(max_examples=40, deadline=None)
@given(
    period=st.integers(1, 12),
    phase_frac=st.floats(0.0, 0.999),
    delay=st.integers(0, 30),
    jitter=st.integers(0, 10),
    drop=st.sampled_from([0.0, 0.25]),
    seed=st.integers(0, 2**32 - 1),
)
def test_camera_every_kept_frame_delivered_once_on_time(
    period: int, phase_frac: float, delay: int, jitter: int, drop: float, seed: int
) -> None:
    phase = int(phase_frac * period)
    cfg = CameraConfig(
        period=period,
        phase=phase,
        delay=delay,
        pixel_std=1.0,
        jitter_steps=jitter,
        drop_probability=drop,
    )
    cam = Camera(cfg, linear_projection, np.random.default_rng(seed))
    horizon = 150
    delivered: list[CameraFrame] = []
    for k in range(horizon + delay + jitter + 1):
        delivered.extend(cam.tick(k, np.zeros(2)))
    exposures = [e for e in range(horizon + delay + jitter + 1) if e % period == phase]
    s = cam.stats
    assert s.exposed == len(exposures)
    assert s.exposed == s.delivered + s.dropped + s.out_of_image + cam.in_flight
    steps = [f.exposure_step for f in delivered]
    assert len(steps) == len(set(steps))
    assert set(steps) <= set(exposures)
    for f in delivered:
        assert delay <= f.delay <= delay + jitter
    # every exposure before the horizon is due by now: delivered, or else dropped
    assert s.out_of_image == 0
    missing = {e for e in exposures if e < horizon} - set(steps)
    assert len(missing) <= s.dropped
    if drop == 0.0:
        assert not missing


def test_camera_deterministic_given_seed() -> None:
    cfg = CameraConfig(period=3, delay=4, pixel_std=1.3, drop_probability=0.2, jitter_steps=5)

    def stream(seed: int) -> list[tuple[int, int, float, float]]:
        cam = Camera(cfg, linear_projection, np.random.default_rng(seed))
        return [
            (f.exposure_step, f.delivery_step, float(f.z[0]), float(f.z[1]))
            for f in run_camera(cam, 500, q=[0.2, -0.1])
        ]

    assert stream(21) == stream(21)
    assert stream(21) != stream(22)


# --------------------------------------------------------------------------------------
# disturbance


def test_disturbance_statistics_and_determinism() -> None:
    dist = Disturbance(2, std_link=[0.1, 0.2], std_motor=0.0, rng=np.random.default_rng(9))
    samples = [dist.sample() for _ in range(20000)]
    link = np.array([s.link for s in samples])
    motor = np.array([s.motor for s in samples])
    assert link.shape == motor.shape == (20000, 2)
    np.testing.assert_allclose(link.std(axis=0), [0.1, 0.2], rtol=0.03)
    np.testing.assert_array_equal(motor, 0.0)

    def stream(seed: int) -> NDArray[np.float64]:
        d = Disturbance(3, 0.5, 0.1, np.random.default_rng(seed))
        return np.array(
            [np.concatenate([s.link, s.motor]) for s in (d.sample() for _ in range(20))]
        )

    np.testing.assert_array_equal(stream(1), stream(1))
    assert not np.array_equal(stream(1), stream(2))


def test_disturbance_rejects_bad_std() -> None:
    with pytest.raises(ConfigError):
        Disturbance(2, -1.0, 0.0, np.random.default_rng(0))
    with pytest.raises(ShapeError):
        Disturbance(2, [0.1, 0.1, 0.1], 0.0, np.random.default_rng(0))
