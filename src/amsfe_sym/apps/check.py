"""Check every generated function against an independent reference.

References (none of them shares code with the symbolic layer):

- ``mass_matrix``, ``bias``, ``gravity``: Pinocchio's ``crba``, ``nle``,
  ``computeGeneralizedGravity``;
- ``tracked_point``: Pinocchio's frame placement; ``camera``: a numpy pinhole of it;
- ``transition``: eqs. (1a)-(1d) in numpy on Pinocchio numerics, with
  ``f = C(q, qd)^T qd - g`` (Pinocchio's Coriolis matrix satisfies Mdot = C + C^T, so
  ``d/dq (1/2 qd^T M qd) = C^T qd``);
- ``noise_gain``: the closed form of eq. (4)'s Gamma from Pinocchio's M^-1;
- ``*_jacobian``: central finite differences of the compiled function;
- ``transition_inverse``: the round trip F^-1(F(x)) = x;
- ``plant_step``: numpy RK4 on Pinocchio's ``aba``.

Errors are norm-wise relative: ``max|a - b| / max(max|b|, floor)``.

Two implementations of the same arithmetic in another order (``transition_step_chain``: the
C loop over ``m`` rk4 steps against the one generated expression) differ by rounding, which
grows with what is chained: each rk4 step solves with M(q), so its relative rounding is about
``kappa(M) eps`` (``kappa`` M's condition number), and ``m`` steps add ``m`` of them.  That
tolerance is derived per robot, ``CHAIN_ULPS m kappa eps`` with the worst ``kappa`` of the
sampled states, and the table says so (a UR10 from a bare URDF with ``model_substeps = 7``
failed a fixed 1e-13 at 1.31e-13).  The fused ``transition_step`` against the separate
``transition``, ``transition_jacobian`` and ``noise_gain`` is the same case (one generated
expression against three, ``m`` rk4 steps each): the same derived tolerance, at least 1e-14
(an SO-101 from a bare URDF at a 125 Hz log's period, ``model_substeps = 28`` as ``generate``
advises, failed a fixed 1e-14 at up to 4.2e-14; tests/test_check_advice.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.apps.reference import PinocchioOracle
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.load import Robot
from amsfe_sym.runtime.library import ModelLibrary

__all__ = ["CheckResult", "chain_tolerance", "format_table", "random_states", "run_checks"]

Array = NDArray[np.float64]
#: Round-trip tolerance of ``transition_inverse`` (norm-wise relative, floor 1).
INVERSE_TOL = 1e-9
#: Rounding units allowed per chained rk4 step per unit of M's condition number (the
#: derived tolerance of ``transition_step_chain``: :func:`chain_tolerance`).
CHAIN_ULPS = 64.0


def chain_tolerance(substeps: int, kappa: float, floor: float = 1e-13) -> float:
    """The tolerance [relative] of two orderings of ``substeps`` chained rk4 steps whose mass
    matrix has condition number ``kappa``: ``CHAIN_ULPS substeps kappa eps``, at least
    ``floor`` (the fixed tolerance it replaces, which the shipped robots pass: 1e-13 for
    the C chain against the generated step, 1e-14 for the fused generated step against the
    separate generated functions)."""
    eps = float(np.finfo(float).eps)
    return max(floor, CHAIN_ULPS * max(1, substeps) * max(1.0, kappa) * eps)


@dataclass(frozen=True)
class CheckResult:
    """One row of ``amsfe check``: a function, its reference, the worst error seen, and the
    inputs where it failed (``transition_inverse``: each state whose round trip failed)."""

    function: str
    reference: str
    max_error: float
    tolerance: float
    samples: int
    failed_at: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return bool(self.max_error <= self.tolerance)


def rel_err(a: Array, b: Array, floor: float = 1e-9) -> float:
    """Norm-wise relative error max|a - b| / max(max|b|, floor)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return float(
        np.max(np.abs(a - b), initial=0.0) / max(float(np.max(np.abs(b), initial=0.0)), floor)
    )


