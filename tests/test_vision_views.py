"""The marker's centre over the views a calibration recording holds (docs/camera.md, "The
corners"): small markers (30-45 px) seen up to 75 deg from face-on, rendered through the
simulated camera's lens, blur and noise, detected with the default (``subpix``) corners; the
centre (where the undistorted corners' diagonals meet) against the renderer's exact one.
Beyond ``[marker] max_foreshortening_deg`` a view's centre carries an error of its own (the same on
every frame of that view: it does not average out over a recording), so such frames are
skipped and counted."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.vision.camera_info import make_camera_info, undistort
from amsfe_sym.vision.detections import REASONS
from amsfe_sym.vision.marker import (
    TOO_OBLIQUE,
    MarkerDetector,
    diagonals_meet,
    foreshortening,
)
from amsfe_sym.vision.marker_pose import marker_view
from amsfe_sym.vision.render import ImageNoise, MarkerRenderer
from amsfe_sym.vision.sim_images import LENSES
from amsfe_sym.vision.spec import MAX_FORESHORTENING_DEG, MarkerSpec, parse_marker

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
I3 = np.eye(3)


def _view(rng: np.random.Generator, deg: float):
    """A 10 cm marker 1.1-1.6 m away (30-45 px) at a random pixel, its normal ``deg`` [deg]
    from its line of sight about a random axis, turned in its plane at random; and its
    foreshortening in the image [deg]: arccos of the singular values' ratio of the exact
    pinhole's jacobian at its centre times its x and y axes."""
    pixel = rng.uniform([140.0, 120.0], [500.0, 360.0])
    p = np.append((pixel - K[:2, 2]) / K[0, 0], 1.0) * rng.uniform(1.1, 1.6)
    sight = -p / np.linalg.norm(p)  # marker -> camera
    # a frame whose z is the line of sight (the marker facing the camera), x and y in the plane
    x = np.cross([0.0, 1.0, 0.0], sight)
    x /= np.linalg.norm(x)
    facing = np.column_stack([x, np.cross(sight, x), sight])
    axis = np.append(rng.normal(size=2), 0.0)
    tilt = cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(deg))[0]
    spin = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))[0]
    R = facing @ tilt @ spin
    J = K[0, 0] / p[2] * np.array([[1.0, 0.0, -p[0] / p[2]], [0.0, 1.0, -p[1] / p[2]]])
    s = np.linalg.svd(J @ R[:, :2], compute_uv=False)
    image_deg = math.degrees(math.acos(s[1] / s[0]))
    return marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), R, 0.1), image_deg


def test_the_foreshortening_from_the_corners_is_the_true_one() -> None:
    """``foreshortening`` (the corners' affine part) against the pinhole's jacobian at the
    marker's centre (the foreshortening of an infinitesimal marker), markers 0-80 deg from
    face-on at 15-45 px: within 0.5 deg (measured: 0.1).  Off the optical axis that is not
    the angle from face-on (a marker facing its line of sight there looks stretched along
    the radius): the image's foreshortening is what the detector sees."""
    rng = np.random.default_rng(3)
    for deg in np.linspace(0.0, 80.0, 41):
        view, image_deg = _view(rng, float(deg))
        assert abs(view.angle_deg - deg) < 1e-6
        assert abs(foreshortening(view.corners) - image_deg) < 0.5, (deg, image_deg)


