"""Can a library's discrete model integrate its joints' elastic modes?
(docs/explanation/codegen.md, "Joint modes and other sampling intervals")

Each elastic joint adds a link-against-rotor mode: an oscillator ``x'' + 2 zeta w x' + w^2 x
= 0`` with w [rad/s] from the generalized eigenproblem of the linearised flexible-joint model
(eqs. 1a-1d at rest: stiffness ``[[Ks, -Ks], [-Ks, Ks]]`` against ``diag(M(q), Mm)``, motor
damping ``diag(0, Fm)``; :mod:`amsfe_sym.codegen.modes` surveys it over the workspace and
stores it in the manifest as ``joint_modes``).  A discrete model of step h keeps that mode
bounded only while ``y = w h`` stays below the integrator's limit (derived here, checked
against the 2x2 modal map in tests/test_modes.py):

``rk4``: one step multiplies the mode by ``R(h lambda)``, ``R(z) = 1 + z + z^2/2 + z^3/6 +
z^4/24``.  On the imaginary axis (undamped) ``|R(iy)|^2 = 1 - y^6/72 + y^8/576 <= 1`` iff
``y <= 2 sqrt(2) = 2.83``; with damping the limit moves (2.62-2.95 for zeta in [0, 1],
found by a search along the ray ``y (-zeta + i sqrt(1 - zeta^2))``), and for an overdamped
mode it is ``2.785 / (zeta + sqrt(zeta^2 - 1))`` (RK4 is stable on [-2.785, 0]).

``semi_implicit`` (symplectic Euler, ``v+ = v + h a(x, v)``, ``x+ = x + h v+``): the map has
det ``1 - 2 zeta y`` and trace ``2 - y^2 - 2 zeta y``; Jury's conditions give
``y <= 2 / (sqrt(zeta^2 + 1) + zeta)`` (2 when undamped).

``paper`` (eqs. 1a-1d as printed: explicit Euler in both the link and the motor):
``|1 + h lambda|^2 = 1 - 2 zeta y + y^2 <= 1`` iff ``y <= 2 zeta`` (underdamped; ``2 / (zeta +
sqrt(zeta^2 - 1))`` overdamped).  It is stable only through the motor damping Fm: an undamped
mode grows at every step.

Only the ``rk4`` model takes ``model_substeps`` (h = T / m); the Euler forms step once per T.
The limits are for the linearisation at rest (no Coriolis, no gravity gradient).  Stable is not
consistent: :func:`substeps_for` asks for ``w h <= 0.5`` (:data:`DEFAULT_MARGIN`, measured).
Numpy only: the runtime reads the stored modes to explain a covariance failure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_MARGIN",
    "GROWTH_PER_S",
    "INTEGRATOR_LIMITS",
    "NUMERICAL_FAILURES",
    "STABILITY_MARGIN",
    "STATUS_NOT_PD",
    "JointMode",
    "ModalPoint",
    "RobotSource",
    "StiffJoint",
    "covariance_hint",
    "growth_per_step",
    "modal_spectral_radius",
    "modes_from_manifest",
    "stable_wh",
    "stiff_joints",
    "stiffness_fix",
    "substeps_for",
]

#: The undamped limit of w h per integrator (see the module docstring).
INTEGRATOR_LIMITS: dict[str, float] = {
    "rk4": 2.0 * math.sqrt(2.0),
    "semi_implicit": 2.0,
    "paper": 0.0,
}
#: The w h that keeps a mode stable with headroom (rk4's limit is 2.83): each rk4 step
#: multiplies an undamped mode by |R(2i)| = 0.745 at most, and 200 samples can miss modes up
#: to 19 % faster (tools/joint_modes.py).  Stable is not enough for an estimator, see below.
STABILITY_MARGIN = 2.0
#: :func:`substeps_for` keeps every joint's fastest w h at or below this.  Measured
#: (tools/period_consistency.py: the Panda at T = 1/30 s, compiled encoders filter against a
#: DOP853 truth driven by the filter's own noise, 5 seeds x 10 s): median NEES/N 4.2e4 (two
#: seeds diverged) at w h = 1.93, 1.22 at 0.96, 1.10 at 0.64 and at 0.48: a stable model that
#: damps the modes the truth keeps (|R|^m down to 0.15 per period at w h = 1.93) makes the
#: filter overconfident.  0.5 keeps the consistent 0.64 even for a mode 19 % faster than the
#: sampled maximum (docs/explanation/codegen.md, "Joint modes and other sampling intervals").  At 1
#: kHz,
#: where the encoders observe the modes, it is conservative: one step at w h 0.92 gives 1.02.
DEFAULT_MARGIN = 0.5
#: A mode past its limit is reported only when it grows faster than this [1/s]: the paper's
#: 2-link arm (explicit Euler, joint 2's motor damping 0.5 N m s/rad) has a mode past its limit
#: that grows by 2e-5 per 1 ms step at q = 0 (measured from its transition_jacobian at rest;
#: 1.5e-4, 0.15 /s, at the worst of the 200 sampled configurations),
#: far slower than the arm's own gravity instability there (eigenvalue 1.0039 per step, 3.9 /s)
#: and absorbed by every measurement update; a mode at w T = 26 under rk4 grows 1e4-fold per
#: step.
GROWTH_PER_S = 1.0
#: ``AMSFE_ERR_NOT_PD`` of runtime/c/amsfe_runtime.h: the covariance lost positive
#: definiteness (the status :func:`covariance_hint` explains).
STATUS_NOT_PD = -2
#: The statuses a model that cannot integrate its joints ends in (runtime/c/amsfe_runtime.h):
#: ``AMSFE_ERR_NOT_PD``, ``AMSFE_ERR_NONFINITE`` (the model gave NaN or inf: a mode that grew
#: 1e4-fold per step overflows within ~80 steps) and ``AMSFE_ERR_S_NOT_PD`` (an innovation
#: covariance built from that P); the runtime adds :func:`covariance_hint` to each.
NUMERICAL_FAILURES: tuple[int, ...] = (-2, -3, -4)
#: RK4's stability interval on the negative real axis: R(z) = 1 at z = -2.785...
_RK4_REAL = 2.785293563405282


def _rk4(z: NDArray[np.complex128]) -> NDArray[np.complex128]:
    return 1.0 + z * (1.0 + z * (0.5 + z * (1.0 / 6.0 + z / 24.0)))


def _rk4_ray(zeta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Largest y with |R(y d)| <= 1, d = -zeta + i sqrt(1 - zeta^2), 0 <= zeta < 1 (scan in
    steps of 0.02 to the first unstable point, then 50 bisections)."""
    d = -zeta + 1j * np.sqrt(1.0 - zeta**2)
    grid = np.arange(0.02, 4.0 + 1e-9, 0.02)
    unstable = np.abs(_rk4(np.outer(d, grid))) > 1.0 + 1e-13
    first = np.argmax(unstable, axis=1)  # every ray leaves the region before |z| = 4
    hi = grid[first]
    lo = np.where(first > 0, grid[np.maximum(first - 1, 0)], 0.0)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        bad = np.abs(_rk4(mid * d)) > 1.0 + 1e-13
        hi = np.where(bad, mid, hi)
        lo = np.where(bad, lo, mid)
    return np.asarray(lo, dtype=float)


