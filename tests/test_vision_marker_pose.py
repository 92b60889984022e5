"""The marker fixed to its link (robot.toml ``[tracked] orientation``; docs/camera.md, "The
simulated camera's images"): its corners at their true pose, the centre unchanged, the frames
the camera does not see, and the detector finding the drawn corners where they project."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.load import load_robot
from amsfe_sym.load.rotation import matrix_to_quaternion
from amsfe_sym.logs.sim_marker import marker_pose_of, robot_marker_pose
from amsfe_sym.scenario import load_scenario
from amsfe_sym.vision.camera_info import make_camera_info, undistort
from amsfe_sym.vision.marker import MarkerDetector, diagonals_meet
from amsfe_sym.vision.marker_pose import MAX_VIEW_DEG, MIN_AREA_PX2, marker_view
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer, marker_corners
from amsfe_sym.vision.sim_images import LENSES, ImageOptions, SimulatedCamera
from amsfe_sym.vision.spec import MarkerSpec

DATA = Path(__file__).parent / "data" / "calibrate"
#: calib_arm's camera (tests/data/calibrate/robot.toml): 640 x 480, f = 500 px.
K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
I3 = np.eye(3)
#: The marker's frame facing a camera whose frame is the world's (x right, y down, z ahead):
#: its x along the camera's x, its y up (-y), its face toward the camera (-z).
FACING = np.diag([1.0, -1.0, -1.0])


def _turn(axis: np.ndarray, deg: float) -> np.ndarray:
    v = np.asarray(axis, dtype=float)
    return np.asarray(cv2.Rodrigues(v / np.linalg.norm(v) * math.radians(deg))[0])


def _tilted(rng: np.random.Generator, deg: float) -> np.ndarray:
    """The facing marker tilted ``deg`` about a random axis in its plane, turned in it."""
    axis = np.append(rng.normal(size=2), 0.0)
    return _turn(axis, deg) @ FACING @ _turn(np.array([0.0, 0.0, 1.0]), rng.uniform(-180, 180))


def test_a_marker_turned_to_face_the_camera_is_the_facing_square() -> None:
    """With its frame turned to face the camera the marker's corners are those of the
    facing-the-camera drawing (``marker_corners``, what a spec without orientation gets),
    for a camera looking any way and the marker off the link's origin."""
    rng = np.random.default_rng(1)
    R_cw = _turn(rng.normal(size=3), 40.0)
    position = np.array([0.2, -0.1, 0.3])
    R_f = _turn(rng.normal(size=3), 70.0)
    offset = np.array([0.01, 0.02, -0.03])
    centre = position + R_cw.T @ np.array([0.05, -0.03, 0.9])
    p_f = centre - R_f @ offset
    R_m = R_f.T @ R_cw.T @ FACING
    view = marker_view(K, R_cw, position, p_f, R_f, offset, R_m, 0.1)
    facing = marker_corners(K, R_cw, position, centre, 0.1)
    assert np.abs(view.corners - facing).max() < 1e-9
    assert view.angle_deg < 5.0 and view.seen  # (the line of sight is 3.9 deg off the axis)


def test_the_diagonals_meet_at_the_tracked_point() -> None:
    """An oblique marker's projected diagonals meet at the pinhole's pixel of its centre (the
    tracked point the estimator fuses), not at the mean of its corners."""
    R_m = _turn(np.array([1.0, 1.0, 0.0]), 55.0) @ FACING
    p = np.array([0.1, -0.05, 0.8])
    view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), R_m, 0.1)
    pixel = (K @ p)[:2] / p[2]
    assert np.abs(diagonals_meet(view.corners) - pixel).max() < 1e-9
    assert np.abs(view.corners.mean(axis=0) - pixel).max() > 0.1
    assert abs(view.angle_deg - 55.0) < 10.0 and view.seen


@pytest.mark.parametrize(
    ("deg", "depth", "seen"),
    [
        (70.0, 1.0, True),
        (MAX_VIEW_DEG + 3.0, 1.0, False),  # too oblique
        (180.0, 1.0, False),  # from behind
        (0.0, 5.0, False),  # 10 x 10 px: under MIN_AREA_PX2
        (0.0, -1.0, False),  # behind the camera
    ],
)
def test_the_camera_sees_the_marker_only_from_the_front(deg: float, depth: float, seen: bool):
    """Not drawn: seen from behind, past MAX_VIEW_DEG from face-on, under MIN_AREA_PX2 (the
    detector's limit, measured: docs/camera.md), behind the camera."""
    R_m = _turn(np.array([0.0, 1.0, 0.0]), deg) @ FACING
    view = marker_view(K, I3, np.zeros(3), np.array([0, 0, depth]), I3, np.zeros(3), R_m, 0.1)
    assert view.seen is seen, view
    if depth == 5.0:
        assert view.area_px2 < MIN_AREA_PX2


def test_the_detector_finds_the_drawn_corners() -> None:
    """Exact geometry: 30 renders of a 10 cm marker tilted 0-40 deg at 0.7-1.2 m through the
    simulated camera's lens, blur and noise (calib_arm's camera): the detected corners,
    undistorted, are the true pinhole projections of the corners within 0.35 px RMS per
    axis and 1.0 px at worst (measured 0.17 and 0.48 px; the detector's corner refinement,
    which at 60 deg and more errs by px: docs/camera.md).  Tilted from facing the optical
    axis, off it the line of sight is up to ~56 deg from the normal: none gated."""
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)
    model, D = LENSES["plumb_bob"]
    info = make_camera_info(640, 480, model, K, D)
    renderer, detector = MarkerRenderer(info, spec, ImageNoise()), MarkerDetector(spec)
    rng = np.random.default_rng(5)
    errors = []
    for k in range(30):
        pixel = rng.uniform([120.0, 100.0], [520.0, 380.0])
        p = np.append((pixel - K[:2, 2]) / 500.0, 1.0) * rng.uniform(0.7, 1.2)
        view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), _tilted(rng, 40 * k / 29), 0.1)
        det = detector.detect(renderer.render(view.corners, rng, foreshortened=True))
        assert det.corners is not None, k
        errors.append(undistort(info, det.corners) - view.corners)
    err = np.array(errors)
    rms, worst = float(np.sqrt(np.mean(err**2))), float(np.abs(err).max())
    assert rms < 0.35 and worst < 1.0, (rms, worst)


