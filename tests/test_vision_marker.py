"""The marker and the undistortion (docs/camera.md, "Accuracy"): detections on rendered
images against the generated pinhole map, for each distortion model; the pixel std the
marker spec reports against the spread measured; undistortion as the inverse of OpenCV's
projection."""

from __future__ import annotations

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from amsfe_sym.vision.camera_info import distort, make_camera_info, undistort
from amsfe_sym.vision.marker import MarkerDetector, diagonals_meet, tracked_point
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer, marker_corners
from amsfe_sym.vision.sim_images import LENSES
from amsfe_sym.vision.spec import CORNERS, MarkerSpec


@pytest.fixture(scope="module")
def lib():
    """The paper's 2-link arm: its generated camera map is the truth the chain must meet."""
    return library_for(load_scenario("paper-sim"))


def _K(lib) -> np.ndarray:
    return np.asarray(lib.manifest.camera.K, dtype=np.float64)


@pytest.mark.parametrize("lens", list(LENSES))
def test_undistortion_inverts_the_lens(lib, lens: str) -> None:
    """``undistort(distort(y)) == y`` over the whole image, for every model (OpenCV's
    default 5 iterations left 0.8 px at the corners of the strong lens)."""
    model, D = LENSES[lens]
    cam = lib.manifest.camera
    info = make_camera_info(cam.width, cam.height, model, _K(lib), D)
    y = np.random.default_rng(1).uniform([0, 0], [cam.width, cam.height], (400, 2))
    assert np.abs(undistort(info, distort(info, y)) - y).max() < 1e-9
    if lens != "rectified":  # and the lens does move points (the test can fail)
        assert np.abs(distort(info, y) - y).max() > 1.0


def test_the_centre_is_the_projection_of_the_square_centre() -> None:
    """The diagonals of a projected square meet at its centre's projection (not at the
    mean of the corners)."""
    K = np.array([[400.0, 0, 320], [0, 400.0, 256], [0, 0, 1]])
    R = np.array([[1.0, 0, 0], [0, np.cos(1.0), -np.sin(1.0)], [0, np.sin(1.0), np.cos(1.0)]])
    P = np.array([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]]) @ R.T
    P += [0.05, -0.02, 0.6]
    uv = (P @ K.T)[:, :2] / (P @ K.T)[:, 2:]
    c = P.mean(axis=0)
    centre = (K @ c)[:2] / (K @ c)[2]
    assert np.abs(diagonals_meet(uv) - centre).max() < 1e-9
    assert np.abs(uv.mean(axis=0) - centre).max() > 1.0
    assert tracked_point(uv, "bottom_right").tolist() == uv[2].tolist()


def _renders(lib, lens: str, count: int, seed: int, spec: MarkerSpec, noise=None):
    """(detected, true) points of ``count`` renders of the arm at random q: true = the
    generated ``camera`` map at q, detected = the chain (render -> detect -> undistort ->
    the tracked point)."""
    model, D = LENSES[lens]
    cam = lib.manifest.camera
    info = make_camera_info(cam.width, cam.height, model, _K(lib), D)
    renderer = MarkerRenderer(info, spec, noise or ImageNoise())
    detector = MarkerDetector(spec)
    camera, point = lib.function("camera"), lib.function("tracked_point")
    theta = lib.theta_true
    rng = np.random.default_rng(seed)
    got, true = [], []
    while len(true) < count:
        q = rng.uniform(-np.pi, np.pi, lib.n)
        y = np.asarray(camera(q, theta)[0], dtype=np.float64).ravel()
        if not (60 < y[0] < cam.width - 60 and 60 < y[1] < cam.height - 60):
            continue  # (the marker must be inside the image)
        r = np.asarray(point(q, theta)[0], dtype=np.float64).ravel()
        corners = marker_corners(cam.K, cam.R_cw, cam.position, r, spec.size)
        det = detector.detect(renderer.render(corners, rng))
        und = undistort(info, det.corners) if det.corners is not None else None
        got.append(tracked_point(und, spec.point) if und is not None else [np.nan, np.nan])
        if spec.point == "centre":
            true.append(y)
        else:
            true.append(corners[CORNERS.index(spec.point)])
    return np.array(got), np.array(true)