def stable_wh(integrator: str, zeta: ArrayLike) -> NDArray[np.float64]:
    """The largest ``w h`` for which ``integrator`` keeps a mode of damping ratio ``zeta``
    bounded (the module docstring derives each).

    Args:
        integrator: ``"rk4"``, ``"semi_implicit"`` or ``"paper"``.
        zeta: Modal damping ratios (>= 0), any shape.

    Returns:
        The limits of y = w h, same shape as ``zeta``.
    """
    z = np.maximum(np.asarray(zeta, dtype=float), 0.0)
    over = z >= 1.0
    zo = np.where(over, z, 1.0)
    root = zo + np.sqrt(zo**2 - 1.0)  # zeta + sqrt(zeta^2 - 1) of an overdamped mode
    if integrator == "paper":
        return np.where(over, 2.0 / root, 2.0 * z)
    if integrator == "semi_implicit":
        return 2.0 / (np.sqrt(z**2 + 1.0) + z)
    if integrator == "rk4":
        flat = z.reshape(-1)
        out = np.empty_like(flat)
        under = flat < 1.0
        out[under] = _rk4_ray(flat[under])
        out[~under] = _RK4_REAL / (flat[~under] + np.sqrt(flat[~under] ** 2 - 1.0))
        return out.reshape(z.shape)
    raise ValueError(f"integrator must be one of {tuple(INTEGRATOR_LIMITS)}, not {integrator!r}")


