"""The start-up's settings on the tuning seeds (docs/explanation/control.md, "Start-up"):
paper-sim, 3 s
runs, ``amsfe``.  Group ``threshold`` (Python loop): the paper's start against waiting until
the link angles' posterior std is below 0.10 / 0.05 / 0.03 / 0.02 rad (rates not waited for);
group ``blend`` (compiled loop): the wait with the blended reference at offset accelerations
``blend_accel`` [rad/s^2] and jerk/snap bandwidths ``blend_rate`` [rad/s], and without it::

    .venv/bin/python tools/startup_variants.py 700 740            # threshold
    .venv/bin/python tools/startup_variants.py 700 740 oosm blend

Prints per variant: divergences, the peak tracking error past the initial one (max, median,
seeds above 0.1 rad), the largest error after 1.5 s and the joint-2 RMSE over the last 80 %.
"""

import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import apply_sets, load_scenario
from amsfe_sym.sim.loop import run

VARIANTS = {
    "old": ["controller_gains.amsfe.startup=first"],
    "q10": [
        "controller_gains.amsfe.ready_q_std=0.10",
        "controller_gains.amsfe.ready_qd_std=1e9",
        "controller_gains.amsfe.blend_accel=inf",
    ],
    "q05": [
        "controller_gains.amsfe.ready_q_std=0.05",
        "controller_gains.amsfe.ready_qd_std=1e9",
        "controller_gains.amsfe.blend_accel=inf",
    ],
    "q03": [
        "controller_gains.amsfe.ready_q_std=0.03",
        "controller_gains.amsfe.ready_qd_std=1e9",
        "controller_gains.amsfe.blend_accel=inf",
    ],
    "q02": [
        "controller_gains.amsfe.ready_q_std=0.02",
        "controller_gains.amsfe.ready_qd_std=1e9",
        "controller_gains.amsfe.blend_accel=inf",
    ],
}
BLEND = {
    f"blend{a}-rate{r}": [
        f"controller_gains.amsfe.blend_accel={a}",
        f"controller_gains.amsfe.blend_rate={r}",
    ]
    for a, r in [
        ("inf", "inf"),
        ("20.0", "inf"),
        ("20.0", "20.0"),
        ("20.0", "10.0"),
        ("20.0", "5.0"),
        ("40.0", "10.0"),
        ("40.0", "5.0"),
        ("10.0", "10.0"),
    ]
}


def one(args):
    seed, startup, est = args
    blend = startup in BLEND
    sc = load_scenario("paper-sim").with_overrides(
        controller="amsfe", estimator=est, duration=3.0, seed=seed
    )
    sc = apply_sets(sc, BLEND[startup] if blend else VARIANTS[startup])
    res = run(sc, library_for(sc), runtime="compiled" if blend else "python")
    n = res.lib.n
    e = res.x_true[:, :n] - res.q_des
    peak = np.abs(e).max()
    e0 = np.abs(e[0]).max()
    late = np.abs(e[int(1.5 / res.lib.T) :]).max() if len(e) > int(1.5 / res.lib.T) else np.inf
    rmse = np.sqrt(np.mean(e[int(0.2 * len(e)) :] ** 2, axis=0))
    return seed, startup, res.diverged_at, e0, peak, late, rmse.tolist()


if __name__ == "__main__":
    seeds = range(int(sys.argv[1]), int(sys.argv[2]))
    est = sys.argv[3] if len(sys.argv) > 3 else "oosm"
    group = BLEND if len(sys.argv) > 4 and sys.argv[4] == "blend" else VARIANTS
    jobs = [(s, st, est) for s in seeds for st in group]
    with ProcessPoolExecutor(2) as ex:
        rows = list(ex.map(one, jobs))
    for st in group:
        r = [x for x in rows if x[1] == st]
        peak_over = np.array([x[4] - x[3] for x in r])
        late = np.array([x[5] for x in r])
        j2 = np.array([x[6][1] for x in r])
        print(
            st,
            "diverged",
            sum(x[2] is not None for x in r),
            f"peak-over-initial max {peak_over.max():.3f} med {np.median(peak_over):.3f}",
            f"err after 1.5s max {late.max():.4f}",
            f"j2 rmse med {np.median(j2):.4f} max {j2.max():.4f}",
            "n(peak>0.1)",
            int((peak_over > 0.1).sum()),
        )
