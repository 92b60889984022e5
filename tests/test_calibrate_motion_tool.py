"""tools/calibrate_motion.py (docs/calibrate.md, "Designing the motion", "With the camera
closer"): its miss shares by quadrature against the chi-square tail and against Gaussian
draws, and the stored prediction of the closer camera (docs/data/calibrate-motion-near.json)
against a fresh run of the tool with ``--robot``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from tests.tool_modules import tool

ROOT = Path(__file__).resolve().parent.parent


cm = tool("calibrate_motion")


@pytest.mark.parametrize(("var", "radius"), [(1.0, 4.0), (0.3, 2.0), (0.1, 2.0), (0.05, 2.0)])
def test_norm_tail_with_equal_axes_is_the_chi_square_tail(var: float, radius: float) -> None:
    """Equal axes: ``|e|^2 / var`` is chi-square with 3 degrees of freedom, down to 1e-17."""
    got = cm.norm_tail(np.eye(3) * var, radius)
    assert got == pytest.approx(chi2.sf(radius**2 / var, 3), rel=1e-4)


def test_norm_tail_with_unequal_axes_matches_gaussian_draws() -> None:
    """Unequal, turned axes: the share of 4e6 draws beyond the radius, within 5 of its
    binomial sigmas, at two radii."""
    rng = np.random.default_rng(7)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    C = R @ np.diag([0.05, 0.1, 0.3]) @ R.T
    norms = np.linalg.norm(rng.multivariate_normal(np.zeros(3), C, 4_000_000), axis=1)
    for radius in (1.2, 1.8):
        p = cm.norm_tail(C, radius)
        drawn = float(np.mean(norms > radius))
        assert abs(drawn - p) < 5 * math.sqrt(p * (1 - p) / norms.size), (radius, p, drawn)


def test_the_stored_closer_camera_prediction_is_the_tool_s() -> None:
    """docs/calibrate.md's prediction for robot-near.toml (its half-widths and miss shares)
    is what the tool computes now, each miss share under the design's 1e-5."""
    stored = json.loads((ROOT / "docs/data/calibrate-motion-near.json").read_text())
    scenario = ROOT / "tests/data/calibrate/calib-sim.toml"
    near = Path("tests/data/calibrate/robot-near.toml")
    got = cm.motion_report(scenario, [], None, near)
    assert got["command"] == stored["command"]
    assert got["frames_in_view"] == stored["frames_in_view"]
    for group in ("half_width_95", "miss_probability"):
        for k, v in stored[group].items():
            assert got[group][k] == pytest.approx(v, rel=1e-6, abs=1e-300), (group, k)
    assert max(got["miss_probability"].values()) < 1e-5  # the design's requirement
