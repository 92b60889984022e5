"""Each shipped robot's joint modes, what its integrator makes of them at its own T and at a
log's period, and what the rk4 model's substeps cost in accuracy (issue 26, item 5): the
numbers of docs/explanation/codegen.md, "Joint modes and other sampling intervals".

    .venv/bin/python tools/joint_modes.py                        # robots/*, own T and 30 Hz
    .venv/bin/python tools/joint_modes.py --robots panda --period 0.01

Per robot and joint: the fastest elastic mode w [rad/s] over 200 random link angles, its w T
and damping ratio, whether the robot's integrator integrates its critical mode at the robot's
T and at ``--period`` (``stiff_joints``: past the limit and growing faster than 1 /s), and
``substeps_for`` at ``--period``.  Then the wall time of ``joint_modes`` (the cost ``amsfe
generate`` adds), the fastest w found with 200 and with 5000 samples (what the margin of
w h <= 2.0 must cover), and, for the Panda linearised at rest at 5 random link angles (gravity
held by the springs), the eigenvalues of the rk4 model's map over one period with m substeps,
R(h lambda)^m, against the exact exp(lambda T): the largest error over the modes below the
period's Nyquist rate (|Im lambda| T < pi, the ones a log at that rate can show) and the
largest and smallest |R(h lambda)^m| of the modes above it (exact: |exp(lambda T)| ~ 1; how
much the model damps what it cannot resolve); then the same m against a tight reference
integration (scipy DOP853) over one period from 20 moving states, nonlinear: the largest
link-angle error.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from amsfe_sym.codegen.modes import joint_modes
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.load.spec import robots_dir
from amsfe_sym.runtime.stability import stiff_joints, substeps_for


def table(robot: Robot, period: float) -> None:
    spec = robot.spec.model
    t0 = time.perf_counter()
    modes = joint_modes(robot)
    dt = time.perf_counter() - t0
    own = {s.joint for s in stiff_joints(modes, spec.T, spec.integrator, spec.model_substeps)}
    log = {s.joint for s in stiff_joints(modes, period, spec.integrator, spec.model_substeps)}
    k = substeps_for(modes, period)
    print(
        f"\n{robot.name}: T = {spec.T:g} s, integrator {spec.integrator}, model_substeps "
        f"{spec.model_substeps}; joint_modes {dt * 1e3:.0f} ms; substeps_for({period:.4g} s) = {k}"
    )
    print(f"  {'joint':<22} {'w [rad/s]':>10} {'w T':>7} {'zeta':>7} {'own T':>8} {'period':>8}")
    for m in modes:
        print(
            f"  {m.joint:<22} {m.highest.w:10.1f} {m.highest.w * spec.T:7.3f} "
            f"{m.highest.zeta:7.4f} {'STIFF' if m.joint in own else 'ok':>8} "
            f"{'STIFF' if m.joint in log else 'ok':>8}"
        )
    many = joint_modes(robot, samples=5000, seed=1)
    print(
        "  fastest w, 200 samples (seed 0) vs 5000 (seed 1): "
        + ", ".join(
            f"{a.highest.w:.0f}/{b.highest.w:.0f}" for a, b in zip(modes, many, strict=True)
        )
    )


def _continuous(robot: Robot, q: np.ndarray) -> np.ndarray:
    """A_c (4n x 4n) of eqs. (1a)-(1d) at rest at q, the springs holding gravity."""
    n = robot.n
    th = robot.theta_initial
    model = robot.pin_model_at(th)
    data = model.createData()
    pq = robot.to_pin_q(q)
    g = pin.computeGeneralizedGravity(model, data, pq)
    Ks = robot.stiffness_at(th)
    pin.computeABADerivatives(model, data, pq, np.zeros(n), g)
    Minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
    A = np.zeros((4 * n, 4 * n))
    A[:n, n : 2 * n] = np.eye(n)
    A[n : 2 * n, :n] = data.ddq_dq - Minv * Ks
    A[n : 2 * n, n : 2 * n] = data.ddq_dv
    A[n : 2 * n, 2 * n : 3 * n] = Minv * Ks
    A[2 * n : 3 * n, 3 * n :] = np.eye(n)
    A[3 * n :, :n] = np.diag(Ks / robot.Mm)
    A[3 * n :, 2 * n : 3 * n] = -np.diag(Ks / robot.Mm)
    A[3 * n :, 3 * n :] = -np.diag(robot.Fm / robot.Mm)
    return A


def accuracy(robot: Robot, period: float, steps: list[int]) -> None:
    rng = np.random.default_rng(2)
    lams = np.concatenate(
        [np.linalg.eigvals(_continuous(robot, rng.uniform(-1, 1, robot.n))) for _ in range(5)]
    )
    slow = np.abs(lams.imag) * period < math.pi
    exact = np.exp(lams * period)
    wmax = max(m.highest.w for m in joint_modes(robot))
    print(
        f"\n{robot.name} at T = {period:.4g} s, linearised at rest (5 random q): "
        f"{int(slow.sum())} modes below Nyquist, {int((~slow).sum())} above"
    )
    print(
        f"  {'m':>4} {'w h':>6} {'slow: max |mu - e^(lambda T)|':>30} {'fast: max |mu|':>15} "
        f"{'min |mu|':>9}"
    )
    for m in steps:
        z = lams * period / m
        mu = (1 + z * (1 + z * (0.5 + z * (1 / 6 + z / 24)))) ** m
        err = float(np.max(np.abs(mu[slow] - exact[slow])))
        fast = np.abs(mu[~slow]) if (~slow).any() else np.zeros(1)
        print(f"  {m:4d} {wmax * period / m:6.2f} {err:30.2e} {fast.max():15.3g} {fast.min():9.3g}")


def _rhs(
    robot: Robot, model: pin.Model, data: pin.Data, u: np.ndarray
) -> Callable[[float, np.ndarray], np.ndarray]:
    """d/dt [q, qd, qm, qmd] of the flexible-joint model (eqs. 1a-1d in continuous time)."""
    n = robot.n
    Ks, Mm, Fm = robot.Ks, robot.Mm, robot.Fm

    def f(_t: float, x: np.ndarray) -> np.ndarray:
        q, qd, qm, qmd = x[:n], x[n : 2 * n], x[2 * n : 3 * n], x[3 * n :]
        spring = Ks * (qm - q)
        qdd = pin.aba(model, data, robot.to_pin_q(q), qd, spring)
        return np.concatenate([qd, qdd, qmd, (u - Fm * qmd - spring) / Mm])

    return f


def one_step(robot: Robot, period: float, steps: list[int], deflection: float) -> None:
    """The rk4 model's one-period error against a tight reference (scipy DOP853, rtol
    1e-11) from 20 moving states of the Panda: q in +-1 rad, qd ~ N(0, 0.5) rad/s, the
    springs holding gravity plus ``deflection`` [rad] (std) that excites the elastic modes,
    u = g(q) + N(0, 1) N m."""
    from scipy.integrate import solve_ivp

    n = robot.n
    model = robot.pin_model_at(robot.theta_initial)
    data = model.createData()
    rng = np.random.default_rng(4)
    errs = {m: 0.0 for m in steps}
    for _ in range(20):
        q = rng.uniform(-1, 1, n)
        g = pin.computeGeneralizedGravity(model, data, robot.to_pin_q(q))
        qd = rng.normal(0, 0.5, n)
        qm = q + g / robot.Ks + rng.normal(0, deflection, n)
        x0 = np.concatenate([q, qd, qm, qd])
        u = g + rng.normal(0, 1.0, n)
        f = _rhs(robot, model, data, u)
        ref = solve_ivp(f, (0, period), x0, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
        for m in steps:
            x, h = x0.copy(), period / m
            for _ in range(m):
                k1 = f(0, x)
                k2 = f(0, x + h / 2 * k1)
                k3 = f(0, x + h / 2 * k2)
                k4 = f(0, x + h * k3)
                x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            errs[m] = max(errs[m], float(np.max(np.abs(x[:n] - ref[:n]))))
    print(
        f"  one period from 20 moving states, spring deflection std {deflection:g} rad: "
        "max |q_model - q_ref| [rad] " + ", ".join(f"m = {m}: {e:.2g}" for m, e in errs.items())
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    names = sorted(d.name for d in robots_dir().iterdir() if (d / "robot.toml").is_file())
    ap.add_argument("--robots", nargs="+", default=names)
    ap.add_argument("--period", type=float, default=1.0 / 30.0, help="a log's period [s]")
    args = ap.parse_args()
    for name in args.robots:
        table(load_robot(name), args.period)
    if "panda" in args.robots:
        robot = load_robot("panda")
        k = substeps_for(joint_modes(robot), args.period)
        steps = sorted({8, 15, 16, 32, 48, 64, k})
        accuracy(robot, args.period, steps)
        for deflection in (0.0, 1e-4):
            one_step(robot, args.period, steps, deflection)


if __name__ == "__main__":
    main()
