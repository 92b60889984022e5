"""The saturation-aware hand-over of the cascades (``headroom_tau``, docs/explanation/control.md
"Start-up"; issue 28): while the blend runs, the share of the last demand the actuators could
apply scales h, eps, wm and wf, drops at once and recovers with its time constant; the C
controller does the same tick by tick, and the whole loop equals the Python one.

The studies that chose it (moving starts, fresh seeds) live in tools/startup_moving.py.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, apply_sets
from amsfe_sym.sim.builders import build_controller
from amsfe_sym.sim.loop import run
from tests.test_compiled_loop import assert_same_run
from tests.test_startup import assert_same_tick, controller_pair

TAU = 0.05


def _with(sc: Scenario, controller: str, *sets: str) -> Scenario:
    sc = sc.with_overrides(controller=controller)
    return apply_sets(sc, [f"controller_gains.{controller}.{s}" for s in sets])


def test_headroom_scales_the_loop_gains(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """A demand of twice the limit on one joint halves h, eps, wm and wf on every joint at
    once; lam, Lt, phi, tau_max and vmax stay; rho then returns as rho += T / tau (r - rho)."""
    sc, lib = paper_sim
    ctrl, _ = build_controller(_with(sc, "amsfe", f"headroom_tau={TAU}"), lib)
    names = ["h", "lam", "Lt", "eps", "p", "phi", "wm", "tau_max", "wf", "vmax"]
    base = ctrl._gain_args()
    assert ctrl._headroom(base) is base  # no demand yet: unscaled
    u_max = ctrl.u_max
    ctrl._u_demand = np.array([2.0 * u_max[0], -0.5 * u_max[1]])
    scaled = dict(zip(names, ctrl._headroom(base), strict=True))
    for k, g in zip(names, base, strict=True):
        factor = 0.5 if k in ("h", "eps", "wm", "wf") else 1.0
        np.testing.assert_array_equal(scaled[k], g * factor, err_msg=k)
    assert ctrl._rho == 0.5
    ctrl._u_demand = np.array([0.1, 0.1])  # within the limits: r = 1, rho recovers
    ctrl._headroom(base)
    assert ctrl._rho == pytest.approx(0.5 + lib.T / TAU * 0.5, rel=1e-15)
    ctrl._u_demand = np.array([0.1, -4.0 * u_max[1]])  # a deeper cut is taken at once
    ctrl._headroom(base)
    assert ctrl._rho == 0.25
    ctrl._headroom(base, cut=False)  # the blend is over: no cut, whatever the demand
    assert ctrl._rho == pytest.approx(0.25 + lib.T / TAU * 0.75, rel=1e-15)
    off, _ = build_controller(_with(sc, "dtsmc-ekf", "headroom_tau=inf"), lib)
    off._u_demand = np.array([1e6, 1e6])
    assert off._headroom(base) is base  # headroom_tau = inf: off


def test_bad_headroom_is_refused(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    sc, lib = paper_sim
    for bad in ("0", "-1", "nan"):
        with pytest.raises(ConfigError, match="headroom_tau"):
            build_controller(_with(sc, "amsfe", f"headroom_tau={bad}"), lib)


def test_compiled_headroom_tick_by_tick(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """amsfe_ctrl against the Python controller, fed the same inputs, on a state that asks
    for more than the actuators have, then less: torques equal to 1e-12, and the gains were
    scaled (rho below 1) and recovered."""
    sc, lib = paper_sim
    K, n = 80, lib.n
    ctrl, cc, refs = controller_pair(
        _with(sc, "amsfe", f"headroom_tau={TAU}", "blend_wf=20"), lib, K
    )
    rng = np.random.default_rng(3)
    q0, qd0 = refs[0, :n], refs[0, n : 2 * n]
    x = np.concatenate([q0 + 0.4, qd0 - 3.0, q0 - 1.0, qd0 + 5.0, lib.theta_true])
    rhos = []
    for k in range(K):
        x_hat = x + 1e-3 * rng.standard_normal(lib.N)
        z = x[2 * lib.n : 4 * lib.n] + 1e-4 * rng.standard_normal(2 * lib.n)
        P = np.diag(np.full(lib.N, 1e-6))
        assert_same_tick(ctrl, cc, k, refs[k], x, x_hat, z, P)
        rhos.append(ctrl._rho)
        if k == 20:  # the arm joins the path: the demand falls within the limits
            qk, qdk = refs[k, :n], refs[k, n : 2 * n]
            x = np.concatenate([qk, qdk, qk + 0.2, qdk, lib.theta_true])
        x[: lib.n] += 1e-3 * np.sin(k)
    assert rhos[0] == 1.0 and min(rhos[:20]) < 0.5  # cut at once on the first demand
    low = int(np.argmin(rhos))
    assert low > 20 and np.all(np.diff(rhos[low:]) > 0)  # the jump at k = 20 cuts deeper,
    assert rhos[-1] > rhos[low] + 0.15  # then it recovers with its time constant


def test_headroom_c_loop_equals_python_loop(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """The whole loop with the headroom on a start that saturates: C against Python (C
    estimator), every signal; and another run than without it."""
    sc, lib = paper_sim
    sc = replace(
        _with(sc.with_overrides(duration=0.8, seed=5), "amsfe", f"headroom_tau={TAU}"),
    )
    sc = replace(sc, plant=replace(sc.plant, q0=(0.3, 0.8), qd0=(-2.0, 1.0)))
    c = run(sc, lib, runtime="compiled")
    assert_same_run(run(sc, lib, runtime="python", compiled_estimator=True), c)
    assert c.saturated.any()
    off = run(_with(sc, "amsfe", "headroom_tau=inf"), lib, runtime="compiled")
    assert not np.allclose(off.u, c.u)


def test_the_c_api_refuses_a_bad_headroom(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    from amsfe_sym.runtime.compiled_loop import CompiledController
    from amsfe_sym.sim.compiled import controller_params

    sc, lib = paper_sim
    ctrl, _ = build_controller(sc.with_overrides(controller="amsfe"), lib)
    good = controller_params(ctrl, lib)
    for bad in (float("nan"), -1.0):
        with pytest.raises(ConfigError):
            CompiledController(str(lib.library_path), replace(good, headroom_tau=bad), lib.n)
    # a block zeroed by a C caller that predates the field: off
    CompiledController(str(lib.library_path), replace(good, headroom_tau=0.0), lib.n)
