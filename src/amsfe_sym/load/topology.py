"""The URDF's kinematic tree: unique names, one parent per link, one root, no loop.

urdfdom (inside Pinocchio) and yourdfpy report these defects misleadingly or not at all: a
link with two parents becomes "a missing body", a loop "no modelled joints", and a
duplicate joint name lets urdfdom's raw error through.  :func:`check_topology` runs on the
strictly parsed XML before either of them sees the file, and names the links and joints
involved in one line.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from xml.etree.ElementTree import Element

from amsfe_sym.errors import UrdfError, describe

__all__ = ["check_topology"]

_TREE_FIX = "a URDF is a tree: remove or re-parent one of the joints (closed chains are not "
_TREE_FIX += "supported; lock or drop the joint that closes the loop)"


def check_topology(root: Element, path: Path) -> None:
    """Refuse a URDF whose links and joints do not form one tree.

    Args:
        root: The ``<robot>`` element, parsed strictly; every joint's parent and child name a
            link of the file (checked before).
        path: The file, for the message.

    Raises:
        UrdfError: a duplicate link or joint name, a link with two parent joints, a joint
            that is its own parent, no root link (a loop), several roots, or links not
            reachable from the root (a loop off the tree).
    """
    for tag in ("link", "joint"):
        counts = Counter(str(e.get("name")) for e in root.findall(tag))
        dup = sorted(n for n, c in counts.items() if c > 1)
        if dup:
            raise UrdfError(
                describe(
                    f"{path}: {tag} {dup[0]!r}",
                    f"unique {tag} names",
                    f"{dup[0]!r} defined {counts[dup[0]]} times",
                    f"rename or remove the duplicate <{tag}>",
                )
            )
    parent_of: dict[str, str] = {}
    joint_of: dict[str, str] = {}
    children: dict[str, list[str]] = {}
    for j in root.findall("joint"):
        name = str(j.get("name"))
        parent = str(_link(j, "parent"))
        child = str(_link(j, "child"))
        if parent == child:
            raise UrdfError(
                describe(
                    f"{path}: joint {name!r}",
                    "a parent and a child link that differ",
                    f"{child!r} as both",
                    _TREE_FIX,
                )
            )
        if child in parent_of:
            raise UrdfError(
                describe(
                    f"{path}: link {child!r}",
                    "one parent joint",
                    f"two: joints {joint_of[child]!r} and {name!r}",
                    _TREE_FIX,
                )
            )
        parent_of[child], joint_of[child] = parent, name
        children.setdefault(parent, []).append(child)
    links = [str(e.get("name")) for e in root.findall("link")]
    roots = [ln for ln in links if ln not in parent_of]
    if not roots:
        raise UrdfError(
            describe(
                f"{path}: kinematic loop",
                "one root link (a link that is no joint's child)",
                f"none: every link has a parent (a loop through {_cycle(parent_of)})",
                _TREE_FIX,
            )
        )
    if len(roots) > 1:
        raise UrdfError(
            describe(
                f"{path}: links {roots}",
                "one root link",
                f"{len(roots)} links that are no joint's child",
                "connect each to the tree with a joint, or remove the unused links",
            )
        )
    seen, todo = set(), [roots[0]]
    while todo:
        ln = todo.pop()
        seen.add(ln)
        todo.extend(children.get(ln, []))
    cut = [ln for ln in links if ln not in seen]
    if cut:
        loop = {ln: parent_of[ln] for ln in cut}
        raise UrdfError(
            describe(
                f"{path}: kinematic loop",
                f"every link reachable from the root {roots[0]!r}",
                f"a loop through {_cycle(loop)}",
                _TREE_FIX,
            )
        )


def _link(joint: Element, tag: str) -> str | None:
    el = joint.find(tag)
    return None if el is None else el.get("link")


def _cycle(parent_of: dict[str, str]) -> str:
    """One cycle of the parent map, parent before child: ``a -> b -> a`` (every node of
    ``parent_of`` has its parent in it)."""
    start = next(iter(parent_of))
    seen: list[str] = []
    ln = start
    while ln not in seen:
        seen.append(ln)
        ln = parent_of[ln]
    loop = seen[seen.index(ln) :][::-1]
    return " -> ".join([*loop, loop[0]])
