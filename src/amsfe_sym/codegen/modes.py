"""Joint modes over the workspace, and a robot's library at another sampling interval
(docs/explanation/codegen.md, "Joint modes and other sampling intervals").

:func:`joint_modes` linearises the flexible-joint model (eqs. 1a-1d) at rest at random link
angles within the joint limits and solves the undamped two-mass eigenproblem

    [[Ks, -Ks], [-Ks, Ks]] phi = w^2 diag(M(q), Mm) phi

(M(q) from Pinocchio's CRBA; the n zero eigenvalues are the rigid-body motions qm = q, the n
others the elastic modes).  Each elastic mode goes to the joint whose spring stores most of its
strain energy, ``Ks_i (phi_m,i - phi_l,i)^2``, and gets the modal damping ratio ``zeta =
phi^T diag(0, Fm) phi / (2 w)`` (phi mass-normalised: the light-damping approximation, which
neglects the coupling of the modes through the motor damping).  Per joint it keeps the
fastest mode and, per integrator, the one that needs the smallest step
(:mod:`amsfe_sym.runtime.stability` says which w h each integrator can take).  Numerics
are Pinocchio and numpy only (no CasADi): 200 samples of the Panda take 0.04 s
(docs/explanation/codegen.md, "Joint modes").

:func:`spec_at_period` derives, in memory, the spec of a robot sampled at another T (the robot
folder is never edited), with ``model_substeps`` chosen from the modes;
:func:`amsfe_sym.codegen.libraries.library_at_period` generates (or reuses, cached by content
like every library) and loads it.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import SpecError, describe
from amsfe_sym.load.spec import INTEGRATORS, RobotSpec, load_spec, robots_dir
from amsfe_sym.runtime.stability import (
    DEFAULT_MARGIN,
    STABILITY_MARGIN,
    JointMode,
    ModalPoint,
    RobotSource,
    StiffJoint,
    stable_wh,
    stiff_joints,
    stiffness_fix,
    substeps_for,
)

if TYPE_CHECKING:  # (Pinocchio's types: imported when modes are computed)
    from amsfe_sym.load.types import Robot

__all__ = [
    "DEFAULT_SAMPLES",
    "ModeSet",
    "derived_name",
    "joint_modes",
    "modes_at",
    "modes_document",
    "period_fix",
    "robot_source",
    "spec_at_period",
    "warn_stiff",
]

#: Random configurations :func:`joint_modes` samples (seeded: the same modes every call).
DEFAULT_SAMPLES = 200


def _sample_q(robot: Robot, samples: int, seed: int) -> NDArray[np.float64]:
    """``samples`` x n link angles uniform within the joint limits (revolute joints clipped to
    [-pi, pi], continuous ones over it, prismatic ones within their limits or +-1 m)."""
    rng = np.random.default_rng(seed)
    model = robot.model
    lo = np.empty(robot.n)
    hi = np.empty(robot.n)
    for i, j in enumerate(robot.joints):
        a, b = float(model.lowerPositionLimit[j.idx_q]), float(model.upperPositionLimit[j.idx_q])
        span = math.pi if j.kind != "prismatic" else 1.0
        if j.kind == "continuous" or not (math.isfinite(a) and math.isfinite(b)) or a >= b:
            a, b = -span, span
        lo[i], hi[i] = max(a, -span), min(b, span)
        if lo[i] >= hi[i]:
            lo[i], hi[i] = -span, span
    return rng.uniform(lo, hi, size=(samples, robot.n))


@dataclass(frozen=True)
class ModeSet:
    """The n elastic modes at each of S configurations, ascending in w per configuration.

    Attributes:
        w: Undamped angular frequencies [rad/s], ``(S, n)``.
        zeta: Modal damping ratios [-], ``(S, n)``.
        joint: Index (in q) of the joint whose spring stores most of each mode's strain
            energy, ``(S, n)``.
    """

    w: NDArray[np.float64]
    zeta: NDArray[np.float64]
    joint: NDArray[np.int64]


def modes_at(robot: Robot, qs: NDArray[np.float64], theta: NDArray[np.float64]) -> ModeSet:
    """The elastic modes at each configuration of ``qs`` [rad] ``(S, n)`` with parameters
    ``theta`` (module docstring: generalized eigenproblem, strain-energy mapping, modal
    damping)."""
    import pinocchio as pin  # here, not at import: reading a cached library needs none

    n = robot.n
    model = robot.pin_model_at(theta)
    data = model.createData()
    Ks = robot.stiffness_at(theta)
    Mm, Fm = robot.Mm, robot.Fm
    S = len(qs)
    B = np.zeros((S, 2 * n, 2 * n))
    for s, q in enumerate(qs):
        M = pin.crba(model, data, robot.to_pin_q(q))
        B[s, :n, :n] = np.triu(M) + np.triu(M, 1).T
    B[:, n:, n:] = np.diag(Mm)
    K = np.block([[np.diag(Ks), -np.diag(Ks)], [-np.diag(Ks), np.diag(Ks)]])
    # a configuration where M(q) is not numerically positive definite (a URDF link with no
    # inertia about a joint axis, not caught by load's 8-sample check) has no modes: it is
    # given the smallest positive inertia instead of stopping `amsfe generate`
    floor = 1e-12 * max(1.0, float(np.abs(B).max()))
    low = np.linalg.eigvalsh(B)[:, 0] <= floor
    if low.any():
        B[low] += floor * np.eye(2 * n)
    L = np.linalg.cholesky(B)  # B = L L^T: K phi = w^2 B phi  <=>  (L^-1 K L^-T) y = w^2 y
    Linv = np.linalg.inv(L)
    lam, Y = np.linalg.eigh(Linv @ K @ np.swapaxes(Linv, 1, 2))
    lam, Y = lam[:, n:], Y[:, :, n:]  # the n elastic modes (the n others are qm = q, w = 0)
    phi = np.swapaxes(Linv, 1, 2) @ Y  # mass-normalised: phi^T B phi = I
    w = np.sqrt(np.maximum(lam, 0.0))
    strain = Ks[None, :, None] * (phi[:, n:, :] - phi[:, :n, :]) ** 2
    joint = np.argmax(strain, axis=1)
    damping = np.einsum("i,sik->sk", Fm, phi[:, n:, :] ** 2)
    zeta = damping / (2.0 * np.maximum(w, 1e-300))
    return ModeSet(w, zeta, joint)


def joint_modes(
    robot: Robot, samples: int = DEFAULT_SAMPLES, seed: int = 0
) -> tuple[JointMode, ...]:
    """Each joint's elastic mode over the workspace (module docstring).

    Sampled at ``samples`` random link angles within the joint limits (seeded), with the
    parameters theta at their true and their initial values (a payload lowers w, a stiffness
    parameter may raise it).

    Args:
        robot: The loaded robot.
        samples: Configurations sampled.
        seed: Seed of the sampling generator.

    Returns:
        One :class:`JointMode` per modelled joint, in q order (a joint that no mode maps to
        at any sample gets w = 0).
    """
    qs = _sample_q(robot, samples, seed)
    ws, zs, js, qi = [], [], [], []
    thetas = [tuple(robot.theta_true)]
    if tuple(robot.theta_initial) != thetas[0]:
        thetas.append(tuple(robot.theta_initial))
    for theta in thetas:
        ms = modes_at(robot, qs, np.array(theta, dtype=float))
        ws.append(ms.w.ravel())
        zs.append(ms.zeta.ravel())
        js.append(ms.joint.ravel())
        qi.append(np.repeat(np.arange(len(qs)), robot.n))
    w, z, j, qidx = (np.concatenate(a) for a in (ws, zs, js, qi))
    h_max = {k: stable_wh(k, z) / np.maximum(w, 1e-300) for k in INTEGRATORS}
    out = []
    for i, info in enumerate(robot.joints):
        mine = np.nonzero(j == i)[0]
        if mine.size == 0:
            zero = ModalPoint(0.0, 0.0, ())
            out.append(JointMode(info.name, zero, {k: zero for k in INTEGRATORS}))
            continue

        def point(k: int) -> ModalPoint:
            return ModalPoint(float(w[k]), float(z[k]), tuple(float(v) for v in qs[qidx[k]]))

        fastest = point(int(mine[np.argmax(w[mine])]))
        critical = {k: point(int(mine[np.argmin(h_max[k][mine])])) for k in INTEGRATORS}
        out.append(JointMode(info.name, fastest, critical))
    return tuple(out)


def modes_document(
    robot: Robot, modes: tuple[JointMode, ...], samples: int = DEFAULT_SAMPLES, seed: int = 0
) -> dict[str, Any]:
    """The manifest's ``joint_modes`` entry: the modes, how they were sampled, and where the
    user fixes the robot (:func:`robot_source`, for the fixes
    :mod:`amsfe_sym.runtime.stability` prints)."""
    source = robot_source(robot.spec)
    return {
        "robot": source.robot,
        "spec_file": source.spec_file,
        "samples": samples,
        "seed": seed,
        "joints": [m.as_dict() for m in modes],
    }


def robot_source(spec: RobotSpec) -> RobotSource:
    """What the user passes to ``amsfe generate`` for ``spec`` and which file they edit: a
    shipped robot by name (``robots/<name>/robot.toml``), another by its folder (or its
    ``.toml``), a bare URDF by its path.  A derived spec (:func:`spec_at_period`) keeps its
    source's ``spec_path``, so it points back to the robot it came from."""
    if spec.spec_path is None:
        return RobotSource(str(spec.urdf), None)
    path = spec.spec_path
    shipped = robots_dir().resolve() / path.parent.name / "robot.toml"
    if path.name == "robot.toml" and path.resolve() == shipped:
        return RobotSource(path.parent.name, f"robots/{path.parent.name}/robot.toml")
    return RobotSource(str(path.parent if path.name == "robot.toml" else path), str(path))