def growth_per_step(integrator: str, zeta: ArrayLike, wh: ArrayLike) -> NDArray[np.float64]:
    """Spectral radius of one step of ``integrator`` on a mode of damping ratio ``zeta`` at
    ``w h`` = ``wh`` (vectorised: the eigenvalues of the 2x2 modal map in closed form)."""
    z = np.asarray(zeta, dtype=float)
    y = np.asarray(wh, dtype=float)
    root = np.sqrt((z**2 - 1.0).astype(complex))
    lam = np.stack([-z + root, -z - root])  # eigenvalues of x'' + 2 zeta x' + x = 0
    if integrator == "rk4":
        return np.asarray(np.max(np.abs(_rk4(y * lam)), axis=0), dtype=float)
    if integrator == "paper":
        return np.asarray(np.max(np.abs(1.0 + y * lam), axis=0), dtype=float)
    if integrator == "semi_implicit":
        tr = 2.0 - y**2 - 2.0 * z * y
        det = 1.0 - 2.0 * z * y
        disc = np.sqrt((tr**2 - 4.0 * det).astype(complex))
        mu = np.stack([(tr + disc) / 2.0, (tr - disc) / 2.0])
        return np.asarray(np.max(np.abs(mu), axis=0), dtype=float)
    raise ValueError(f"integrator must be one of {tuple(INTEGRATOR_LIMITS)}, not {integrator!r}")


def modal_spectral_radius(integrator: str, zeta: float, wh: float) -> float:
    """Spectral radius of one step of ``integrator`` applied to ``x'' + 2 zeta w x' + w^2 x =
    0`` (w = 1, step y = ``wh``), built as the 2x2 update matrix itself: the reference that
    :func:`stable_wh`'s closed forms are tested against."""
    y = float(wh)
    A = np.array([[0.0, 1.0], [-1.0, -2.0 * zeta]])
    if integrator == "rk4":
        Z = y * A
        P = np.eye(2) + Z + Z @ Z / 2 + Z @ Z @ Z / 6 + Z @ Z @ Z @ Z / 24
    elif integrator == "paper":
        P = np.eye(2) + y * A
    elif integrator == "semi_implicit":  # v+ = v + y a(x, v); x+ = x + y v+
        V = np.eye(2) + y * np.array([[0.0, 0.0], [-1.0, -2.0 * zeta]])  # velocity first
        X = np.array([[1.0, 0.0], [0.0, 0.0]]) + y * np.array([[0.0, 1.0], [0.0, 0.0]])
        P = X @ V + np.array([[0.0, 0.0], [0.0, 1.0]]) @ V  # [x + y v+, v+]
    else:
        raise ValueError(f"unknown integrator {integrator!r}")
    return float(np.max(np.abs(np.linalg.eigvals(P))))


