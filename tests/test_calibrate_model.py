"""The calibration's reprojection map (amsfe_sym.calibration.model): its jacobian against
finite differences, the map against the generated camera function at the spec's pose, the
link angles by effort kind, and the hold of a time offset that a motion cannot determine
(issue 35, item 5; docs/calibrate.md)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from amsfe_sym.apps.calibrate import CORNER_CAUTION, corner_caution
from amsfe_sym.calibration import (
    NP,
    LinkAngles,
    Observations,
    ReprojectionModel,
    calibrate,
    link_angles,
    smooth_angles,
)
from amsfe_sym.calibration.design import motion_information
from amsfe_sym.calibration.intervals import Z95
from amsfe_sym.calibration.model import CORNER_PARAMETERS, PARAMETERS, marker_corners_local
from amsfe_sym.errors import ConfigError, LogError
from amsfe_sym.load import load_robot
from amsfe_sym.load.types import Robot
from amsfe_sym.logs.read import RobotLog
from amsfe_sym.scenario import apply_sets, load_scenario
from amsfe_sym.signals.trajectory import from_config

DATA = Path(__file__).parent / "data" / "calibrate"
T = 0.001


@pytest.fixture(scope="module")
def robot() -> Robot:
    return load_robot(DATA / "robot.toml")


def _moving(K: int = 4000) -> LinkAngles:
    """Smooth link angles of the 3 joints over K ticks: a sweep across the camera's view (the
    calib-sim motion before the designed one)."""
    t = np.arange(K) * T
    q = np.stack(
        [
            1.2 * np.sin(1.3 * t),
            0.5 + 0.5 * np.sin(2.1 * t),
            0.8 + 0.8 * np.sin(2.9 * t),
        ],
        axis=1,
    )
    return LinkAngles(T, q, "synthetic")


def _x(robot: Robot, w: list[float], dc: list[float], o: list[float], dt: float) -> np.ndarray:
    return np.concatenate([w, robot.camera.position + np.array(dc), o, [dt]])


def _trial(robot: Robot, rng: np.random.Generator, trial: int) -> np.ndarray:
    """Parameters away from the start: a rotation vector, a moved camera, a marker offset, a
    time offset between ticks (no difference straddles an interpolation knot)."""
    return _x(
        robot,
        list(rng.normal(0, 0.03, 3)),
        list(rng.normal(0, 0.03, 3)),
        list(rng.normal(0, 0.02, 3)),
        0.0251 + 0.0003 * trial,
    )


def _columns_match(model: ReprojectionModel, x: np.ndarray) -> None:
    """Every column of the exact jacobian at ``x`` against central differences."""
    pr = model.project(x)
    assert pr.valid.all() and (pr.depth > 0).all()
    steps = np.array([1e-6] * 9 + [1e-7] + [1e-6] * (model.np - NP))
    for k in range(model.np):
        e = np.zeros(model.np)
        e[k] = steps[k]
        fd = (model.project(x + e).y - model.project(x - e).y) / (2 * steps[k])
        scale = max(1.0, float(np.abs(pr.J[:, :, k]).max()))
        np.testing.assert_allclose(
            pr.J[:, :, k], fd, rtol=0, atol=2e-6 * scale, err_msg=model.names[k]
        )


def test_jacobian_matches_finite_differences(robot: Robot) -> None:
    """Every column of the exact jacobian against central differences, at parameters away
    from the start (:func:`_trial`)."""
    links = _moving()
    stamp = (np.arange(200, 3800, 33) + 0.5) * T
    model = ReprojectionModel(robot, links, stamp, robot.camera.R_cw)
    assert model.names == PARAMETERS
    rng = np.random.default_rng(7)
    for trial in range(3):
        _columns_match(model, _trial(robot, rng, trial))


def test_corner_jacobian_matches_finite_differences(robot: Robot) -> None:
    """The corner fit's map (4 corners a frame, the marker's orientation as 3 more
    parameters): every column of its exact jacobian against central differences, and its
    corners around the centre fit's point (the marker's centre) at the same parameters."""
    links = _moving()
    stamp = (np.arange(200, 3800, 33) + 0.5) * T
    local = marker_corners_local(0.05)
    Rm0 = np.asarray(cv2.Rodrigues(np.array([0.3, -0.2, 0.1]))[0])
    model = ReprojectionModel(robot, links, stamp, robot.camera.R_cw, local, Rm0)
    centre = ReprojectionModel(robot, links, stamp, robot.camera.R_cw)
    assert model.names == CORNER_PARAMETERS and model.np == NP + 3
    rng = np.random.default_rng(8)
    for trial in range(2):
        x = _trial(robot, rng, trial)
        xc = np.concatenate([x, rng.normal(0, 0.1, 3)])
        pr = model.project(xc)
        assert pr.y.shape == (stamp.size, 8) and pr.J.shape == (stamp.size, 8, NP + 3)
        mid = pr.y.reshape(-1, 4, 2).mean(axis=1)  # (a square's corners: near its centre)
        assert np.abs(mid - centre.project(x).y).max() < 1.0
        _columns_match(model, xc)


def test_map_is_the_generated_camera_at_the_spec_pose(robot: Robot, libraries: object) -> None:
    """At the spec's pose, its marker offset and no time offset the map is the generated
    ``camera`` (eq. 6-7) at the frames' link angles to 1e-9 px, and its time-offset column is
    ``-camera_jacobian(q) qdot``."""
    _, lib = libraries.get(DATA / "robot.toml", parts=("model",))  # type: ignore[attr-defined]
    cam, jac = lib.function("camera"), lib.function("camera_jacobian")
    links = _moving()
    stamp = (np.arange(100, 3900, 33) + 0.25) * T
    model = ReprojectionModel(robot, links, stamp, robot.camera.R_cw)
    x = np.concatenate([np.zeros(3), robot.camera.position, robot.tracked_offset, [0.0]])
    pr = model.project(x)
    q, qdot, ok = links.at(stamp)
    assert ok.all()
    theta = np.zeros(lib.p)
    for i in range(stamp.size):
        y = cam(q[i], theta)[0].reshape(2)
        np.testing.assert_allclose(pr.y[i], y, rtol=0, atol=1e-9)
        Jq = jac(q[i], theta)[0].reshape(2, -1)
        np.testing.assert_allclose(pr.J[i, :, 9], -Jq @ qdot[i], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(pr.y[i], robot.camera.project(pr.r[i]), atol=1e-9)


def _log(z: np.ndarray, u: np.ndarray, effort: np.ndarray | None, kind: str) -> RobotLog:
    return RobotLog(
        path=Path("synthetic"),
        T=T,
        t0_ns=0,
        z=z,
        u=u,
        frames=[],
        effort=effort,
        effort_kind=kind,  # type: ignore[arg-type]
    )


def test_link_angles_by_effort_kind(robot: Robot) -> None:
    """q = qm - tau_J / Ks for a joint torque; from the motor rows of eq. (1b) for an applied
    torque (exact on a motion whose motor acceleration the central difference gets right);
    the positions themselves without effort.  Smoothed (the default), a motion this slow
    is unchanged to 1e-8 rad."""
    K, n = 2000, 3
    t = np.arange(K) * T
    qm = np.stack([0.3 * np.sin(2 * t + j) for j in range(n)], axis=1)
    qmd = np.stack([0.6 * np.cos(2 * t + j) for j in range(n)], axis=1)
    qmdd_exact = np.stack([-1.2 * np.sin(2 * t + j) for j in range(n)], axis=1)
    z = np.concatenate([qm, qmd], axis=1)
    Ks, Mm, Fm = robot.Ks, robot.Mm, robot.Fm
    tau = np.stack([2.0 + np.sin(t + j) for j in range(n)], axis=1)  # spring torque
    got = link_angles(_log(z, np.zeros((K, n)), tau, "joint_torque"), Ks, Mm, Fm, smooth=False)
    np.testing.assert_allclose(got.q, qm - tau / Ks, rtol=0, atol=1e-15)
    u = Mm * qmdd_exact + Fm * qmd + tau
    got = link_angles(_log(z, u, u, "applied"), Ks, Mm, Fm, smooth=False)
    h = 10
    # the central difference of a sinusoid over +-h ticks: sin(w h T) / (w h T) of the truth
    np.testing.assert_allclose(got.q[h:-h], (qm - tau / Ks)[h:-h], rtol=0, atol=1e-7)
    assert np.isnan(got.q[:h]).all()
    smoothed = link_angles(_log(z, u, u, "applied"), Ks, Mm, Fm)
    np.testing.assert_allclose(smoothed.q[h:-h], got.q[h:-h], rtol=0, atol=1e-8)
    assert np.isnan(smoothed.q[:h]).all() and "Savitzky-Golay" in smoothed.note
    got = link_angles(_log(z, np.zeros((K, n)), None, "none"), Ks, Mm, Fm, smooth=False)
    np.testing.assert_array_equal(got.q, qm)
    assert "ignored" in got.note
    got = link_angles(_log(z, np.zeros((K, n)), tau, "joint_torque"), Ks, Mm, Fm, "link", False)
    np.testing.assert_array_equal(got.q, qm)


def test_smoothing_is_savgol_and_quiets_the_time_offsets_slope() -> None:
    """The link angles' smoothing is scipy's ``savgol_filter`` (cubic, 21 ticks, mode
    "interp") run by finite run, to 1e-12; a gap stays NaN, a run shorter than the window
    stays raw; on 2e-4 rad of encoder noise the slope between ticks, which the time offset's
    jacobian column is made of (model.py), has ~0.28 rad/s of noise raw and under a tenth of
    that smoothed."""
    from scipy.signal import savgol_filter

    rng = np.random.default_rng(11)
    q = rng.normal(size=(3000, 3))
    q[1000:1010] = np.nan  # a gap
    q[[2000, 2016]] = np.nan  # a 15-tick run between: shorter than the 21-tick window
    got, h = smooth_angles(q, T)
    assert h == 10
    for a, b in [(0, 1000), (1010, 2000), (2017, 3000)]:
        want = savgol_filter(q[a:b], 21, 3, axis=0, mode="interp")
        np.testing.assert_allclose(got[a:b], want, rtol=0, atol=1e-12)
    assert np.isnan(got[1000:1010]).all() and np.isnan(got[[2000, 2016]]).all()
    np.testing.assert_array_equal(got[2001:2016], q[2001:2016])
    assert smooth_angles(q, 0.01)[1] == 0  # 100 Hz: a 3-tick window, nothing smoothed

    noise = rng.normal(0.0, 2e-4, (30000, 3))
    raw_slope = np.diff(noise, axis=0) / T
    smooth_slope = np.diff(smooth_angles(noise, T)[0], axis=0) / T
    assert 0.25 < raw_slope.std() < 0.31
    assert smooth_slope[20:-20].std() < 0.1 * raw_slope.std()


def _synthetic(
    robot: Robot, links: LinkAngles, stamp: np.ndarray, x_true: np.ndarray, seed: int
) -> Observations:
    """Frames seen by a camera at ``x_true`` with 1 px noise."""
    model = ReprojectionModel(robot, links, stamp, robot.camera.R_cw)
    y = model.project(x_true).y
    y += np.random.default_rng(seed).normal(0, 1.0, y.shape)
    steps = np.rint(stamp / T).astype(np.int64)
    return Observations(stamp, y, steps, {})


def test_recovers_a_synthetic_camera(robot: Robot) -> None:
    """Frames made by the map itself (a moved camera, a marker offset, 20 ms late stamps):
    the fit finds them within its stated intervals (4 sigma) and the issue's bounds."""
    links = _moving(31000)
    stamp = np.arange(100, 30900, 33) * T
    x_true = _x(robot, [0.02, -0.015, 0.01], [0.02, -0.01, 0.015], [0.01, -0.012, 0.008], 0.02)
    obs = _synthetic(robot, links, stamp, x_true, seed=1)
    cal = calibrate(robot, links, obs)
    R_true = ReprojectionModel(robot, links, stamp, robot.camera.R_cw).rotation(x_true[:3])
    assert cal.held == {}
    err_pos = cal.position - x_true[3:6]
    assert np.linalg.norm(err_pos) < 2e-3
    assert np.all(np.abs(err_pos) < 4 * cal.std[3:6])
    dR = cal.R_cw @ R_true.T
    assert np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 0.1
    assert np.linalg.norm(cal.offset - x_true[6:9]) < 1e-3
    assert abs(cal.time_offset - 0.02) < 1e-3
    assert abs(cal.time_offset - 0.02) < 4 * cal.std[9]
    assert 0.9 < cal.pixel_std < 1.1
    # dropped: only frames the moved camera does not see (the map has no other error)
    inside = (obs.pixel >= 0).all(axis=1) & (obs.pixel[:, 0] < 640) & (obs.pixel[:, 1] < 480)
    assert set(cal.dropped.values()) <= {"pixel outside the image"}
    assert cal.used.sum() == inside.sum() > 800
    # the correlations and sigmas: those of the sandwich (J^T J)^-1 M (J^T J)^-1 at the
    # solution, computed here without scaling; its middle from the residuals (white noise:
    # the sandwich, no correlation over frames to speak of)
    J = ReprojectionModel(robot, links, stamp, cal.R0).project(cal.x).J[cal.used].reshape(-1, NP)
    assert cal.errors is not None and cal.errors.kind == "sandwich"
    assert corner_caution(cal) == []  # a centre fit's intervals hold on images
    assert cal.errors.bandwidth <= 2
    Hi = np.linalg.inv(J.T @ J)
    C = Hi @ cal.errors.middle @ Hi
    np.testing.assert_allclose(cal.correlation, C / np.outer(*[np.sqrt(np.diag(C))] * 2), atol=1e-8)
    np.testing.assert_allclose(cal.std, np.sqrt(np.diag(C)), rtol=1e-8)
    np.testing.assert_allclose(cal.std_white, np.sqrt(np.diag(cal.pixel_std**2 * Hi)), rtol=1e-8)