@pytest.mark.slow
@pytest.mark.parametrize("lens", list(LENSES))
def test_detections_meet_the_generated_pinhole_map(lib, lens: str) -> None:
    """On distorted renders of the arm, the undistorted detected centre matches the
    generated camera map at sub-pixel level: every frame found, RMS < 0.25 px, worst < 1 px
    (measured 0.08-0.15 px RMS)."""
    got, true = _renders(lib, lens, 30, seed=11, spec=MarkerSpec(size=0.1))
    assert np.isfinite(got).all()
    err = got - true
    assert np.sqrt(np.mean(err**2)) < 0.25 and np.abs(err).max() < 1.0


@pytest.mark.slow
def test_a_named_corner_is_tracked_too(lib) -> None:
    """``point = "top_right"``: that corner, sub-pixel (the corner refinement pulls corners
    ~0.3 px inwards, which the centre does not see: a looser bound)."""
    got, true = _renders(
        lib, "plumb_bob", 20, seed=12, spec=MarkerSpec(size=0.1, point="top_right")
    )
    err = got - true
    assert np.isfinite(got).all() and np.sqrt(np.mean(err**2)) < 0.6


@pytest.mark.slow
def test_the_reported_pixel_std_bounds_the_measured_spread(lib) -> None:
    """The marker spec's default ``pixel_std`` against the spread of 80 detections on renders
    with the simulated camera's noise (blur 0.8 px, noise 4 grey levels) at two marker sizes
    (~27 px and ~45 px across): the measured per-axis RMS error is between 40 % and 100 % of
    the std reported (a covariance that is conservative, but not by more than 2.5x); a
    noisier image (noise 12 grey levels, blur 1.2 px) exceeds it: the std holds for images
    this clean, and the test can fail."""
    reported = MarkerSpec().pixel_std
    for size, seed in ((0.1, 21), (0.17, 22)):
        got, true = _renders(lib, "plumb_bob", 40, seed=seed, spec=MarkerSpec(size=size))
        rms = np.sqrt(np.mean((got - true) ** 2, axis=0))
        assert np.all(rms <= reported) and np.all(rms >= 0.4 * reported), (size, rms)
    noisy = ImageNoise(blur_px=1.2, noise_std=12.0)
    got, true = _renders(lib, "plumb_bob", 40, seed=23, spec=MarkerSpec(size=0.1), noise=noisy)
    ok = np.isfinite(got).all(axis=1)
    assert np.sqrt(np.mean((got[ok] - true[ok]) ** 2)) > reported


def test_a_region_of_interest_finds_the_same_corners(lib) -> None:
    """Detection in a region around the last corners gives the whole image's corners (to
    1e-4 px: the region's corners are float32 before its offset is added) on 24 frames of a
    moving arm, each region placed from the previous frame's corners as the log reader
    does; and a marker that left the region is found in the whole image."""
    spec = MarkerSpec(size=0.1)
    cam = lib.manifest.camera
    info = make_camera_info(
        cam.width, cam.height, *LENSES["plumb_bob"][:1], _K(lib), LENSES["plumb_bob"][1]
    )
    renderer, detector = MarkerRenderer(info, spec), MarkerDetector(spec)
    rng = np.random.default_rng(31)
    point = lib.function("tracked_point")
    qs = [[0.3 + 0.02 * k, -0.8 + 0.03 * k] for k in range(24)] + [[-1.2, 0.9]]
    images = []
    for q in qs:  # the last: far from the one before
        r = np.asarray(point(np.array(q), lib.theta_true)[0]).ravel()
        images.append(renderer.render(marker_corners(cam.K, cam.R_cw, cam.position, r, 0.1), rng))
    full = [detector.whole(img).corners for img in images]
    assert all(c is not None for c in full)
    for k in range(1, len(images)):
        near = detector._near(images[k], full[k - 1])  # (the region alone, no fall-back)
        if k < len(images) - 1:
            assert near is not None and near.corners is not None
            assert np.abs(near.corners - full[k]).max() < 1e-4, k
        else:
            assert near is None  # (it did leave the region) ...
    moved = detector.detect(images[-1], full[-2]).corners  # ... and the whole image has it
    assert moved is not None and np.abs(moved - full[-1]).max() < 1e-4
    assert np.abs(full[-1] - full[-2]).max() > 50