def warn_stiff(
    stiff: tuple[StiffJoint, ...], source: RobotSource, modes: tuple[JointMode, ...]
) -> None:
    """One line on stderr per joint the model cannot integrate, with the fix."""
    if not stiff:
        return
    T = stiff[0].T
    k = substeps_for(modes, T)
    fix = stiffness_fix(source, T, stiff[0].integrator, k)
    for s in stiff:
        print(f"[amsfe] warning: {s.line()}; fix: {fix}", file=sys.stderr, flush=True)


def period_fix(
    robot: str | os.PathLike[str] | RobotSpec, T: float, loaded: Robot | None = None
) -> str:
    """The one-step fix for a log sampled at ``T`` [s] that is not ``robot``'s T: the
    command that generates the robot at that period, with the substeps the joint modes
    choose (for a message such as "the log's period 0.0333 s is not the robot's T = 0.001 s;
    fix: ...")."""
    from amsfe_sym.load import load_robot

    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    rob = loaded if loaded is not None else load_robot(spec)
    k = substeps_for(joint_modes(rob), T)
    return (
        f"amsfe generate {robot_source(spec).robot} --period {T:.12g} (its own library, "
        f"model_substeps = {k} from the joint modes; in Python: "
        f"amsfe_sym.codegen.library_at_period(robot, {T:.12g}))"
    )


