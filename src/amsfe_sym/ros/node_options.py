"""How ``amsfe node`` runs: its options (:func:`amsfe_sym.ros.node.run_node`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from amsfe_sym.ros.outputs import DEFAULT_STD_EVERY
from amsfe_sym.ros.tick import HoldKind
from amsfe_sym.topics import TopicSpec

__all__ = ["NodeOptions"]


@dataclass(frozen=True)
class NodeOptions:
    """How ``amsfe node`` runs.

    Attributes:
        controller: Run the scenario's controller and publish commands.
        compiled: The library's C estimator (else the Python reference).
        spec: The topic spec (ROS parameters override it).
        encoder_timeout: Encoder silence that triggers the hold [s, wall]; None: the spec's.
        hold: The hold command's kind.
        duration: Stop after this much of the samples' time [s] (None: run until stopped).
        record: Write a rosbag2 (MCAP) of the session here (None: none).
        ros_args: ``--ros-args`` for rclpy.
        domain_id: ROS_DOMAIN_ID (None: the environment's).
        subscriber_wait: Longest wait for a subscriber of the commands before the first
            command [s] (a command published before a subscriber matched is lost).
        managed: A lifecycle node: it reads the spec and builds the estimator on
            ``configure``, processes samples only while ``active``, holds on ``deactivate``
            and stops on ``shutdown`` (docs/how-to/ros.md, "Managed node").
        std_every: Publish ``estimate_std`` and ``theta`` at every ``std_every``-th tick
            (tick 0, k % std_every == 0, the last tick of ``duration``, and the last
            estimate when the node stops); the estimate and the command go out at every
            tick, and a record has all three at every tick (ROS parameter
            ``publish.std_every`` overrides it; 1: every tick).
    """

    controller: bool = False
    compiled: bool = True
    spec: TopicSpec = field(default_factory=TopicSpec)
    encoder_timeout: float | None = None
    hold: HoldKind = "gravity"
    duration: float | None = None
    record: Path | None = None
    ros_args: tuple[str, ...] = ()
    domain_id: int | None = None
    subscriber_wait: float = 5.0
    managed: bool = False
    std_every: int = DEFAULT_STD_EVERY
