"""The blend planned before the trusted tick (``blend_lead``, docs/explanation/control.md
"Start-up: the blend planned before the trusted tick"): the Python controller and amsfe_ctrl
(runtime/c/amsfe_blend.c, amsfe_ctrl.c) equal tick by tick and in the loop, the gain's checks,
and the moving start that motivated it.

The studies on 1000-seed blocks live in tools/startup_moving.py (``--set
GAINS.blend_lead=...``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from amsfe_sym.errors import ConfigError
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.sim.builders import build_controller
from amsfe_sym.sim.loop import run
from tests.test_compiled_loop import assert_same_run
from tests.test_headroom import _with
from tests.test_startup import assert_same_tick, controller_pair


def _grid_start_19765(sc: Scenario) -> Scenario:
    """tools/startup_moving.py's grid start of seed 19765 (rounded to 1 mrad): joint 1 moving
    at -3 rad/s while the path moves at +pi rad/s; the estimate 0.4 rad and 0.65 rad/s off.
    With the blend planned at the trusted tick (~86 ms) amsfe was thrown past pi at 0.57 s;
    the oracle, the same law on the true state from the first tick, peaked 2.76 rad off."""
    return replace(
        sc,
        plant=replace(sc.plant, q0=(-0.366, 1.278), qd0=(-3.027, 0.406)),
        estimate0=replace(sc.estimate0, q=(0.034, 1.253), qd=(-3.676, 0.427)),
    )


@pytest.mark.parametrize("hold", ["reference", "motor"])
@pytest.mark.parametrize("lead", ["0.75", "1.0"])
def test_compiled_lead_tick_by_tick(
    paper_sim: tuple[Scenario, ModelLibrary], hold: str, lead: str
) -> None:
    """amsfe_ctrl fed the Python controller's inputs gives its torques to 1e-12 N m through
    the wait, the start of a blend planned before it, the blend and the headroom."""
    sc, lib = paper_sim
    sets = ("ready_qd_std=0.05", "ready_nis=inf", f"hold={hold}", f"blend_lead={lead}")
    K, n = 80, lib.n
    ctrl, cc, refs = controller_pair(_with(sc, "amsfe", *sets), lib, K)
    rng = np.random.default_rng(2)
    q0, qd0 = refs[0, :n], refs[0, n : 2 * n]
    x = np.concatenate([q0 + 0.3, qd0 - 3.0, q0, qd0 + 0.5, lib.theta_true])
    for k in range(K):
        x_hat = x + 1e-3 * rng.standard_normal(lib.N)
        z = x[2 * n : 4 * n] + 1e-4 * rng.standard_normal(2 * n)
        P = np.diag(np.full(lib.N, (0.3 * np.exp(-k / 4.0)) ** 2))
        assert_same_tick(ctrl, cc, k, refs[k], x, x_hat, z, P)
        x[:n] += 1e-3 * np.sin(k)
    k0, s0, tb, _, _ = ctrl._blend
    assert 0 < k0 < K - 20  # it waited, then started
    assert s0 == pytest.approx(float(lead) * k0 * lib.T)  # planned lead x wait before
    assert tb > s0


def test_the_moving_start_that_crossed_pi(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """Seed 19765's grid start: planned at the trusted tick the blend itself leaves the path
    by more than pi and the run diverges; planned 3/4 of the wait before it, it does not. C
    and Python equal on the run that holds (C estimator, every signal)."""
    sc, lib = paper_sim
    sc = _grid_start_19765(sc.with_overrides(duration=0.8, seed=19765))
    before = run(_with(sc, "amsfe", "blend_lead=0"), lib, runtime="compiled")
    assert before.diverged_at is not None and 0.5 < before.diverged_at < 0.65
    led = _with(sc, "amsfe", "blend_lead=0.75")
    c = run(led, lib, runtime="compiled")
    assert c.diverged_at is None
    assert np.abs(c.x_true[:, : lib.n] - c.q_des).max() < np.pi - 0.3
    assert_same_run(run(led, lib, runtime="python", compiled_estimator=True), c)


def test_the_oracle_has_no_wait_to_lead(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    """``truth`` trusts at the first tick: blend_lead changes nothing, to the bit."""
    sc, lib = paper_sim
    sc = _grid_start_19765(sc.with_overrides(duration=0.3, seed=3))
    a = run(_with(sc, "truth", "blend_lead=0"), lib, runtime="compiled")
    b = run(_with(sc, "truth", "blend_lead=1"), lib, runtime="compiled")
    np.testing.assert_array_equal(a.u, b.u)


@pytest.mark.parametrize("bad", ["-0.1", "1.5", "nan", "true", '"start"'])
def test_a_bad_lead_is_refused(paper_sim: tuple[Scenario, ModelLibrary], bad: str) -> None:
    sc, lib = paper_sim
    with pytest.raises(ConfigError, match="blend_lead"):
        build_controller(_with(sc, "amsfe", f"blend_lead={bad}"), lib)


def test_the_c_api_refuses_a_bad_lead(paper_sim: tuple[Scenario, ModelLibrary]) -> None:
    from amsfe_sym.runtime.compiled_loop import CompiledController
    from amsfe_sym.sim.compiled import controller_params

    sc, lib = paper_sim
    ctrl, _ = build_controller(sc.with_overrides(controller="amsfe"), lib)
    good = controller_params(ctrl, lib)
    assert good.blend_lead == 0.75  # paper-sim ships it
    for bad in (-0.5, 2.0, float("nan")):
        with pytest.raises(ConfigError):
            CompiledController(str(lib.library_path), replace(good, blend_lead=bad), lib.n)
    CompiledController(str(lib.library_path), replace(good, blend_lead=0.0), lib.n)
