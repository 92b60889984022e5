"""Is the estimator consistent on a model generated at a log's period, and how many rk4
substeps does that take? (issue 26, item 5: the margin of ``substeps_for``.)

    .venv/bin/python tools/period_consistency.py                     # Panda, 30 Hz, m 16 32 64
    .venv/bin/python tools/period_consistency.py --substeps 16 32 --seeds 0 1 --duration 5

The Panda's library at T = 1/30 s (``library_at_period``) with m rk4 substeps per T, its
compiled ``encoders`` estimator (motor encoders qm, qmd at every step), against a truth that
no library computes: the continuous flexible-joint model (eqs. 1a-1d) integrated by scipy's
DOP853 (rtol 1e-9) with Pinocchio's ABA, the payload at its true value, process-noise
impulses drawn from the filter's own Qw at the start of every period (w_l on M(q) qd, w_m on
Mm qmd: eq. 3's noise entry) and encoder noise from its own R.  The input is a gravity
compensation on the true state held over each period plus a 0.5 Hz, 2 N m sine per joint, so
the arm moves and stays up.  The same truth (per seed) serves every m.  Reported per m: the
time-averaged NEES / N of the 4n joint states over the last 80 % of the run (1 = consistent;
the 95 % band of one 10 s run is about 1 +- 0.1), its median over seeds, and the largest
error of q (a filter that fails, NaN or a lost covariance, counts as NEES/N = inf).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from amsfe_sym.codegen import library_at_period
from amsfe_sym.codegen.modes import joint_modes
from amsfe_sym.errors import EstimatorError
from amsfe_sym.estimation.base import FilterConfig
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)

FloatArray = NDArray[np.float64]
LINK_STD = 2.0  # process noise: link and motor torque std [N m] held over a period
MOTOR_STD = 2.0
ENC_Q_STD = 1e-4  # motor encoder [rad], its rate [rad/s]
ENC_QD_STD = 1e-3


def truth(robot: Robot, T: float, K: int, seed: int) -> tuple[FloatArray, FloatArray]:
    """States x[0..K] (4n, no theta) and inputs u[0..K-1] of one seeded run."""
    n = robot.n
    model = robot.pin_model_at(robot.theta_true)
    data = model.createData()
    Ks, Mm, Fm = robot.stiffness_at(robot.theta_true), robot.Mm, robot.Fm
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, n)
    q0 = rng.uniform(-0.5, 0.5, n)
    g0 = pin.computeGeneralizedGravity(model, data, robot.to_pin_q(q0))
    x = np.concatenate([q0, np.zeros(n), q0 + g0 / Ks, np.zeros(n)])
    xs, us = [x], []
    for k in range(K):
        q = x[:n]
        pq = robot.to_pin_q(q)
        u = pin.computeGeneralizedGravity(model, data, pq) + 2.0 * np.sin(np.pi * k * T + phase)
        M = pin.crba(model, data, pq)
        M = np.triu(M) + np.triu(M, 1).T
        x = x.copy()  # the impulses of eq. (3) at the start of the period
        x[n : 2 * n] += np.linalg.solve(M, rng.normal(0, LINK_STD * T, n))
        x[3 * n :] += rng.normal(0, MOTOR_STD * T, n) / Mm

        def f(_t: float, y: FloatArray, u: FloatArray = u) -> FloatArray:
            qq, qd, qm, qmd = y[:n], y[n : 2 * n], y[2 * n : 3 * n], y[3 * n :]
            spring = Ks * (qm - qq)
            qdd = pin.aba(model, data, robot.to_pin_q(qq), qd, spring)
            return np.concatenate([qd, qdd, qmd, (u - Fm * qmd - spring) / Mm])

        x = solve_ivp(f, (0.0, T), x, method="DOP853", rtol=1e-9, atol=1e-11).y[:, -1]
        xs.append(x)
        us.append(u)
    return np.array(xs), np.array(us)


def run(lib: object, xs: FloatArray, us: FloatArray, seed: int) -> tuple[float, float]:
    """The compiled encoders estimator over one truth: mean NEES/N (4n states, last 80 %)
    and the largest |q error| [rad]."""
    n = lib.n  # type: ignore[attr-defined]
    rng = np.random.default_rng(10_000 + seed)
    theta = lib.theta_true  # type: ignore[attr-defined]
    std0 = np.r_[np.full(n, 1e-3), np.full(n, 1e-2), np.full(n, 1e-4), np.full(n, 1e-2)]
    P0 = np.diag(np.r_[std0**2, np.full(len(theta), 1e-8)])
    x0 = np.r_[xs[0] + rng.normal(0, std0), theta]
    est = make_compiled_estimator(
        "encoders",
        model=CompiledTransition(lib, noise_covariance(lib, LINK_STD, MOTOR_STD, 1e-6)),
        encoder=EncoderMeasurement(lib, ENC_Q_STD**2, ENC_QD_STD**2),
        camera=CameraMeasurement(lib, 1.0),
        x0=x0,
        P0=P0,
        config=FilterConfig(),
    )
    nees, qerr = [], 0.0
    for k in range(len(us)):
        xt = xs[k + 1]
        z = np.r_[xt[2 * n : 3 * n], xt[3 * n :]]
        z = z + np.r_[rng.normal(0, ENC_Q_STD, n), rng.normal(0, ENC_QD_STD, n)]
        try:
            est.step(us[k], z)
        except EstimatorError:  # a diverged filter counts as NEES/N = inf
            return float("inf"), float("nan")
        e = est.x[: 4 * n] - xt
        nees.append(float(e @ np.linalg.solve(est.P[: 4 * n, : 4 * n], e)) / (4 * n))
        qerr = max(qerr, float(np.max(np.abs(e[:n]))))
    tail = nees[len(nees) // 5 :]
    return float(np.mean(tail)), qerr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--period", type=float, default=1.0 / 30.0)
    ap.add_argument("--substeps", type=int, nargs="+", default=[16, 32, 64])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--duration", type=float, default=10.0)
    args = ap.parse_args()
    robot = load_robot("panda")
    T = args.period
    K = round(args.duration / T)
    libs = {m: library_at_period("panda", T, substeps=m) for m in args.substeps}
    wmax = max(jm.highest.w for jm in joint_modes(robot))
    t0 = time.perf_counter()
    truths = {s: truth(robot, T, K, s) for s in args.seeds}
    print(f"truth: {len(args.seeds)} x {K} periods in {time.perf_counter() - t0:.1f} s")
    for m, lib in libs.items():
        rows = [run(lib, *truths[s], s) for s in args.seeds]
        nees = [r[0] for r in rows]
        print(
            f"m = {m:3d} (w h <= {wmax * T / m:.2f}): NEES/N per seed "
            + " ".join(f"{v:.3g}" for v in nees)
            + f"; median {np.median(nees):.3g}; max |q error| {max(r[1] for r in rows):.2g} rad"
        )


if __name__ == "__main__":
    main()
