"""The typed ``manifest.json``: what codegen wrote about a library, parsed once.

:class:`Manifest` is the runtime's only reader of the manifest document; every other module
reads its typed fields (``lib.manifest.camera.delay``, ``lib.manifest.theta[0].unit``)
instead of string keys.  The document itself stays available as :attr:`Manifest.raw` for
tools that show or copy it.  The field list is the contract of docs/explanation/architecture.md
("Generated-function contract").
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amsfe_sym.errors import CodegenError, describe

__all__ = [
    "Actuators",
    "CameraInfo",
    "FunctionSignature",
    "IOSpec",
    "Manifest",
    "ThetaInfo",
    "read_manifest",
]


@dataclass(frozen=True)
class IOSpec:
    """One input or output of a generated function: ``shape`` (rows, cols), and whether it
    is a ``matrix`` (a jacobian with one column is still a matrix) or a vector."""

    name: str
    shape: tuple[int, int]
    matrix: bool

    @property
    def np_shape(self) -> tuple[int, ...]:
        """numpy shape: ``(rows,)`` for vectors, ``(rows, cols)`` for matrices."""
        return self.shape if self.matrix else (self.shape[0],)


@dataclass(frozen=True)
class FunctionSignature:
    """Inputs and outputs of one generated function, in call order."""

    inputs: tuple[IOSpec, ...]
    outputs: tuple[IOSpec, ...]


@dataclass(frozen=True)
class ThetaInfo:
    """One identified parameter theta_i: ``kind`` (``payload_mass``, ``joint_stiffness``),
    ``target`` (a frame or joint name), ``true`` and ``initial`` values in ``unit``."""

    name: str
    kind: str
    target: str
    true: float
    initial: float
    unit: str


@dataclass(frozen=True)
class CameraInfo:
    """The resolved camera: intrinsics ``K`` (3x3), rotation ``R_cw`` (3x3) and ``position``
    [m] in the world, image ``width`` x ``height`` [px], the robot's period l and delay d
    [steps] (eq. 11)."""

    K: tuple[tuple[float, ...], ...]
    R_cw: tuple[tuple[float, ...], ...]
    position: tuple[float, ...]
    width: int
    height: int
    period: int
    delay: int


@dataclass(frozen=True)
class Actuators:
    """Per joint: spring stiffness ``Ks`` [N m/rad], motor inertia ``Mm`` [kg m^2], motor
    viscous friction ``Fm`` [N m s/rad], torque limit ``u_max`` [N m] (``inf``: none)."""

    Ks: tuple[float, ...]
    Mm: tuple[float, ...]
    Fm: tuple[float, ...]
    u_max: tuple[float, ...] = ()


@dataclass(frozen=True)
class Manifest:
    """A generated library's ``manifest.json``, typed (see docs/explanation/architecture.md).

    Attributes:
        name: Library (robot) name.
        library, source, header: File names in the library folder.
        urdf, spec: Paths of the robot's URDF and ``robot.toml`` (``spec`` may be None).
        joints, joint_kinds: Modelled joints in q order, and their kinds.
        n, p, N: Joints, parameters, state size 4n + p (eq. 2).
        theta: The parameters.
        T: Sample time [s].
        integrator: The estimator's discrete model (``paper``, ``semi_implicit``, ``rk4``).
        plant_substeps: RK4 substeps of ``plant_step`` per T.
        model_substeps: RK4 steps per T of the ``rk4`` model F (1 for the other models).
        state_layout: Blocks q, qd, qm, qmd, theta as (start, stop) of x.
        actuators: Ks, Mm, Fm.
        camera: The resolved camera with the robot's timing.
        camera_depends_on_theta: Whether theta moves the tracked point.
        functions: Signature of every generated function.
        content_hash: The cache key the library was built under.
        raw: The whole document as read.
    """

    name: str
    library: str
    source: str
    header: str
    urdf: str
    spec: str | None
    joints: tuple[str, ...]
    joint_kinds: tuple[str, ...]
    n: int
    p: int
    N: int
    theta: tuple[ThetaInfo, ...]
    T: float
    integrator: str
    plant_substeps: int
    model_substeps: int
    state_layout: Mapping[str, tuple[int, int]]
    actuators: Actuators
    camera: CameraInfo
    camera_depends_on_theta: bool
    functions: Mapping[str, FunctionSignature]
    content_hash: str
    raw: Mapping[str, Any]

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "manifest.json") -> Manifest:
        """Parse a manifest document.

        Raises:
            CodegenError: a key is missing or has the wrong type (an old or damaged library).
        """
        try:
            return _parse(d)
        except (KeyError, TypeError, ValueError) as exc:
            raise CodegenError(
                describe(
                    where,
                    "a manifest with every key of docs/explanation/architecture.md",
                    f"{type(exc).__name__}: {exc}",
                    "regenerate the library (`amsfe generate --force`)",
                )
            ) from exc


def _floats(v: Any) -> tuple[float, ...]:
    return tuple(float(x) for x in v)


def _io(d: Mapping[str, Any]) -> IOSpec:
    rows, cols = (int(v) for v in d["shape"])
    return IOSpec(str(d["name"]), (rows, cols), bool(d.get("matrix", cols > 1)))


def _parse(d: Mapping[str, Any]) -> Manifest:
    cam = d["camera"]
    act = d["actuators"]
    return Manifest(
        name=str(d["name"]),
        library=str(d["library"]),
        source=str(d["source"]),
        header=str(d["header"]),
        urdf=str(d["urdf"]),
        spec=None if d.get("spec") is None else str(d["spec"]),
        joints=tuple(str(j) for j in d["joints"]),
        joint_kinds=tuple(str(j) for j in d["joint_kinds"]),
        n=int(d["n"]),
        p=int(d["p"]),
        N=int(d["N"]),
        theta=tuple(
            ThetaInfo(
                name=str(t["name"]),
                kind=str(t["kind"]),
                target=str(t["target"]),
                true=float(t["true"]),
                initial=float(t["initial"]),
                unit=str(t.get("unit", "")),
            )
            for t in d["theta"]
        ),
        T=float(d["T"]),
        integrator=str(d["integrator"]),
        plant_substeps=int(d["plant_substeps"]),
        model_substeps=int(d.get("model_substeps", 1)),
        state_layout={str(k): (int(a), int(b)) for k, (a, b) in d["state_layout"].items()},
        actuators=Actuators(
            _floats(act["Ks"]),
            _floats(act["Mm"]),
            _floats(act["Fm"]),
            # null in JSON = no limit; a manifest from before the limit existed has none
            tuple(
                float("inf") if v is None else float(v)
                for v in act.get("u_max") or [None] * len(act["Ks"])
            ),
        ),
        camera=CameraInfo(
            K=tuple(_floats(r) for r in cam["K"]),
            R_cw=tuple(_floats(r) for r in cam["R_cw"]),
            position=_floats(cam["position"]),
            width=int(cam["width"]),
            height=int(cam["height"]),
            period=int(cam["period"]),
            delay=int(cam["delay"]),
        ),
        camera_depends_on_theta=bool(d.get("camera_depends_on_theta", False)),
        functions={
            str(name): FunctionSignature(
                tuple(_io(i) for i in f["inputs"]), tuple(_io(o) for o in f["outputs"])
            )
            for name, f in d["functions"].items()
        },
        content_hash=str(d["content_hash"]),
        raw=d,
    )


def read_manifest(path: str | Path) -> Manifest:
    """Read and parse ``manifest.json`` (or the folder holding it).

    Raises:
        CodegenError: unreadable, not JSON, or missing keys.
    """
    p = Path(path)
    mpath = p / "manifest.json" if p.is_dir() else p
    try:
        data = json.loads(mpath.read_text())
    except (OSError, ValueError) as exc:
        raise CodegenError(
            describe(str(mpath), "a readable manifest.json", str(exc), "run `amsfe generate`")
        ) from exc
    return Manifest.from_dict(data, str(mpath))