def test_recovers_a_synthetic_camera_from_the_marker_corners(robot: Robot, tmp_path: Path) -> None:
    """The marker's 4 corners per frame (5 cm, turned on its link, 1 px noise on each), as an
    image log gives them: the corner fit runs (13 parameters, 8 residuals a frame), finds
    the camera, the marker's offset and orientation and the time offset within 4 of its
    stated sigmas; a frame with one corner 40 px off is dropped whole; the report says which
    fit ran; the written robot.toml carries ``[tracked] orientation``, which loads."""
    import tomllib

    from amsfe_sym.apps.calibrate import report_lines
    from amsfe_sym.calibration.spec_out import calibrated_spec
    from amsfe_sym.load.spec import load_spec

    links = _moving(12000)
    stamp = np.arange(100, 11900, 33) * T
    x_true = _x(robot, [0.02, -0.015, 0.01], [0.02, -0.01, 0.015], [0.01, -0.012, 0.008], 0.02)
    Rm = np.asarray(cv2.Rodrigues(np.array([0.4, -0.3, 1.1]))[0])
    local = marker_corners_local(0.05)
    model = ReprojectionModel(robot, links, stamp, robot.camera.R_cw, local, Rm)
    y = model.project(np.concatenate([x_true, np.zeros(3)])).y
    y += np.random.default_rng(4).normal(0, 1.0, y.shape)
    y[40, 2] += 40.0  # one corner of frame 40 mis-detected
    corners = y.reshape(-1, 4, 2)
    centre = ReprojectionModel(robot, links, stamp, robot.camera.R_cw).project(x_true).y
    steps = np.rint(stamp / T).astype(np.int64)
    obs = Observations(stamp, centre, steps, {}, corners, 0.05)
    cal = calibrate(robot, links, obs)
    assert cal.fit == "corners" and cal.names == CORNER_PARAMETERS and cal.held == {}
    # amsfe calibrate --corners would say its intervals understate the error on images
    assert corner_caution(cal) == [CORNER_CAUTION]
    assert cal.corner_start is not None and cal.corner_start.rms < 50.0
    assert cal.dropped.get(40, "").startswith("outlier")
    assert all(why == "pixel outside the image" for i, why in cal.dropped.items() if i != 40)
    err = np.abs(cal.x[3:10] - x_true[3:10])
    assert np.all(err < 4 * cal.std[3:10]), (err, cal.std[3:10])
    assert cal.marker_R is not None
    dRm = cv2.Rodrigues(cal.marker_R @ Rm.T)[0].ravel()
    assert np.all(np.abs(dRm) < 4 * cal.std[10:13])
    R_true = ReprojectionModel(robot, links, stamp, robot.camera.R_cw).rotation(x_true[:3])
    dR = cv2.Rodrigues(cal.R_cw @ R_true.T)[0].ravel()
    assert np.all(np.abs(dR) < 4 * cal.std[0:3])
    assert 0.85 < cal.pixel_std < 1.15
    lines = report_lines(cal, robot, {})
    assert any(ln.strip().startswith("marker orientation") for ln in lines)
    text = calibrated_spec(robot, cal, "synthetic")
    written = tomllib.loads(text)["tracked"]["orientation"]
    (tmp_path / "robot.toml").write_text(text)
    q = load_spec(str(tmp_path / "robot.toml")).tracked.orientation
    assert q is not None
    np.testing.assert_allclose(q, written, atol=1e-12)