@dataclass(frozen=True)
class ModalPoint:
    """One elastic mode: undamped angular frequency ``w`` [rad/s], modal damping ratio
    ``zeta`` [-] and the link angles ``q`` [rad] where it was found."""

    w: float
    zeta: float
    q: tuple[float, ...] = ()

    def max_step(self, integrator: str) -> float:
        """The largest step h [s] that ``integrator`` integrates this mode with (inf if w = 0)."""
        if self.w <= 0.0:
            return math.inf
        return float(stable_wh(integrator, self.zeta)) / self.w


@dataclass(frozen=True)
class JointMode:
    """A joint's elastic mode over the workspace (:func:`amsfe_sym.codegen.modes.joint_modes`).

    Attributes:
        joint: Joint name.
        highest: The largest w [rad/s] of the modes mapped to the joint (most strain energy in
            its spring) over the sampled configurations, with its damping ratio.
        critical: Per integrator, the mode of this joint that needs the smallest step (for
            ``paper`` a fast, lightly damped one rather than the fastest).
    """

    joint: str
    highest: ModalPoint
    critical: Mapping[str, ModalPoint]

    def as_dict(self) -> dict[str, Any]:
        """JSON form (the manifest's ``joint_modes.joints`` entries)."""

        def point(m: ModalPoint) -> dict[str, Any]:
            return {"w": m.w, "zeta": m.zeta, "q": list(m.q)}

        return {
            "joint": self.joint,
            "highest": point(self.highest),
            "critical": {k: point(v) for k, v in self.critical.items()},
        }

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> JointMode:
        """Inverse of :meth:`as_dict`."""

        def point(m: Mapping[str, Any]) -> ModalPoint:
            return ModalPoint(float(m["w"]), float(m["zeta"]), tuple(float(v) for v in m["q"]))

        return JointMode(
            joint=str(d["joint"]),
            highest=point(d["highest"]),
            critical={str(k): point(v) for k, v in d["critical"].items()},
        )


@dataclass(frozen=True)
class StiffJoint:
    """A joint whose mode the model cannot integrate at its step.

    Attributes:
        joint: Joint name.
        w: The critical mode's angular frequency [rad/s]; ``wT`` = w T, ``wh`` = w h with
            h = T / substeps for rk4, T otherwise.
        limit: The integrator's limit of w h for that mode's damping.
        growth: The mode's amplification per step (> 1).
        integrator, T [s], substeps: The model checked.
    """

    joint: str
    w: float
    wT: float
    wh: float
    limit: float
    growth: float
    integrator: str
    T: float
    substeps: int

    def line(self) -> str:
        """``joint X: w = 790 rad/s, w T = 26.3 > 2.83 (rk4, T = 0.0333 s)`` (one step per
        T; with substeps: ``w h = ... (rk4, 4 steps per T = ...)``)."""
        per = f"{self.substeps} steps per T = {self.T:.4g} s"
        if self.integrator != "rk4" or self.substeps == 1:
            return (
                f"joint {self.joint}: w = {self.w:.4g} rad/s, w T = {self.wT:.3g} > "
                f"{self.limit:.3g} ({self.integrator}, T = {self.T:.4g} s)"
            )
        return (
            f"joint {self.joint}: w = {self.w:.4g} rad/s, w T = {self.wT:.3g}, w h = "
            f"{self.wh:.3g} > {self.limit:.3g} ({self.integrator}, {per})"
        )


def stiff_joints(
    modes: Sequence[JointMode],
    T: float,
    integrator: str,
    substeps: int = 1,
    growth_per_s: float = GROWTH_PER_S,
) -> tuple[StiffJoint, ...]:
    """The joints whose critical mode ``integrator`` cannot integrate at step T (T / substeps
    for rk4): past the limit and growing faster than ``growth_per_s`` [1/s]; worst first.

    Args:
        modes: The robot's joint modes.
        T: Sampling interval [s].
        integrator: The model's integrator.
        substeps: The rk4 model's steps per T (ignored by the Euler forms).
    """
    m = substeps if integrator == "rk4" else 1
    h = T / m
    out = []
    for jm in modes:
        c = jm.critical.get(integrator, jm.highest)
        limit = float(stable_wh(integrator, c.zeta))
        growth = float(growth_per_step(integrator, c.zeta, c.w * h))
        if c.w * h > limit and math.log(max(growth, 1.0)) > growth_per_s * h:
            out.append(StiffJoint(jm.joint, c.w, c.w * T, c.w * h, limit, growth, integrator, T, m))
    return tuple(sorted(out, key=lambda s: s.limit - s.wh))