def derived_name(spec: RobotSpec, T: float, integrator: str, substeps: int) -> str:
    """The library name of ``spec`` at period T with ``integrator`` and m = ``substeps``
    rk4 steps per T: ``<name>_T<T in us>us_<integrator>x<m>``, e.g. ``panda_T33333p333us_rk4x16``
    (a C identifier, like every robot name)."""
    us = T * 1e6
    tag = f"{us:.0f}" if abs(us - round(us)) < 1e-6 else f"{us:.3f}".rstrip("0").replace(".", "p")
    return f"{spec.name}_T{tag}us_{integrator}x{substeps}"


def spec_at_period(
    robot: str | os.PathLike[str] | RobotSpec,
    T: float,
    substeps: int | None = None,
    margin: float = DEFAULT_MARGIN,
    loaded: Robot | None = None,
) -> RobotSpec:
    """The spec of ``robot`` sampled at period ``T`` [s], derived in memory.

    ``model_substeps`` is ``substeps`` or the smallest that keeps every joint's w h <=
    ``margin`` (:func:`~amsfe_sym.runtime.stability.substeps_for`; it is also what a
    scenario's ``integrator = "rk4"`` override uses).  A robot whose integrator is ``paper``
    or ``semi_implicit`` keeps it when it is stable at T, else becomes ``rk4`` (the only
    integrator with substeps).  The camera's period and delay are
    kept in real time (rounded, >= 1 and >= 0 steps).  The truth plant (simulation only)
    takes the robot's ``plant_substeps`` or the fewest stable ones (w h <= 2.0) if more:
    stable, not as accurate as at the robot's own T (scaling them with T made a 2-link
    library at T = 0.5 s unroll 1000 steps and compile for 60 s).  The stiffness is fixed to
    the loaded robot's (a bare URDF's default Ks depends on T).  Named by
    :func:`derived_name`, so it never replaces the robot's own library.

    Raises:
        SpecError: T outside [PERIOD_MIN, PERIOD_MAX], substeps outside [1, SUBSTEPS_MAX],
            or a T at which the joint modes need more than SUBSTEPS_MAX rk4 steps
            (docs/input-rules.md).
    """
    from amsfe_sym.codegen.preflight import check_period, check_substeps
    from amsfe_sym.load import load_robot

    T = check_period(T)  # [PERIOD_MIN, PERIOD_MAX] (docs/input-rules.md)
    if substeps is not None and (not isinstance(substeps, int) or isinstance(substeps, bool)):
        raise SpecError(
            describe("--substeps", "an integer >= 1", repr(substeps), "give e.g. 4 or omit it")
        )
    if substeps is not None:
        check_substeps(substeps, "--substeps", T, chosen=False)
    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    rob = loaded if loaded is not None else load_robot(spec)
    modes = joint_modes(rob)
    integrator = spec.model.integrator
    if substeps is None:
        substeps = check_substeps(substeps_for(modes, T, margin), "--period", T, chosen=True)
    if integrator != "rk4" and stiff_joints(modes, T, integrator):
        integrator = "rk4"
    plant = max(spec.model.plant_substeps, substeps_for(modes, T, STABILITY_MARGIN))
    check_substeps(plant, "--period (the plant's rk4 steps)", T, chosen=True)
    cam = spec.camera
    model = replace(
        spec.model,
        T=float(T),
        integrator=integrator,
        model_substeps=substeps,
        plant_substeps=plant,
    )
    return replace(
        spec,
        name=derived_name(spec, T, integrator, substeps),
        model=model,
        actuators=replace(spec.actuators, Ks=tuple(float(v) for v in rob.Ks)),
        camera=replace(
            cam,
            period=max(1, round(cam.period * spec.model.T / T)),
            delay=max(0, round(cam.delay * spec.model.T / T)),
        ),
    )
