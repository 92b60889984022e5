"""URDF validation before Pinocchio (which accepts several invalid things silently):
strict XML, supported joint types, mimic tags, dangling links, finite joint origins, axes
and limits (not swapped), zero axes, masses and inertia tensors; and each link's own
inertia for the theta bindings."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import UnsupportedJointError, UrdfError, describe
from amsfe_sym.load.topology import check_topology

__all__ = ["check_inertia", "link_inertias", "validate_urdf"]

_SUPPORTED_URDF_TYPES = {"revolute", "continuous", "prismatic", "fixed"}
_INERTIA_TOL = 1e-9


def validate_urdf(path: Path, locked: set[str] | frozenset[str] = frozenset()) -> Any:
    """Check XML, joint types, mimic, links, axes, masses and inertias; return yourdfpy's URDF.

    Order matters: a strict XML parse first (yourdfpy falls back to a recovering parser and
    returns a robot without joints on malformed XML), then the joints' links (yourdfpy fails
    with a bare ``list.remove`` error on a missing one), then yourdfpy's own parse and
    ``validate()``, then the physical checks on its objects, which it does not make.
    A ``<mimic>`` tag is accepted on fixed joints and on joints the spec locks.
    """
    import yourdfpy

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise UrdfError(
            describe(str(path), "well-formed XML", f"a parse error ({exc})", "fix the XML syntax")
        ) from exc
    if root.tag != "robot":
        raise UrdfError(
            describe(str(path), "a <robot> root element", f"<{root.tag}>", "is this a URDF?")
        )
    links = {ln.get("name") for ln in root.findall("link")}
    if not links:
        raise UrdfError(describe(str(path), "at least one <link>", "none", "add links"))
    for j in root.findall("joint"):
        name = j.get("name", "?")
        for tag in ("parent", "child"):
            el = j.find(tag)
            link = None if el is None else el.get("link")
            if link not in links:
                raise UrdfError(
                    describe(
                        f"{path}: joint {name!r} <{tag}>",
                        "the name of a <link> in the file",
                        repr(link),
                        "add the link or fix the name",
                    )
                )
    check_topology(root, path)  # one tree: before urdfdom/yourdfpy's misleading messages
    for j in root.findall("joint"):
        _check_joint_numbers(j, path)
    for ln in root.findall("link"):
        _check_finite(ln, f"{path}: link {ln.get('name', '?')!r}", _LINK_NUMBERS)
    try:
        urdf = yourdfpy.URDF.load(
            str(path),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
        valid = urdf.validate()
    except Exception as exc:  # yourdfpy raises plain ValueError / KeyError / lxml errors
        raise UrdfError(
            describe(str(path), "a URDF yourdfpy can parse", f"error {exc!r}", "fix the file")
        ) from exc
    if not valid:
        raise UrdfError(
            describe(
                str(path),
                "a URDF passing yourdfpy's validate()",
                "a failed check",
                "see yourdfpy's log messages above",
            )
        )
    for j in urdf.robot.joints:
        where = f"{path}: joint {j.name!r}"
        if j.type not in _SUPPORTED_URDF_TYPES:
            raise UnsupportedJointError(
                describe(
                    where,
                    "type revolute, continuous, prismatic or fixed",
                    f"type {j.type!r}",
                    "make it fixed, or lock/replace it; floating bases are not modelled",
                )
            )
        if j.type != "fixed" and j.name not in locked and j.mimic is not None:
            raise UnsupportedJointError(
                describe(
                    where,
                    "independent joints",
                    "a <mimic> joint",
                    "remove <mimic> (model it as its own joint), make it fixed or lock it",
                )
            )
        if j.type != "fixed" and j.axis is not None and float(np.linalg.norm(j.axis)) < 1e-12:
            raise UrdfError(
                describe(
                    f"{where} <axis>",
                    "a non-zero axis",
                    "xyz = 0 0 0",
                    'give the joint axis, e.g. xyz="0 0 1"',
                )
            )
    for ln in urdf.robot.links:
        if ln.inertial is None:
            continue
        where = f"{path}: link {ln.name!r}"
        mass = float(ln.inertial.mass if ln.inertial.mass is not None else 0.0)
        if not math.isfinite(mass) or mass < 0:
            raise UrdfError(
                describe(f"{where} <mass>", "a finite mass >= 0 [kg]", f"{mass}", "fix the mass")
            )
        if ln.inertial.inertia is not None:
            check_inertia(np.asarray(ln.inertial.inertia, dtype=float), where)
    return urdf


# the numbers of a <joint> that urdfdom and yourdfpy parse: element -> attributes
_JOINT_NUMBERS = {
    "origin": ("xyz", "rpy"),
    "axis": ("xyz",),
    "limit": ("lower", "upper", "effort", "velocity"),
}


# the same for a <link>'s inertial frame and its mass
_LINK_NUMBERS = {"inertial/origin": ("xyz", "rpy"), "inertial/mass": ("value",)}


def _numbers(text: str) -> list[float] | None:
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return None


def _check_joint_numbers(joint: ET.Element, path: Path) -> None:
    """Every number of a joint's origin, axis and limits is finite (urdfdom refuses NaN and
    inf only with parser noise on stderr that names no value; yourdfpy accepts them), and a
    movable joint's limits are not swapped: ``lower > upper`` is refused, because the default
    camera placement (and any user of the limits) would take the empty range as the
    workspace, and no reading of such a file is right (a warning would be lost in a build's
    output while the generated library kept the wrong camera)."""
    where = f"{path}: joint {joint.get('name', '?')!r}"
    _check_finite(joint, where, _JOINT_NUMBERS)
    limit = joint.find("limit")
    if joint.get("type") in ("revolute", "prismatic") and limit is not None:
        lower, upper = (_numbers(limit.get(a) or "0") or [0.0] for a in ("lower", "upper"))
        if len(lower) == len(upper) == 1 and lower[0] > upper[0]:
            raise UrdfError(
                describe(
                    f"{where} <limit>",
                    "lower <= upper",
                    f"lower {limit.get('lower')} > upper {limit.get('upper')}",
                    "swap the two values (the default camera placement uses the limits)",
                )
            )


def _check_finite(el: ET.Element, where: str, numbers: dict[str, tuple[str, ...]]) -> None:
    """Raise :class:`UrdfError` naming the first attribute of ``numbers`` (sub-element ->
    attributes) of ``el`` that is not a list of finite numbers."""
    for tag, attrs in numbers.items():
        sub = el.find(tag)
        for attr in attrs if sub is not None else ():
            text = sub.get(attr) if sub is not None else None
            if text is None:
                continue
            values = _numbers(text)
            if values is not None and all(math.isfinite(v) for v in values):
                continue
            raise UrdfError(
                describe(
                    f"{where} <{tag.split('/')[-1]} {attr}>",
                    "finite numbers",
                    repr(text),
                    f"write the {tag.split('/')[-1]} {attr} as finite numbers",
                )
            )


def check_inertia(inertia: NDArray[np.float64], where: str) -> None:
    """Positive semi-definite and principal moments satisfying the triangle inequality."""
    if not np.all(np.isfinite(inertia)):
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "finite values",
                "inf or NaN",
                "write the six inertia entries as finite numbers [kg m^2]",
            )
        )
    eig = np.linalg.eigvalsh(inertia)
    scale = max(float(np.max(np.abs(eig))), 1e-12)
    if eig[0] < -_INERTIA_TOL * scale:
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "a positive semi-definite tensor",
                f"principal moments {np.round(eig, 9).tolist()}",
                "check signs of the products of inertia (URDF stores +ixy, not -ixy)",
            )
        )
    a, b, c = eig
    if a + b < c - _INERTIA_TOL * scale:
        raise UrdfError(
            describe(
                f"{where} <inertia>",
                "principal moments with I1 + I2 >= I3 (triangle inequality)",
                f"{np.round(eig, 9).tolist()}",
                "no rigid body has these moments; recompute the inertia tensor",
            )
        )


def link_inertias(urdf: Any) -> dict[str, tuple[float, NDArray[np.float64], NDArray[np.float64]]]:
    """Each link's own (mass [kg], centre of mass [m], inertia about it in the link frame)."""
    out = {}
    for ln in urdf.robot.links:
        if ln.inertial is None:
            continue
        mass = float(ln.inertial.mass or 0.0)
        origin = np.eye(4) if ln.inertial.origin is None else np.asarray(ln.inertial.origin)
        R = origin[:3, :3]
        inertia = (
            np.zeros((3, 3)) if ln.inertial.inertia is None else np.asarray(ln.inertial.inertia)
        )
        out[ln.name] = (mass, origin[:3, 3].copy(), R @ inertia @ R.T)
    return out