@pytest.mark.slow
def test_the_default_windows_catch_what_the_one_window_misses(lib) -> None:
    """On noisy renders (12 grey levels, blur 1.2 px) the one threshold window of the
    first search misses some markers; the detector then searches OpenCV's default windows
    and finds every marker those find (and the one window alone does miss: the fall-back
    is exercised)."""
    spec = MarkerSpec(size=0.1)
    cam = lib.manifest.camera
    info = make_camera_info(
        cam.width, cam.height, *LENSES["plumb_bob"][:1], _K(lib), LENSES["plumb_bob"][1]
    )
    renderer = MarkerRenderer(info, spec, ImageNoise(blur_px=1.2, noise_std=12.0))
    camera, point = lib.function("camera"), lib.function("tracked_point")
    rng = np.random.default_rng(41)
    images = []
    while len(images) < 20:
        q = rng.uniform(-np.pi, np.pi, lib.n)
        y = np.asarray(camera(q, lib.theta_true)[0]).ravel()
        if 60 < y[0] < cam.width - 60 and 60 < y[1] < cam.height - 60:
            r = np.asarray(point(q, lib.theta_true)[0]).ravel()
            c = marker_corners(cam.K, cam.R_cw, cam.position, r, 0.1)
            images.append(renderer.render(c, rng))
    both, default = MarkerDetector(spec), MarkerDetector(spec, threshold_window=None)
    one = [both._found(both._detector, g, 0, 0).corners is not None for g in images]
    found = [both.whole(g).corners is not None for g in images]
    found_default = [default.whole(g).corners is not None for g in images]
    assert not all(one)
    assert all(f or not d for f, d in zip(found, found_default, strict=True))
    assert sum(found) >= sum(found_default) >= 15


def _blurred_square(corners: np.ndarray, sigma: float, shape=(240, 320)) -> np.ndarray:
    """A dark convex quadrilateral (30 grey levels on 220) blurred by a Gaussian of
    ``sigma`` px, exact along its edges away from the corners: each pixel centre's value
    from its signed distance to the nearest edge line (the blur of a half-plane)."""
    from scipy.special import ndtr

    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    pts = np.stack([xs, ys], axis=-1)
    centre = corners.mean(axis=0)
    dist = np.full(shape, -np.inf)
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        n = np.array([-d[1], d[0]])
        n *= np.sign((0.5 * (a + b) - centre) @ n)
        dist = np.maximum(dist, (pts - a) @ n)  # > 0 outside this edge
    img = 30.0 + 190.0 * ndtr(dist / sigma)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("sigma", [0.5, 0.8, 1.5])
