"""What the ROS graph says about a node's peers: who publishes a topic (by name and GID) and
whether another node carries the same name (two controllers on one
lockstep arm, two nodes of one name)."""

from __future__ import annotations

from typing import Any

__all__ = ["duplicate_name_warning", "gid_key", "publisher_names"]


def gid_key(gid: Any) -> bytes:
    """A publisher's GID as bytes, from a message info's ``publisher_gid`` (a dict with
    ``data``) or a graph entry's ``endpoint_gid`` (a list of ints); b"" when unknown."""
    if gid is None:
        return b""
    if isinstance(gid, dict):
        gid = gid.get("data", b"")
    return bytes(gid)


def publisher_names(node: Any, topic: str) -> dict[bytes, str]:
    """The publishers of ``topic`` the graph shows: GID -> fully qualified node name."""
    out = {}
    for info in node.get_publishers_info_by_topic(topic):
        ns = info.node_namespace.rstrip("/")
        out[gid_key(info.endpoint_gid)] = f"{ns}/{info.node_name}"
    return out


def duplicate_name_warning(node: Any) -> str | None:
    """One line when another node on the graph has ``node``'s name and namespace (ROS 2
    does not refuse it: parameters, services and logs then mix), else None."""
    me = (node.get_name(), node.get_namespace())
    same = sum(1 for name_ns in node.get_node_names_and_namespaces() if tuple(name_ns) == me)
    if same <= 1:
        return None
    full = node.get_fully_qualified_name()
    return (
        f"{same} nodes named {full} on this ROS_DOMAIN_ID: their parameters, services and "
        f"logs mix; stop the other one or rename this one (--ros-args -r __node:=NAME)"
    )
