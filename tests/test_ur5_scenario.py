"""The shipped UR5 scenario (scenarios/ur5-demo.toml): the estimator on a real 6-DOF arm.

One second of the scenario per estimator: the run stays finite, the payload estimate moves
from its 2.5 kg prior to the true 2 kg, the link angles are estimated to well under a
milliradian, and the filter is consistent (mean NEES near N = 25).  Why the scenario's
choices (rk4 model, payload prior, disturbance level, gains) are what they are:
docs/explanation/ur5-estimation.md.

The scenario's estimator model is the ``ur5_rk4`` library: the first run on a fresh checkout
compiles it (~15 s on 2 cores, hence ``slow``); later runs reuse ``generated/``
(each test below then takes < 1 s).
"""

from __future__ import annotations

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import summarize

ESTIMATORS = ("encoders", "naive", "oosm", "replay", "cloning")


@pytest.fixture(scope="module")
def ur5_demo():
    sc = load_scenario("ur5-demo").with_overrides(duration=1.0)
    return sc, library_for(sc)


def test_scenario_is_the_documented_setup(ur5_demo) -> None:
    sc, lib = ur5_demo
    assert lib.n == 6 and lib.N == 25
    assert sc.integrator == "rk4" and lib.name == "ur5_rk4"
    # the prior is deliberately not the spec's 0 kg (from there the EKF fails, see the docs)
    assert lib.theta_true.tolist() == [2.0]
    assert tuple(sc.estimate0.theta) == (2.5,)


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_ur5_demo_converges_and_is_consistent(ur5_demo, estimator: str) -> None:
    sc, lib = ur5_demo
    res = run(sc.with_overrides(estimator=estimator), lib=lib)
    L = lib.layout
    for name in ("x_true", "x_hat", "P_diag", "nees", "u"):
        assert np.all(np.isfinite(getattr(res, name))), name
    assert np.all(res.P_diag > 0)
    s = summarize(res)
    # theta: starts at 2.5 kg, ends within 1 g of the true 2 kg (measured 0.35 g, sd 0.46 g)
    th = res.x_hat[:, L["theta"]][:, 0]
    assert th[0] == pytest.approx(2.5)
    assert abs(th[-1] - 2.0) < 1e-3, th[-1]
    assert np.sqrt(res.P_diag[-1, L["theta"]][0]) < 1e-3
    # link angles: < 3 mrad RMSE on every joint over the last 80 % (measured 2.32 mrad on
    # wrist 3, 0.03-0.13 on the others; 1.02 before the model took 4 RK4 steps per T, when
    # the filter was inconsistent under the sliding-mode laws: docs/explanation/ur5-estimation.md,
    # 7)
    assert max(s["estimation_rmse"]["q"]) < 3e-3, s["estimation_rmse"]["q"]
    # consistency: mean NEES 31.8 (33.4 with the 4-step model) at seed 0, 1 s (N = 25)
    assert 20.0 < s["nees_mean"] < 45.0, s["nees_mean"]
    # the camera frames are delivered and (for the late-frame estimators) all applied
    assert s["counters"]["frames_delivered"] >= 29
    assert s["counters"]["frames_out_of_image"] == 0
    if estimator in ("oosm", "replay", "cloning"):
        assert s["counters"]["frames_applied"] == s["counters"]["frames_delivered"]
        # the frames are used: the estimate is not the encoders-only one (these bounds alone
        # would pass with the camera unused: encoders-only RMSE 1.02 mrad, 0.35 g)
        enc = run(sc.with_overrides(estimator="encoders"), lib=lib)
        assert np.max(np.abs(res.x_hat[:, L["q"]] - enc.x_hat[:, L["q"]])) > 1e-6
