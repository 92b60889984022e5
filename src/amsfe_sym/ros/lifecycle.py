"""``amsfe node --managed``: the node as a ROS 2 lifecycle node (docs/ros.md, "Managed node").

The transitions drive the node's own object (``ros/node.py``'s, :class:`Managed`):
``configure`` builds it (spec parameters, estimator, subscriptions), ``activate`` starts
processing samples, ``deactivate`` publishes the hold and stops processing, ``shutdown``
stops the node.  rclpy is imported only when the node is made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from amsfe_sym.errors import AmsfeError

__all__ = ["Managed", "lifecycle_node"]


class Managed(Protocol):
    """What a transition asks of the node's object."""

    def activate(self) -> None: ...

    def deactivate(self) -> None: ...

    def shut_down(self) -> None: ...


M = TypeVar("M", bound=Managed)


def lifecycle_node(ctx: Any, build: Callable[[Any], M], holder: list[M], down: list[bool]) -> Any:
    """The lifecycle node ``amsfe_node``: ``configure`` appends ``build(node)`` to ``holder``
    (a refused configuration fails the transition, its reason in the node's log), the other
    transitions call the object's methods; ``shutdown`` appends to ``down``."""
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

    ok, failed = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE

    class Node(LifecycleNode):
        def on_configure(self, state: Any) -> Any:
            if holder:
                return ok
            try:
                holder.append(build(self))
            except AmsfeError as exc:
                self.get_logger().error(str(exc))
                return failed
            return ok

        def on_activate(self, state: Any) -> Any:
            holder[-1].activate()
            return ok

        def on_deactivate(self, state: Any) -> Any:
            holder[-1].deactivate()
            return ok

        def on_cleanup(self, state: Any) -> Any:
            return ok

        def on_shutdown(self, state: Any) -> Any:
            down.append(True)
            if holder:
                holder[-1].shut_down()
            return ok

    return Node("amsfe_node", context=ctx)