def random_states(robot: Robot, count: int, rng: np.random.Generator) -> list[Array]:
    """Random states x = [q, qd, qm, qmd, theta] (eq. 2) within the joints' limits."""
    n = robot.n
    lo = np.full(n, -math.pi)
    hi = np.full(n, math.pi)
    for i, j in enumerate(robot.joints):
        if j.kind != "continuous":
            a = robot.model.lowerPositionLimit[j.idx_q]
            b = robot.model.upperPositionLimit[j.idx_q]
            if np.isfinite(a) and np.isfinite(b) and b > a:
                lo[i], hi[i] = max(a, -math.pi), min(b, math.pi)
            elif j.kind == "prismatic":
                lo[i], hi[i] = -0.5, 0.5
    out = []
    for _ in range(count):
        q = rng.uniform(lo, hi)
        qd = rng.uniform(-2.0, 2.0, n)
        qm = q + rng.uniform(-0.1, 0.1, n)
        qmd = qd + rng.uniform(-0.5, 0.5, n)
        th = np.array(
            [
                rng.uniform(0.5, 1.5) * b.spec.true
                if b.kind == "joint_stiffness"
                else rng.uniform(0.0, 2.0 * max(b.spec.true, 0.1))
                for b in robot.theta
            ]
        )
        out.append(np.concatenate([q, qd, qm, qmd, th]))
    return out


def fd_jacobian(fun: Callable[[Array], Array], x: Array, h: float = 1e-6) -> Array:
    """Central finite-difference jacobian of ``fun`` at ``x`` (step ``h`` per coordinate)."""
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((np.asarray(fun(x + e)) - np.asarray(fun(x - e))).ravel() / (2 * h))
    return np.stack(cols, axis=1)


def _bind(
    fn: Callable[..., tuple[Array, ...]], other: Array, first: bool
) -> Callable[[Array], Array]:
    """``z -> fn(other, z)[0]`` (first=True) or ``z -> fn(z, other)[0]``."""

    def call(z: Array) -> Array:
        return fn(other, z)[0] if first else fn(z, other)[0]

    return call