def test_time_offset_of_an_arm_that_stops_for_each_frame(robot: Robot) -> None:
    """An arm moved between poses and at rest at every exposure: the pose and the marker are
    determined, the time offset is not; it is held at 0 and the report names it."""
    from amsfe_sym.apps.calibrate import report_lines

    rng = np.random.default_rng(5)
    K, hold = 30000, 100
    poses = np.stack(
        [
            rng.uniform(-1.2, 1.2, K // hold),
            rng.uniform(0, 1, K // hold),
            rng.uniform(0, 1.6, K // hold),
        ],
        axis=1,
    )
    q = np.repeat(poses, hold, axis=0)
    links = LinkAngles(T, q, "synthetic")
    stamp = (np.arange(K // hold) * hold + hold // 2) * T  # mid-rest: +-50 ms of stillness
    x_true = _x(robot, [0.01, 0.0, -0.01], [0.01, 0.02, 0.0], [0.01, 0.0, -0.01], 0.0)
    cal = calibrate(robot, links, _synthetic(robot, links, stamp, x_true, seed=2))
    assert "time_offset" in cal.held and cal.time_offset == 0.0
    assert np.isnan(cal.std[9]) and not cal.free[9]
    assert np.isnan(cal.correlation[9]).all() and np.isnan(cal.correlation[:, 9]).all()
    np.testing.assert_allclose(np.diag(cal.correlation)[:9], 1.0, atol=1e-12)
    assert np.linalg.norm(cal.position - x_true[3:6]) < 5e-3
    lines = report_lines(cal, robot, {})
    held = [ln for ln in lines if "cannot determine the time offset" in ln]
    assert len(held) == 1 and "hardly moves" in held[0]
    assert any("time offset" in ln and "held" in ln for ln in lines)


def test_arm_at_rest_is_refused_in_one_line(robot: Robot) -> None:
    links = LinkAngles(T, np.tile([0.2, 0.5, 0.8], (5000, 1)), "synthetic")
    stamp = np.arange(100, 4900, 33) * T
    x = _x(robot, [0, 0, 0], [0, 0, 0], [0, 0, 0], 0.0)
    with pytest.raises(LogError) as err:
        calibrate(robot, links, _synthetic(robot, links, stamp, x, seed=3))
    msg = str(err.value)
    assert "\n" not in msg and "at rest" in msg and "time offset cannot be determined" in msg


def test_frames_without_encoders_are_dropped_by_reason(robot: Robot) -> None:
    links = _moving(31000)
    q = links.q.copy()
    q[15000:15200] = np.nan  # an encoder gap
    links = replace(links, q=q)
    stamp = np.arange(100, 30900, 33) * T
    x_true = _x(robot, [0, 0, 0], [0.01, 0, 0], [0, 0, 0], 0.01)
    obs = _synthetic(robot, links, stamp, x_true, seed=4)
    pix = obs.pixel.copy()
    pix[50] = [-5.0, 10.0]  # outside the image
    pix[60] += [40.0, -30.0]  # a wrong detection
    cal = calibrate(robot, links, replace(obs, pixel=pix))
    reasons = set(cal.dropped.values())
    assert cal.dropped[50] == "pixel outside the image"
    assert cal.dropped[60].startswith("outlier of the robust loss")
    assert any(r.startswith("no encoder sample") for r in reasons)
    gap = [i for i, r in cal.dropped.items() if r.startswith("no encoder")]
    assert all(14990 * T <= stamp[i] <= 15220 * T for i in gap)


def _planned(scenario: Path, K: int) -> LinkAngles:
    """The link angles of ``scenario``'s ``[trajectory]`` over K ticks (the arm following it)."""
    sc = load_scenario(scenario)
    return LinkAngles(T, from_config(sc.trajectory).evaluate(np.arange(K) * T).q, "planned")


def test_a_motion_s_predicted_intervals_are_the_fit_s(robot: Robot) -> None:
    """calibration.design, before recording: the 95 % half-widths it predicts for the
    calib-sim motion are those the fit states on frames the map makes from that motion with
    1 px noise, to 5 %; the designed motion narrows every group of parameters against the
    sweep across the view it replaced (docs/calibrate.md, "What the motion must do")."""
    links = _planned(DATA / "calib-sim.toml", 31000)
    stamp = np.arange(100, 30900, 33) * T
    info = motion_information(robot, links, stamp, pixel_std=1.0)
    x_true = _x(robot, [0.002, -0.001, 0.001], [0.002, -0.001, 0.0015], [0.001, 0.0, -0.001], 0.0)
    cal = calibrate(robot, links, _synthetic(robot, links, stamp, x_true, seed=3))
    assert cal.held == {} and info.seen.sum() > 850
    assert abs(int(cal.used.sum()) - int(info.seen.sum())) <= 5  # (the camera moved 2.6 mm)
    # the fit's white-noise width (its verdict's), per px of its measured noise; the stated
    # sandwich on white noise within its sampling spread of it
    stated = Z95 * cal.std_white / cal.pixel_std
    np.testing.assert_allclose(stated, info.half_width95(), rtol=0.05)
    np.testing.assert_allclose(cal.std, cal.std_white, rtol=0.12)
    assert np.all(np.abs(cal.x - x_true)[3:] < 4 * cal.std[3:])

    # the camera's rotation and position and the marker offset, each as the RMS of its
    # error: under 3/4 of the sweep's (over 1.8 times the information), in its weak direction
    # (the camera sideways and turned back about its y axis) under 2/3
    sweep = motion_information(robot, _moving(31000), stamp, pixel_std=1.0)
    for group in (slice(0, 3), slice(3, 6), slice(6, 9)):
        rms = [np.sqrt(np.trace(m.covariance[group, group])) for m in (info, sweep)]
        assert rms[0] < 0.75 * rms[1], (group, rms)
    assert np.all(info.half_width95()[[1, 4]] < 0.67 * sweep.half_width95()[[1, 4]])


def test_a_motion_that_sees_too_little_is_refused(robot: Robot) -> None:
    """A marker held still determines nothing: one line naming the motion."""
    links = LinkAngles(T, np.tile([0.0, 0.5, 0.8], (4000, 1)), "still")
    with pytest.raises(ConfigError, match="calibration motion"):
        motion_information(robot, links, np.arange(100, 3900, 33) * T, pixel_std=1.0)


def test_a_trajectory_key_is_set_from_the_command_line() -> None:
    """``--set trajectory.amplitude=...`` (a calibration motion tried without editing the
    scenario): a [trajectory] list takes numbers separated by commas or a TOML list."""
    sc = load_scenario(DATA / "calib-sim.toml")
    for value in ("1.2,0.5,0.8", "[1.2, 0.5, 0.8]"):
        got = apply_sets(sc, [f"trajectory.amplitude={value}"]).trajectory["amplitude"]
        assert got == [1.2, 0.5, 0.8]
    with pytest.raises(ConfigError, match=r"trajectory\.omega"):
        apply_sets(sc, ["trajectory.omega=fast"])