def test_the_edge_fit_finds_the_corners_of_a_blurred_square(sigma: float) -> None:
    """On an exactly blurred dark square (no lens, no noise; 8-bit rounding only), turned
    0.3 rad, 60 px a side, the edge fit started 0.4 px inside each corner returns the true
    corners to 0.015 px with a line per edge, 0.03 px with a parabola (measured 0.003-0.006
    and 0.013-0.021 px: the 8-bit rounding)."""
    from amsfe_sym.vision.edges import edge_corners

    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    square = np.array([[-30.0, -30.0], [30.0, -30.0], [30.0, 30.0], [-30.0, 30.0]])
    truth = square @ rot.T + [160.3, 120.7]
    img = _blurred_square(truth, sigma)
    start = truth - 0.4 * (truth - truth.mean(axis=0)) / np.linalg.norm(square[0])
    for curve_from, bound in ((1e9, 0.015), (0.0, 0.03)):  # a line per edge, a parabola
        got = edge_corners(img, start, 8, None, curve_from=curve_from)
        assert got is not None and np.abs(got - truth).max() < bound, (curve_from, got - truth)


def test_the_edge_fit_undistorts_the_edges() -> None:
    """A square whose edges are straight in the pinhole image, drawn through the strong
    lens (exactly blurred in the raw image, its edges bent by up to ~0.7 px): with the
    CameraInfo the edge fit's corners are the true raw corners to 0.03 px (measured 0.005);
    a line per edge in the raw image misses them by more than 0.1 px (0.58: the bend is
    real), a parabola per edge lands within 0.06 px (0.027)."""
    from scipy.special import ndtr

    from amsfe_sym.vision.edges import edge_corners

    model, D = LENSES["plumb_bob_strong"]
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    info = make_camera_info(640, 480, model, K, D)
    pin = np.array([[450.0, 300.0], [560.0, 310.0], [550.0, 420.0], [440.0, 410.0]])
    ys, xs = np.mgrid[0:480, 0:640].astype(np.float64)
    und = undistort(info, np.column_stack([xs.ravel(), ys.ravel()])).reshape(480, 640, 2)
    # the signed distance in the pinhole image, scaled to raw pixels by the local stretch
    centre = pin.mean(axis=0)
    dist = np.full((480, 640), -np.inf)
    for k in range(4):
        a, b = pin[k], pin[(k + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        n = np.array([-d[1], d[0]])
        n *= np.sign((0.5 * (a + b) - centre) @ n)
        dist = np.maximum(dist, (und - a) @ n)
    # raw pixels per pinhole pixel across the edges, near the marker (numerically)
    probe = distort(info, np.array([centre, centre + np.array([1.0, 0.0])]))
    scale = float(np.linalg.norm(probe[1] - probe[0]))
    img = np.clip(np.rint(30.0 + 190.0 * ndtr(dist * scale / 0.8)), 0, 255).astype(np.uint8)
    truth = distort(info, pin)
    start = truth - 0.3 * (truth - truth.mean(axis=0)) / 80.0
    with_info = edge_corners(img, start, 8, info)
    assert with_info is not None and np.abs(with_info - truth).max() < 0.03
    line = edge_corners(img, start, 8, None, curve_from=1e9)
    parabola = edge_corners(img, start, 8, None, curve_from=0.0)
    assert line is not None and np.abs(line - truth).max() > 0.1
    assert parabola is not None and np.abs(parabola - truth).max() < 0.06


@pytest.mark.slow
def test_the_detected_corners_are_unbiased_on_renders() -> None:
    """The detector's corners on 96 renders of the simulated camera (plumb_bob lens, noise 4
    grey levels, blur 0.8 and 1.2 px, 10 cm marker at 0.35-1.5 m: 33-140 px, tilted 0-50 deg)
    against the renderer's exact corners: their mean signed error along the marker's
    outward diagonal (the bias) is within 0.04 px of 0, the line (with the CameraInfo) and
    the parabola (without) alike, where ``cornerSubPix`` alone is < -0.15 px on the same
    images; their RMS error < 0.12 px, cornerSubPix's > 0.2 px.  Measured: bias +0.005
    (line), +0.009 (parabola), -0.240 px (cornerSubPix), each +-0.004 px (standard error of
    384 corners); RMS 0.061, 0.087, 0.285 px.  The bound is 10 standard errors and holds
    every blur and size of tools/marker_view_accuracy.py --bias except its 25 px markers at
    1.2-1.5 px of blur (+0.06 to +0.1 px outward: the marker's inner bits reach the dark
    level), which this test does not draw."""
    import math

    import cv2

    from amsfe_sym.vision.marker_pose import marker_view

    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    model, D = LENSES["plumb_bob"]
    info = make_camera_info(640, 480, model, K, D)
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)  # (views to 50 deg: none gated)
    methods = {
        "line": MarkerDetector(spec, info=info, refinement="edges"),
        "parabola": MarkerDetector(spec, refinement="edges"),
        "subpix": MarkerDetector(spec, refinement="subpix"),
    }
    signed: dict[str, list[float]] = {m: [] for m in methods}
    norm: dict[str, list[float]] = {m: [] for m in methods}
    rng = np.random.default_rng(51)
    I3, facing = np.eye(3), np.diag([1.0, -1.0, -1.0])
    for blur in (0.8, 1.2):
        renderer = MarkerRenderer(info, spec, ImageNoise(blur_px=blur))
        for _ in range(48):
            while True:
                dist = rng.uniform(0.35, 1.5)
                pixel = rng.uniform([100.0, 100.0], [540.0, 380.0])
                p = np.append((pixel - K[:2, 2]) / K[0, 0], 1.0) * dist
                axis = np.append(rng.normal(size=2), 0.0)
                angle = math.radians(rng.uniform(0.0, 50.0))
                tilt = cv2.Rodrigues(axis / np.linalg.norm(axis) * angle)[0]
                spin = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))[0]
                view = marker_view(
                    K, I3, np.zeros(3), p, I3, np.zeros(3), tilt @ facing @ spin, 0.1
                )
                c = view.corners
                wide = c.mean(axis=0) + 1.4 * (c - c.mean(axis=0))
                if (wide.min(axis=0) > 5).all() and (wide.max(axis=0) < [635, 475]).all():
                    break
            img = renderer.render(view.corners, rng, foreshortened=True)
            out = c - c.mean(axis=0)
            out /= np.linalg.norm(out, axis=1)[:, None]
            for m, det in methods.items():
                got = det.detect(img).corners
                assert got is not None
                e = undistort(info, got) - c
                signed[m].extend(np.einsum("ij,ij->i", e, out))
                norm[m].extend(np.linalg.norm(e, axis=1))
    bias = {m: float(np.mean(v)) for m, v in signed.items()}
    rms = {m: float(np.sqrt(np.mean(np.square(v)))) for m, v in norm.items()}
    assert abs(bias["line"]) < 0.04 and abs(bias["parabola"]) < 0.04, bias
    assert bias["subpix"] < -0.15, bias
    assert rms["line"] < 0.12 and rms["parabola"] < 0.12 and rms["subpix"] > 0.2, rms


def test_the_refinement_is_the_specs_or_subpix() -> None:
    """``[marker] refinement``: parsed and checked; the detector takes the spec's, else
    ``subpix`` (the tracked point), and the log reader's decoder the spec's; an unknown one is
    one line naming the choices."""
    from amsfe_sym.errors import ConfigError
    from amsfe_sym.vision.detections import ImageDecoder
    from amsfe_sym.vision.spec import parse_marker

    assert parse_marker({}).refinement is None
    assert MarkerDetector(parse_marker({})).refinement == "subpix"
    edges = parse_marker({"refinement": "edges"})
    assert MarkerDetector(edges).refinement == "edges"
    assert MarkerDetector(edges, refinement="apriltag").refinement == "apriltag"
    decoder = ImageDecoder("sensor_msgs/msg/Image", edges, lambda *a: None)
    assert decoder.detector.refinement == "edges"
    with pytest.raises(ConfigError, match=r"refinement.*'subpix'.*'edges'.*found 'bilinear'"):
        parse_marker({"refinement": "bilinear"})