def run_checks(
    robot: Robot, lib: ModelLibrary, samples: int = 50, seed: int = 0
) -> list[CheckResult]:
    """Compare every generated function with its reference at ``samples`` random states.

    Raises:
        ConfigError: ``samples`` < 1 (a check over no state cannot fail).
    """
    if samples < 1:
        raise ConfigError(
            describe("check samples", "at least 1 random state", str(samples), "pass --samples 50")
        )
    rng = np.random.default_rng(seed)
    oracle = PinocchioOracle(robot)
    n = robot.n
    states = random_states(robot, samples, rng)
    inputs = [rng.uniform(-5.0, 5.0, n) for _ in states]
    f = lib.function
    cam = f("camera")
    tr = f("transition")
    errs: dict[str, list[float]] = {}
    inverse_failures: list[str] = []
    kappa = 1.0  # the worst condition number of M over the states (the chain's tolerance)

    def add(name: str, e: float) -> None:
        errs.setdefault(name, []).append(e)

    for x, u in zip(states, inputs, strict=True):
        q, qd, _qm, _qmd, th = oracle.split(x)
        M_ref = oracle.M(q, th)
        kappa = max(kappa, float(np.linalg.cond(M_ref)))
        add("mass_matrix", rel_err(f("mass_matrix")(q, th)[0], M_ref))
        add("bias", rel_err(f("bias")(q, qd, th)[0], oracle.nle(q, qd, th)))
        add("gravity", rel_err(f("gravity")(q, th)[0], oracle.g(q, th), floor=1e-6))
        r_ref = oracle.point(q, th)
        add("tracked_point", rel_err(f("tracked_point")(q, th)[0], r_ref, floor=1e-3))
        add("camera", rel_err(f("camera")(q, th)[0], robot.camera.project(r_ref)))
        J = f("camera_jacobian")(q, th)[0]
        add("camera_jacobian", rel_err(J, fd_jacobian(_bind(cam, th, first=False), q)))
        add("transition", rel_err(f("transition")(x, u)[0], oracle.transition(x, u)))
        A = f("transition_jacobian")(x, u)[0]
        add("transition_jacobian", rel_err(A, fd_jacobian(_bind(tr, u, first=False), x)))
        add("noise_gain", rel_err(f("noise_gain")(x, u)[0], oracle.noise_gain(x, u)))
        xs, As, Gs = f("transition_step")(x, u)
        add(
            "transition_step",
            max(rel_err(xs, tr(x, u)[0]), rel_err(As, A), rel_err(Gs, f("noise_gain")(x, u)[0])),
        )
        if "transition_step_chain" in lib.manifest.functions:  # rk4: the C chain (amsfe_model.c)
            xc, Ac, Gc = f("transition_step_chain")(x, u)
            add("transition_step_chain", max(rel_err(xc, xs), rel_err(Ac, As), rel_err(Gc, Gs)))
        xn = tr(x, u)[0]
        xb, residual = f("transition_inverse")(xn, u)
        e_inv = rel_err(xb, x, floor=1.0)
        add("transition_inverse", e_inv)
        if not e_inv <= INVERSE_TOL:
            inverse_failures.append(
                f"x = {np.array2string(x, precision=3, max_line_width=10**6)}, "
                f"u = {np.array2string(u, precision=3, max_line_width=10**6)}: "
                f"round trip {e_inv:.2e}, residual output {residual[0]:.2e}"
            )
        tau_d = rng.normal(0.0, 0.1, 2 * n)
        xp = x[: 4 * n]
        add(
            "plant_step",
            rel_err(f("plant_step")(xp, u, th, tau_d)[0], oracle.plant_step(xp, u, th, tau_d)),
        )
    m = int(lib.manifest.model_substeps)
    refs = {
        "mass_matrix": ("pin.crba", 1e-10),
        "bias": ("pin.nle", 1e-10),
        "gravity": ("pin.computeGeneralizedGravity", 1e-10),
        "tracked_point": ("pin frame placement", 1e-10),
        "camera": ("numpy pinhole of pin placement", 1e-10),
        "camera_jacobian": ("central finite differences", 1e-6),
        "transition": (
            "numpy RK4 on pin.aba"
            if robot.spec.model.integrator == "rk4"
            else "eqs. (1a)-(1d) on pin numerics",
            1e-10,
        ),
        "transition_jacobian": ("central finite differences", 1e-6),
        "noise_gain": (
            "eq. (4) Gamma from pin M^-1"
            if robot.spec.model.integrator != "rk4"
            else "central differences of numpy RK4",
            1e-10 if robot.spec.model.integrator != "rk4" else 1e-6,
        ),
        "transition_step": (
            f"transition, _jacobian, noise_gain; tol {CHAIN_ULPS:g} m kappa(M) eps",
            chain_tolerance(m, kappa, floor=1e-14),
        ),
        "transition_step_chain": (
            f"the generated transition_step; tol {CHAIN_ULPS:g} m kappa(M) eps, m = {m}, "
            f"kappa = {kappa:.3g}",
            chain_tolerance(m, kappa),
        ),
        "transition_inverse": ("round trip F^-1(F(x)) = x", INVERSE_TOL),
        "plant_step": ("numpy RK4 on pin.aba", 1e-10),
    }
    return [
        CheckResult(
            name,
            refs[name][0],
            max(v, key=lambda e: math.inf if math.isnan(e) else e),
            refs[name][1],
            len(v),
            tuple(inverse_failures) if name == "transition_inverse" else (),
        )
        for name, v in errs.items()
    ]


def format_table(results: list[CheckResult]) -> str:
    """A plain-text table: function, reference, max error, tolerance, pass/fail."""
    rows = [("function", "reference", "max rel. error", "tolerance", "result")]
    for r in results:
        rows.append(
            (
                r.function,
                r.reference,
                f"{r.max_error:.2e}",
                f"{r.tolerance:.2g}",
                "pass" if r.passed else "FAIL",
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(5)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)