def substeps_for(modes: Sequence[JointMode], T: float, margin: float = DEFAULT_MARGIN) -> int:
    """The smallest ``model_substeps`` m of the rk4 model with every joint's ``w T / m <=
    margin`` (its fastest mode) and every critical mode inside rk4's stability limit.

    Args:
        modes: The robot's joint modes.
        T: Sampling interval [s].
        margin: Bound of w h: :data:`DEFAULT_MARGIN` (0.5, a consistent filter) or
            :data:`STABILITY_MARGIN` (2.0, a stable model; rk4 is stable to 2.83).

    Returns:
        m >= 1.
    """
    if not margin > 0:
        raise ValueError("margin must be > 0")
    m = 1
    for jm in modes:
        m = max(m, math.ceil(jm.highest.w * T / margin - 1e-12))
        c = jm.critical.get("rk4", jm.highest)
        m = max(m, math.ceil(T / c.max_step("rk4") - 1e-12) if c.w > 0 else 1)
    return m


@dataclass(frozen=True)
class RobotSource:
    """Where a user fixes a robot: ``robot``, what to pass to ``amsfe generate`` (a shipped
    robot's name, a folder, a URDF), and ``spec_file``, the ``robot.toml`` to edit (None for
    a bare URDF)."""

    robot: str
    spec_file: str | None


def stiffness_fix(source: RobotSource, T: float, integrator: str, substeps: int) -> str:
    """The fix for :func:`stiff_joints`' joints: ``substeps`` rk4 steps per T, in the robot's
    spec or by generating at the period."""
    what = (
        f"model_substeps = {substeps}"
        if integrator == "rk4"
        else f'integrator = "rk4" and model_substeps = {substeps}'
    )
    where = (
        f"in {source.spec_file}"
        if source.spec_file is not None
        else "in a robot.toml next to the URDF"
    )
    return (
        f"set [model] {what} {where} or generate with --period/--substeps "
        f"(amsfe generate {source.robot} --period {T:.6g} --substeps {substeps})"
    )


def modes_from_manifest(raw: Mapping[str, Any]) -> tuple[JointMode, ...] | None:
    """The joint modes a library's manifest stores (None for a library built before they
    were stored, or a malformed entry)."""
    block = raw.get("joint_modes")
    if not isinstance(block, Mapping):
        return None
    try:
        return tuple(JointMode.from_dict(d) for d in block["joints"])
    except (KeyError, TypeError, ValueError):
        return None


def covariance_hint(raw: Mapping[str, Any]) -> str | None:
    """The likely cause of a covariance that lost positive definiteness, from a library's
    manifest: the joints whose mode the model cannot integrate at its T, and the fix; None
    when every joint is inside its limit (or the manifest has no modes)."""
    modes = modes_from_manifest(raw)
    if not modes:
        return None
    T = float(raw.get("T", 0.0))
    integrator = str(raw.get("integrator", "rk4"))
    substeps = int(raw.get("model_substeps", 1))
    stiff = stiff_joints(modes, T, integrator, substeps)
    if not stiff:
        return None
    block = raw["joint_modes"]
    source = RobotSource(
        str(block.get("robot", raw.get("name", "ROBOT"))),
        None if block.get("spec_file") is None else str(block["spec_file"]),
    )
    fix = stiffness_fix(source, T, integrator, substeps_for(modes, T))
    return (
        "the model cannot integrate the elastic mode of "
        + "; ".join(s.line() for s in stiff)
        + f": {fix}"
    )
