"""Robot spec: what the URDF does not say (actuators, camera, unknown parameters, T).

A robot is a folder ``robots/<name>/`` holding a URDF and ``robot.toml``; every key is
documented in ``docs/reference/robot-spec.md``.  A bare URDF path works too: :func:`default_spec`
fills in documented defaults (every non-fixed joint modelled, the tip of the chain
tracked, a camera that sees the whole workspace, no unknown parameters).

The spec is parsed into frozen dataclasses; nothing here touches Pinocchio or CasADi, so
names (joints, frames) are checked later, in :mod:`amsfe_sym.load`, against the model.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal

from amsfe_sym.core.toml import read_toml
from amsfe_sym.core.values import (
    PERIOD_MAX,
    PERIOD_MIN,
    read_in_range,
)
from amsfe_sym.errors import SpecError, describe
from amsfe_sym.load.rotation import read_marker_orientation, read_orientation
from amsfe_sym.load.spec_values import (
    read_count,
    read_finite,
    read_names,
    read_opt_pos,
    read_opt_vec,
    read_steps,
    read_table,
    read_vec3,
    refuse_unknown,
)

__all__ = [
    "ActuatorSpec",
    "CameraSpec",
    "ModelSpec",
    "RobotSpec",
    "ThetaSpec",
    "TrackedSpec",
    "data_dir",
    "default_spec",
    "find_robot",
    "load_spec",
    "robots_dir",
]

ThetaKind = Literal["payload_mass", "link_mass", "joint_stiffness"]
THETA_KINDS: tuple[str, ...] = ("payload_mass", "link_mass", "joint_stiffness")
Integrator = Literal["paper", "semi_implicit", "rk4"]
INTEGRATORS: tuple[str, ...] = ("paper", "semi_implicit", "rk4")


@dataclass(frozen=True)
class ModelSpec:
    """Which joints are modelled and how time is discretised.

    Attributes:
        joints: Modelled joint names in q order; ``None`` means every non-fixed joint.
        locked: Joint name -> value [rad or m] for joints held fixed.
        T: Sampling interval [s] of the discrete model, eqs. (1a)-(1d).
        gravity: Gravity vector in the world frame [m/s^2].
        integrator: ``"paper"`` (eqs. 1a-1d as printed: q advances with the old velocity),
            ``"semi_implicit"`` (q advances with the new velocity; stable for stiff joints) or
            ``"rk4"`` (one RK4 step of the continuous model; no systematic position error).
        inverse_iterations: Unrolled fixed-point steps of the inverse transition (eq. 22).
        plant_substeps: RK4 substeps per T of the continuous-time plant.
        model_substeps: RK4 steps per T of the estimator's ``rk4`` model F (used whenever the
            model is ``rk4``, the spec's integrator or a scenario's): more resolve a joint
            mode near w T ~ 1 that one step mis-integrates (robots/ur5,
            docs/explanation/ur5-estimation.md).
    """

    joints: tuple[str, ...] | None = None
    locked: Mapping[str, float] = field(default_factory=dict)
    T: float = 0.001
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    integrator: Integrator = "semi_implicit"
    inverse_iterations: int = 6
    plant_substeps: int = 10
    model_substeps: int = 1


@dataclass(frozen=True)
class ActuatorSpec:
    """Per-joint elastic actuator constants, in q order (eqs. 1c-1d).

    Attributes:
        Ks: Joint stiffness [N m/rad] (or [N/m] for a prismatic joint).
        Mm: Motor inertia reflected to the link side [kg m^2] (or [kg]).
        Fm: Motor viscous friction [N m s/rad] (or [N s/m]).
        u_max: Motor torque limit [N m] (or [N]); default the URDF's ``effort`` limit where
            it gives one (> 0), else none.
    """

    Ks: tuple[float, ...] | None = None
    Mm: tuple[float, ...] | None = None
    Fm: tuple[float, ...] | None = None
    u_max: tuple[float, ...] | None = None


@dataclass(frozen=True)
class TrackedSpec:
    """The point the camera sees: ``offset`` [m] expressed in ``frame``; ``orientation`` the
    marker's frame in ``frame`` (a unit quaternion [qx, qy, qz, qw], OpenCV's ArUco marker
    frame: :func:`~amsfe_sym.load.rotation.read_marker_orientation`), None when not known
    (the generated functions see the point only; the images and the corner fit use it)."""

    frame: str | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole camera, OpenCV convention (x right, y down, z along the optical axis).

    Attributes:
        width, height: Image size [px].
        fx, fy: Focal lengths [px]; cx, cy: principal point [px].
        position: Camera centre in the world frame [m].
        look_at: A world point on the optical axis [m].
        up: World direction that appears up in the image (must not be parallel to the axis).
        orientation: Instead of ``look_at`` / ``up``, with ``position``: the unit quaternion
            ``[qx, qy, qz, qw]`` of world-from-camera (its matrix's columns: the camera's x
            right, y down, z forward axes in the world).
        period: l, steps between two exposures (eq. 11).
        delay: d, steps from exposure to delivery.
    """

    width: int = 640
    height: int = 512
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    position: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    period: int = 125
    delay: int = 125
    orientation: tuple[float, float, float, float] | None = None