def test_oblique_views_are_skipped_and_the_rest_are_accurate() -> None:
    """Views 0-75 deg from face-on, each rendered 6 times (fresh noise): the centre's error
    averaged over a view's renders is that view's own error, which every frame of the view
    shares (noise averages out over a recording; this does not).  Ungated
    (``max_foreshortening_deg = 90``) the views foreshortened past 55 deg carry such errors
    to 0.3 px and more, and the views' RMS is over 0.15 px; with the default gate the frames
    of views past 55 deg are skipped as too oblique, those under 45 deg are all found, and
    the views' RMS is under 0.15 px (measured 0.12; single views to 0.35 px remain, nearly
    face-on: OpenCV's corners err by the view there too)."""
    model, D = LENSES["plumb_bob"]
    info = make_camera_info(640, 480, model, K, D)
    renderer = MarkerRenderer(info, MarkerSpec(size=0.1), ImageNoise())
    gated = MarkerDetector(MarkerSpec(size=0.1))
    ungated = MarkerDetector(MarkerSpec(size=0.1, max_foreshortening_deg=90.0))
    rng = np.random.default_rng(35)
    kept, every, oblique = [], [], []
    for deg in np.linspace(0.0, 75.0, 31):
        view, image_deg = _view(rng, float(deg))
        truth = diagonals_meet(view.corners)
        err_g, err_u = [], []
        for _ in range(6):
            img = renderer.render(view.corners, rng, foreshortened=True)
            g, u = gated.detect(img), ungated.detect(img)
            if u.corners is not None:
                err_u.append(diagonals_meet(undistort(info, u.corners)) - truth)
            if g.corners is not None:
                assert foreshortening(g.corners) <= MAX_FORESHORTENING_DEG
                err_g.append(diagonals_meet(undistort(info, g.corners)) - truth)
            elif g.skipped == TOO_OBLIQUE:
                assert foreshortening(g.region) > MAX_FORESHORTENING_DEG and g.ids == (0,)
                assert image_deg > 45, image_deg
            else:
                assert image_deg > 45, (image_deg, g.skipped)
        if image_deg > 55:
            assert not err_g, image_deg
            if err_u:
                oblique.append(float(np.linalg.norm(np.mean(err_u, axis=0))))
        if err_u:
            every.append(float(np.linalg.norm(np.mean(err_u, axis=0))))
        if err_g:
            kept.append(float(np.linalg.norm(np.mean(err_g, axis=0))))
    assert len(oblique) >= 6 and max(oblique) > 0.3, oblique  # (what the gate removes)
    assert len(kept) >= 19, kept
    rms = {"gated": float(np.sqrt(np.mean(np.square(kept))))}
    rms["ungated"] = float(np.sqrt(np.mean(np.square(every))))
    assert rms["gated"] < 0.15 < rms["ungated"], rms


@pytest.mark.parametrize(
    ("pixel", "dist", "deg", "axis", "within"),
    [
        ((320, 240), 0.25, 0, (1, 0), 0.07),  # (edges along the rows: one sub-pixel phase)
        ((150, 120), 0.3, 30, (1, 1), 0.03),
        ((470, 360), 0.35, 45, (1, 0), 0.03),
        ((480, 100), 0.35, 60, (1, -1), 0.03),
    ],
)
def test_the_renderer_draws_the_projected_corners(pixel, dist, deg, axis, within) -> None:
    """The renderer against an independent projection: its pinhole corners, distorted, are
    ``cv2.projectPoints`` of the marker's 3D corners through the lens (to 1e-9 px), and on
    a noiseless render (blur 0.8 px) of a 170-200 px marker the edge fit with the
    CameraInfo finds those raw corners to ``within`` px on average (measured 0.058 face-on,
    0.007-0.018 tilted): a pixel-centre convention or a misplaced distortion would be a
    consistent 0.25 px or more."""
    from amsfe_sym.core.camera_frame import MARKER_CORNERS
    from amsfe_sym.vision.camera_info import distort

    model, D = LENSES["plumb_bob"]
    info = make_camera_info(640, 480, model, K, D)
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)
    renderer = MarkerRenderer(info, spec, ImageNoise(noise_std=0.0))
    detector = MarkerDetector(spec, refinement="edges", info=info)
    p = np.append((np.array(pixel, float) - K[:2, 2]) / K[0, 0], 1.0) * dist
    turn = np.array([*axis, 0.0]) / np.linalg.norm(axis) * math.radians(deg)
    R = cv2.Rodrigues(turn)[0] @ np.diag([1.0, -1.0, -1.0])
    view = marker_view(K, I3, np.zeros(3), p, I3, np.zeros(3), R, 0.1)
    world = p + (0.1 * MARKER_CORNERS) @ R.T
    raw = cv2.projectPoints(world, np.zeros(3), np.zeros(3), K, np.array(D))[0].reshape(4, 2)
    assert np.abs(distort(info, view.corners) - raw).max() < 1e-9
    found = detector.detect(renderer.render(view.corners, np.random.default_rng(0))).corners
    assert found is not None
    assert np.abs(found - raw).mean() < within, found - raw