def test_the_drawn_edges_lie_on_the_projected_ones() -> None:
    """The renderer alone (no detector): 20 markers tilted 60 deg, no blur, no noise, a
    rectified lens: across the middle of each projected edge the image crosses halfway
    between black and the quiet zone's white within 0.3 px of the edge (measured 0.23 px)."""
    spec = MarkerSpec(size=0.1)
    noise = ImageNoise(blur_px=0.0, noise_std=0.0)
    info = make_camera_info(640, 480, "plumb_bob", K, (0.0,) * 5)
    renderer = MarkerRenderer(info, spec, noise)
    rng = np.random.default_rng(8)
    offsets = []
    for _ in range(20):
        pixel = rng.uniform([150.0, 130.0], [490.0, 350.0])
        p = np.append((pixel - K[:2, 2]) / 500.0, 1.0) * 0.7
        view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), _tilted(rng, 60.0), 0.1)
        img = renderer.render(view.corners, rng, foreshortened=True).astype(np.float32)
        for k in range(4):
            a, b = view.corners[k], view.corners[(k + 1) % 4]
            t = (b - a) / np.linalg.norm(b - a)
            s = np.linspace(-3.0, 3.0, 601)
            pts = ((a + b) / 2 + np.outer(s, [t[1], -t[0]])).astype(np.float32)
            val = cv2.remap(img, pts[:, :1], pts[:, 1:], cv2.INTER_LINEAR).ravel()
            half = 0.5 * (noise.black + noise.white)
            j = np.flatnonzero(np.diff(np.sign(val - half)))
            offsets.append(abs(s[j]).min())
    assert max(offsets) < 0.3, max(offsets)


@pytest.fixture(scope="module")
def lib():
    """The paper's 2-link arm (its library: the generated tracked point and camera map)."""
    return library_for(load_scenario("paper-sim"))


def test_the_simulated_camera_draws_the_marker_on_its_link(lib) -> None:
    """SimulatedCamera with the marker fixed to the tip of the paper's arm (its joints turn
    about the optical axis): turned to face the camera at q0 its corners are the facing
    square's there; tilted 50 deg on the tip, at another q, its projected diagonals still meet
    at the generated camera map's pixel (Pinocchio's frame and the generated tracked point
    agree) and the detector finds it there; turned away, the camera sees its back: the image
    has no marker."""
    robot = load_robot(lib.manifest.spec)
    cam = lib.manifest.camera
    R_cw = np.asarray(cam.R_cw, dtype=float)
    theta = lib.theta_true
    q0, q1 = np.array([0.4, -0.9]), np.array([-0.3, 0.6])
    R_f = robot_marker_pose(robot, (0.0, 0.0, 0.0, 1.0)).placement(q0)[1]
    options = ImageOptions(marker=MarkerSpec(size=0.1), model="plumb_bob", D=(0.0,) * 5)

    def camera(turn: np.ndarray | None) -> SimulatedCamera:
        """The simulated camera, the marker turned ``turn`` (marker frame) from facing it
        at q0, or facing it always (None)."""
        pose = None
        if turn is not None:
            R_m = R_f.T @ R_cw.T @ FACING @ turn
            pose = robot_marker_pose(robot, tuple(matrix_to_quaternion(R_m)))
        point = lib.function("tracked_point")
        return SimulatedCamera(cam, point, options, np.random.default_rng(2), pose)

    facing, on_tip = camera(None), camera(np.eye(3))
    c0, f0 = on_tip.corners(q0, theta), facing.corners(q0, theta)
    assert c0 is not None and f0 is not None and np.abs(c0 - f0).max() < 1e-6
    tilted = camera(_turn(np.array([1.0, 0.0, 0.0]), 50.0))
    y1 = np.asarray(lib.function("camera")(q1, theta)[0], dtype=float).ravel()
    c1 = tilted.corners(q1, theta)
    assert c1 is not None and np.abs(diagonals_meet(c1) - y1).max() < 1e-6
    f1 = facing.corners(q1, theta)
    assert f1 is not None and np.abs(c1 - f1).max() > 2.0  # (it is seen obliquely)
    found = tilted.detected(tilted.image(q1, theta))
    assert found is not None and np.abs(found - y1).max() < 0.5
    away = camera(_turn(np.array([0.0, 1.0, 0.0]), 180.0))
    assert away.pose is not None
    assert away.pose.view(cam.K, R_cw, cam.position, q1, 0.1).angle_deg > 150.0
    assert away.corners(q1, theta) is None and away.detected(away.image(q1, theta)) is None


def test_the_orientation_is_read_from_the_spec() -> None:
    """``marker_pose_of``: None without ``[tracked] orientation`` (the facing drawing,
    bit-identical images), the marker's rotation with it (robot-marker.toml)."""
    assert marker_pose_of(DATA / "robot.toml") is None
    assert marker_pose_of(None) is None
    pose = marker_pose_of(DATA / "robot-marker.toml")
    assert pose is not None
    assert np.abs(pose.R_m[:, 2] - [0.6, -0.8, 0.0]).max() < 1e-8
    assert np.abs(pose.R_m[:, 0] - [0.0, 0.0, 1.0]).max() < 1e-8