#: The keys of ``[camera]``: the fields of :class:`CameraSpec`.
_CAMERA_KEYS = {f.name for f in fields(CameraSpec)}


@dataclass(frozen=True)
class ThetaSpec:
    """One unknown parameter, a random-walk state (eq. 2, after eq. 1d).

    Attributes:
        name: Identifier used in the manifest and run outputs.
        kind: ``payload_mass`` (a point mass [kg] at ``offset`` in frame ``target``),
            ``link_mass`` (the mass [kg] of link ``target``; its rotational inertia scales
            with it, centre of mass kept) or ``joint_stiffness`` (Ks [N m/rad] of joint
            ``target``, replacing the actuator value).
        target: Frame, link or joint name, as the kind requires.
        offset: Payload position in ``target`` [m] (``payload_mass`` only).
        true: Value used by the simulated plant.
        initial: The estimator's initial guess.
    """

    name: str
    kind: ThetaKind
    target: str
    true: float
    initial: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RobotSpec:
    """Everything about a robot beyond its URDF.  See ``docs/reference/robot-spec.md``.

    Attributes:
        name: Robot name; output goes to ``generated/<name>/``.
        urdf: Path of the URDF file.
        spec_path: The TOML file this came from, or ``None`` for a bare URDF.
        model, actuators, tracked, camera: Sub-specs (see their classes).
        theta: Unknown parameters, in state order.
    """

    name: str
    urdf: Path
    spec_path: Path | None = None
    model: ModelSpec = field(default_factory=ModelSpec)
    actuators: ActuatorSpec = field(default_factory=ActuatorSpec)
    tracked: TrackedSpec = field(default_factory=TrackedSpec)
    camera: CameraSpec = field(default_factory=CameraSpec)
    theta: tuple[ThetaSpec, ...] = ()

    def with_locked(self, extra: Mapping[str, float]) -> RobotSpec:
        """Return a copy with more joints locked (values in rad or m)."""
        if not extra:
            return self
        locked = dict(self.model.locked)
        locked.update(extra)
        joints = self.model.joints
        if joints is not None:
            joints = tuple(j for j in joints if j not in extra)
        return replace(self, model=replace(self.model, locked=locked, joints=joints))

    def fingerprint(self) -> str:
        """SHA-256 of the URDF and spec file contents plus the resolved fields."""
        h = hashlib.sha256()
        h.update(self.urdf.read_bytes())
        if self.spec_path is not None:
            h.update(self.spec_path.read_bytes())
        h.update(repr((self.model, self.actuators, self.tracked, self.camera, self.theta)).encode())
        return h.hexdigest()


# --------------------------------------------------------------------------------------
# locating robots


def data_dir(kind: str, env_var: str) -> Path:
    """A folder of shipped data (``robots``, ``scenarios``): ``$<env_var>``, the repository's
    ``<kind>/`` (editable install), else the copy packaged as ``amsfe_sym/_data/<kind>``."""
    env = os.environ.get(env_var)
    if env:
        return Path(env)
    package = Path(__file__).resolve().parent.parent
    repo = package.parent.parent / kind
    return repo if repo.is_dir() else package / "_data" / kind


def robots_dir() -> Path:
    """Folder of shipped robots (``$AMSFE_ROBOTS_DIR`` overrides)."""
    return data_dir("robots", "AMSFE_ROBOTS_DIR")