@pytest.mark.parametrize("lens", ["plumb_bob", "plumb_bob_strong"])
def test_the_edge_fit_s_bend_is_taken_off(lens: str) -> None:
    """The edge fit without the CameraInfo (the log reader's) fits a line per short edge in
    the raw image, where the lens bends it: on 40 renders of 30-45 px markers, 0-40 deg from
    face-on, its centre lies 0.015 px (0.037 px through the strong lens) away from the
    image's centre on average, the same way on every frame.  ``unbend`` with the lens takes
    that off: the mean within 0.01 px (measured 0.0002, 0.0033), and each frame's centre
    within 0.01 px of the edge fit given the CameraInfo (a line per undistorted edge)."""
    from amsfe_sym.vision.edges import edge_corners, unbend
    from amsfe_sym.vision.marker import raw_corners_unbent

    model, D = LENSES[lens]
    info = make_camera_info(640, 480, model, K, D)
    spec = MarkerSpec(size=0.1, max_foreshortening_deg=90.0)
    renderer = MarkerRenderer(info, spec, ImageNoise())
    detector = MarkerDetector(spec)
    rng = np.random.default_rng(4)
    radial: dict[str, list[float]] = {"raw": [], "unbent": []}
    for _ in range(40):
        view, _ = _view(rng, float(rng.uniform(0, 40)))
        img = renderer.render(view.corners, rng, foreshortened=True)
        c = detector.detect(img).corners
        assert c is not None
        raw = edge_corners(img, c, detector.modules)
        lines = edge_corners(img, c, detector.modules, info)
        assert raw is not None and lines is not None
        unbent = unbend(info, raw[None], detector.modules)[0]
        edges_spec = MarkerSpec(size=0.1, refinement="edges")
        assert np.array_equal(raw_corners_unbent(info, raw[None], edges_spec)[0], unbent)
        assert np.array_equal(raw_corners_unbent(info, raw[None], spec)[0], raw)  # (subpix)
        truth = diagonals_meet(view.corners)
        out = (truth - K[:2, 2]) / np.linalg.norm(truth - K[:2, 2])
        centre = {k: diagonals_meet(undistort(info, v)) for k, v in (("raw", raw),
                  ("unbent", unbent), ("lines", lines))}  # fmt: skip
        assert np.linalg.norm(centre["unbent"] - centre["lines"]) < 0.01
        for k in radial:
            radial[k].append(float((centre[k] - truth) @ out))
    assert np.mean(radial["raw"]) > 0.01, np.mean(radial["raw"])  # (the bend: the premise)
    assert abs(np.mean(radial["unbent"])) < 0.01, np.mean(radial["unbent"])


def test_max_foreshortening_deg_is_parsed_and_checked() -> None:
    """``[marker] max_foreshortening_deg``: parsed; above 90 or not positive: one line; the
    reason is one the log reader counts."""
    assert parse_marker({}).max_foreshortening_deg == MAX_FORESHORTENING_DEG
    assert parse_marker({"max_foreshortening_deg": 90}).max_foreshortening_deg == 90.0
    for bad in (0, 91.0, "x"):
        with pytest.raises(ConfigError, match="max_foreshortening_deg"):
            parse_marker({"max_foreshortening_deg": bad})
    assert TOO_OBLIQUE in REASONS