def find_robot(name_or_path: str | os.PathLike[str]) -> Path:
    """Resolve a robot name, a robot folder, a ``robot.toml`` or a URDF path to a file path.

    Raises:
        SpecError: nothing matches; the message lists the shipped robots.
    """
    p = Path(name_or_path)
    if p.is_file():
        return p
    if p.is_dir() and (p / "robot.toml").is_file():
        return p / "robot.toml"
    shipped = robots_dir() / str(name_or_path) / "robot.toml"
    if shipped.is_file():
        return shipped
    known = sorted(d.name for d in robots_dir().glob("*") if (d / "robot.toml").is_file())
    raise SpecError(
        describe(
            f"robot {str(name_or_path)!r}",
            "a shipped robot name, a robot folder with robot.toml, a robot.toml or a .urdf file",
            "no such file or robot",
            f"use one of {known} or give a path to an existing URDF",
        )
    )


def load_spec(name_or_path: str | os.PathLike[str]) -> RobotSpec:
    """Load a robot spec from a name, folder, ``robot.toml`` or bare URDF path."""
    path = find_robot(name_or_path)
    if path.suffix.lower() == ".urdf":
        return default_spec(path)
    if path.suffix.lower() != ".toml":
        raise SpecError(
            describe(
                str(path),
                "a .toml robot spec or a .urdf file",
                f"a file ending in {path.suffix!r}",
                "pass the robot folder, its robot.toml or a URDF",
            )
        )
    return parse_spec(read_toml(path, SpecError), path)


def default_spec(urdf: Path) -> RobotSpec:
    """Spec for a bare URDF: all non-fixed joints, tip of the chain tracked, defaults below.

    Defaults (documented in docs/reference/robot-spec.md): T = 1 ms, semi-implicit integrator,
    Ks = 1000 N m/rad, Mm = 0.1 kg m^2, Fm = 1 N m s/rad per joint, camera placed by
    :func:`amsfe_sym.load.load_robot` so that it sees the whole workspace, p = 0.
    """
    return RobotSpec(name=_sanitize(urdf.stem), urdf=urdf.resolve(), spec_path=None)


# --------------------------------------------------------------------------------------
# parsing


_TOP_KEYS = {"name", "urdf", "model", "actuators", "tracked", "camera", "theta"}


def parse_spec(data: Mapping[str, Any], path: Path) -> RobotSpec:
    """Build a :class:`RobotSpec` from parsed TOML ``data`` read from ``path``."""
    where = str(path)
    refuse_unknown(data, _TOP_KEYS, where)
    if "urdf" not in data:
        raise SpecError(
            describe(where, "a top-level key 'urdf'", "none", 'add urdf = "<file>.urdf"')
        )
    urdf = (path.parent / str(data["urdf"])).resolve()
    if not urdf.is_file():
        raise SpecError(
            describe(
                f"{where}: urdf",
                "an existing file",
                str(urdf),
                "fix the path (relative to the spec)",
            )
        )
    name = _sanitize(str(data.get("name", path.parent.name)))

    m = read_table(data, "model", where)
    refuse_unknown(
        m,
        {
            "joints",
            "locked",
            "T",
            "gravity",
            "integrator",
            "inverse_iterations",
            "plant_substeps",
            "model_substeps",
        },
        f"{where} [model]",
    )
    integrator = str(m.get("integrator", "semi_implicit"))
    if integrator not in INTEGRATORS:
        raise SpecError(
            describe(
                f"{where} [model] integrator",
                f"one of {INTEGRATORS}",
                repr(integrator),
                "pick one of those",
            )
        )
    T = read_in_range(
        m.get("T", 0.001), f"{where} [model] T", SpecError, PERIOD_MIN, PERIOD_MAX, "give T in s"
    )
    joints = m.get("joints")
    model = ModelSpec(
        joints=None if joints is None else read_names(joints, f"{where} [model] joints"),
        locked={
            str(k): read_finite(v, f"{where} [model] locked {k}")
            for k, v in read_table(m, "locked", f"{where} [model]").items()
        },
        T=T,
        gravity=read_vec3(m.get("gravity", (0.0, 0.0, -9.81)), f"{where} [model] gravity"),
        integrator=integrator,  # type: ignore[arg-type]
        inverse_iterations=read_steps(
            m.get("inverse_iterations", 6), f"{where} inverse_iterations"
        ),
        plant_substeps=read_steps(m.get("plant_substeps", 10), f"{where} plant_substeps"),
        model_substeps=read_steps(m.get("model_substeps", 1), f"{where} model_substeps"),
    )

    a = read_table(data, "actuators", where)
    refuse_unknown(a, {"Ks", "Mm", "Fm", "u_max"}, f"{where} [actuators]")
    actuators = ActuatorSpec(
        Ks=read_opt_vec(a.get("Ks"), f"{where} [actuators] Ks"),
        Mm=read_opt_vec(a.get("Mm"), f"{where} [actuators] Mm"),
        Fm=read_opt_vec(a.get("Fm"), f"{where} [actuators] Fm", strict=False),
        u_max=read_opt_vec(a.get("u_max"), f"{where} [actuators] u_max"),
    )

    t = read_table(data, "tracked", where)
    refuse_unknown(t, {"frame", "offset", "orientation"}, f"{where} [tracked]")
    tracked = TrackedSpec(
        frame=None if t.get("frame") is None else str(t["frame"]),
        offset=read_vec3(t.get("offset", (0.0, 0.0, 0.0)), f"{where} [tracked] offset"),
        orientation=read_marker_orientation(t, f"{where} [tracked]"),
    )

    c = read_table(data, "camera", where)
    refuse_unknown(
        c,
        _CAMERA_KEYS,
        f"{where} [camera]",
    )
    camera = CameraSpec(
        width=read_count(c.get("width", 640), f"{where} [camera] width", 1),
        height=read_count(c.get("height", 512), f"{where} [camera] height", 1),
        fx=read_opt_pos(c.get("fx"), f"{where} [camera] fx"),
        fy=read_opt_pos(c.get("fy"), f"{where} [camera] fy"),
        cx=None if c.get("cx") is None else read_finite(c["cx"], f"{where} [camera] cx"),
        cy=None if c.get("cy") is None else read_finite(c["cy"], f"{where} [camera] cy"),
        position=None
        if c.get("position") is None
        else read_vec3(c["position"], f"{where} position"),
        look_at=None if c.get("look_at") is None else read_vec3(c["look_at"], f"{where} look_at"),
        up=read_vec3(c.get("up", (0.0, 0.0, 1.0)), f"{where} [camera] up"),
        period=read_count(c.get("period", 125), f"{where} [camera] period", 1),
        delay=read_count(c.get("delay", 125), f"{where} [camera] delay", 0),
        orientation=read_orientation(c, f"{where} [camera]"),
    )

    thetas: list[ThetaSpec] = []
    raw_theta = data.get("theta", [])
    if not isinstance(raw_theta, list):
        raise SpecError(
            describe(
                f"{where} theta",
                "an array of tables [[theta]]",
                type(raw_theta).__name__,
                "write each parameter as a [[theta]] table",
            )
        )
    for i, th in enumerate(raw_theta):
        w = f"{where} [[theta]] #{i + 1}"
        refuse_unknown(th, {"name", "kind", "target", "offset", "true", "initial"}, w)
        for key in ("name", "kind", "target", "true", "initial"):
            if key not in th:
                raise SpecError(describe(w, f"key {key!r}", "it missing", f"add {key} = ..."))
        kind = str(th["kind"])
        if kind not in THETA_KINDS:
            raise SpecError(
                describe(
                    f"{w} kind", f"one of {THETA_KINDS}", repr(kind), "use one of the kinds listed"
                )
            )
        thetas.append(
            ThetaSpec(
                name=str(th["name"]),
                kind=kind,  # type: ignore[arg-type]
                target=str(th["target"]),
                true=read_finite(th["true"], f"{w} true"),
                initial=read_finite(th["initial"], f"{w} initial"),
                offset=read_vec3(th.get("offset", (0.0, 0.0, 0.0)), f"{w} offset"),
            )
        )
    names = [t.name for t in thetas]
    if len(set(names)) != len(names):
        raise SpecError(describe(f"{where} theta names", "unique names", str(names), "rename"))
    return RobotSpec(
        name=name,
        urdf=urdf,
        spec_path=path.resolve(),
        model=model,
        actuators=actuators,
        tracked=tracked,
        camera=camera,
        theta=tuple(thetas),
    )


def _sanitize(name: str) -> str:
    """A C-identifier-safe robot name (letters, digits, underscore)."""
    out = "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name)
    if not out or out[0].isdigit():
        out = "r_" + out
    return out
