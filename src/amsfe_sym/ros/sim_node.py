"""``amsfe sim-node``: the simulated arm (:class:`amsfe_sym.ros.arm.SimArm`) as a ROS 2 node.

Each tick k it publishes ``/clock`` (t_k), the truth, the camera frames delivered at k
(stamped at their exposure, published at their arrival), then the encoder sample (stamped
t_k); it applies a command u_k over [t_k, t_k + T] and publishes it as the applied torque
(effort topic, JointState effort, stamped t_k).  Topics, joint names and QoS come from the
topic spec (ROS parameters override it).

``lockstep``: tick k waits for the k-th command received (commands carry no stamp: a node
answers each encoder sample with one command), so a run is deterministic and as fast as DDS
allows; the frames of a tick are acknowledged by every reader (reliable QoS) before its
encoder sample goes out, so a node has them when the sample arrives (DDS does not order
deliveries across topics; the writers' heartbeat period is 1 ms in lockstep,
:func:`~amsfe_sym.ros.middleware.use_lockstep_profile`, or each wait takes seconds).
Without it the plant runs on the wall clock (one tick every T) and applies the latest
command it has when a tick ends (real latency, real drops); it prints the wall clock of tick 0
(epoch [s]), so a harness knows the tick of any wall time.

A lockstep arm follows one controller: commands from a second publisher of the command topic
(another GID than the first command's) stop the run in one line naming both nodes (two
controllers interleaved gave each tick another's command); another node named
``amsfe_sim`` on the domain is warned of.  ``faults``: the arm breaks at a stated time
(:mod:`amsfe_sym.ros.faults`; the effort topic publishes the torque actually applied).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from amsfe_sym.arrays import FloatArray
from amsfe_sym.core.interrupts import DeferredSignals
from amsfe_sym.errors import RosError, describe
from amsfe_sym.ros.arm import SimArm
from amsfe_sym.ros.faults import Fault, FaultPlan
from amsfe_sym.ros.graph import duplicate_name_warning, gid_key, publisher_names
from amsfe_sym.ros.middleware import (
    check_parameters,
    executor,
    qos_profile,
    spec_parameters,
    start,
    stop,
    use_lockstep_profile,
)
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = ["SimNodeOptions", "SimNodeReport", "run_sim_node"]


@dataclass(frozen=True)
class SimNodeOptions:
    """How ``amsfe sim-node`` runs.

    Attributes:
        lockstep: Advance a tick only when its command arrived.
        spec: The topic spec (ROS parameters override it).
        start_timeout: Longest wait for a subscriber of the encoders (and, in lockstep, a
            publisher of the commands) [s, wall].
        command_timeout: Lockstep: longest wait for one tick's command (free running: for
            the first one, which starts the wall clock) [s, wall].
        rate: Free running: speed factor of the wall clock (0.25: a tick every 4 T, for a
            machine that cannot keep up with the robot's rate).
        ros_args: ``--ros-args`` for rclpy (parameters, remaps).
        domain_id: ROS_DOMAIN_ID (None: the environment's).
        images: Publish each frame as the image the true camera took
            (``/camera/image_raw``, mono8) and its ``/camera/camera_info``, at the frame's
            delivery, stamped with its exposure, instead of the pixel topic (docs/camera.md:
            ``amsfe camera-node`` turns them into it).
        faults: Faults of the arm (:mod:`amsfe_sym.ros.faults`).
    """

    lockstep: bool = False
    spec: TopicSpec = field(default_factory=TopicSpec)
    start_timeout: float = 30.0
    command_timeout: float = 5.0
    rate: float = 1.0
    ros_args: tuple[str, ...] = ()
    domain_id: int | None = None
    images: bool = False
    faults: tuple[Fault, ...] = ()


@dataclass(frozen=True)
class SimNodeReport:
    """What a sim-node run did.

    Attributes:
        ticks: Ticks simulated.
        commands: Commands received.
        wall_s: Wall time of the ticks [s].
        late_ticks: Free running: ticks that started later than one period behind the wall
            clock (the machine could not keep up).
        stale_ticks: Free running: ticks whose command was not new (none arrived during the
            tick: the previous one was applied again).
        command_latency_s: Per command: its arrival minus the publication of the encoder
            sample it answers (the i-th command answers the i-th sample: a node sends one per
            sample) [s, wall].
        estimate_latency_s: The same for the estimates (``/amsfe/estimate``) [s, wall].
    """

    ticks: int
    commands: int
    wall_s: float
    late_ticks: int
    stale_ticks: int
    command_latency_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    estimate_latency_s: FloatArray = field(default_factory=lambda: np.zeros(0))

    def latency_line(self) -> str:
        """p50 / p99 / max of both latencies [ms], one line."""
        parts = []
        both = (("estimate", self.estimate_latency_s), ("command", self.command_latency_s))
        for what, lat in both:
            if lat.size:
                p50, p99 = np.percentile(lat, [50, 99]) * 1e3
                parts.append(
                    f"encoder -> {what} p50 {p50:.3f} p99 {p99:.3f} max {lat.max() * 1e3:.3f} ms"
                )
        return "; ".join(parts) or "no latency measured"


def run_sim_node(sc: Scenario, lib: ModelLibrary, options: SimNodeOptions) -> SimNodeReport:
    """Run the arm of ``sc`` for its duration as the node ``amsfe_sim``.

    Raises:
        RosError: no subscriber within ``start_timeout``; lockstep: no command for a tick
            within ``command_timeout``; rclpy missing.
    """
    arm = SimArm(sc, lib)
    plan = FaultPlan(options.faults, lib.T, lib.n)
    # a 1 ms reliable heartbeat: lockstep, the frames' acknowledgement within ms
    # (docs/how-to/ros.md); free running, a sample the transport dropped is repaired within ms
    # instead of Fast DDS's default 3 s, by when the writer's KEEP_LAST history has replaced it
    # and the node sees it missing (docs/live-load.md)
    use_lockstep_profile()
    ctx = start(list(options.ros_args), options.domain_id)
    from amsfe_sym.ros import messages as m

    node = None
    try:
        import rclpy

        node = rclpy.create_node("amsfe_sim", context=ctx)
        spec = spec_parameters(node, options.spec, tuple(lib.manifest.joints))
        check_parameters(node)  # a mistyped -p name: refused, not ignored
        names = list(spec.joint_names or lib.manifest.joints)
        qos = qos_profile(spec)
        # free running, the writers keep 1 s of samples: when this (Python) arm falls behind
        # the wall clock it catches up in a burst, and a KEEP_LAST history shorter than the
        # burst replaced samples before the node took them (seen as missing: a false
        # "encoder stall"); a real driver does not burst
        second = math.ceil(1.0 / lib.T) + 1
        out = qos if options.lockstep else qos_profile(spec, depth=max(spec.depth, second))
        pub_enc = node.create_publisher(m.JointState, spec.encoders, out)
        pub_cam = node.create_publisher(m.PointStamped, spec.camera, out)
        pub_eff = node.create_publisher(m.JointState, spec.effort, out)
        pub_truth = node.create_publisher(m.Float64MultiArray, spec.truth, out)
        pub_clock = node.create_publisher(m.Clock, spec.clock, qos_profile(spec, depth=1))
        images = _Images(node, lib, sc.seed, qos, sc.robot) if options.images else None
        commands: list[FloatArray] = []
        n = lib.n
        controller: list[bytes] = []  # the GID of the first command's publisher
        intruders: list[bytes] = []

        def on_command(msg: m.Float64MultiArray, info: Any) -> None:
            u = m.values(msg.data)
            gid = gid_key(info.get("publisher_gid"))
            if options.lockstep and gid:
                if not controller:
                    controller.append(gid)
                elif gid != controller[0]:
                    intruders.append(gid)  # not applied: the run stops at this tick
                    return
            cmd_at.append(_received(info, len(cmd_at)))
            if u.size == n and np.all(np.isfinite(u)):
                commands.append(u)
            else:
                node.get_logger().warning(f"command of {u.size} values refused (need {n} finite)")

        sub = node.create_subscription(m.Float64MultiArray, spec.commands, on_command, qos)
        # latency by the middleware's receive stamps (system clock [ns]): not delayed by
        # this node's own executor
        cmd_at: list[tuple[int, int]] = []  # (publication sequence number, received [ns])
        est_at: list[tuple[int, int]] = []
        sent_at = np.zeros(arm.K, dtype=np.int64)
        node.create_subscription(
            m.JointState,
            spec.estimate,
            lambda _msg, info: est_at.append(_received(info, len(est_at))),
            qos,
        )
        ex = executor(ctx)
        ex.add_node(node)
        _wait_peers(ex, pub_enc, sub if options.lockstep else None, options.start_timeout)
        warned: list[str] = []
        _warn_duplicate(node, warned)
        if options.lockstep:
            _one_controller(node, spec.commands, None, warned)
        T_ns = round(lib.T * 1e9)
        u = np.zeros(n)
        late = stale = 0
        t0 = time.perf_counter()
        with DeferredSignals() as signals:  # Ctrl-C / SIGTERM raised here, not in rclpy's C++
            for k in range(arm.K):
                s = arm.sense()
                for kind in plan.started(k):
                    print(f"sim-node: fault {kind} at t = {k * lib.T:.3f} s (tick {k})", flush=True)
                ns = k * T_ns
                pub_clock.publish(m.clock(ns))
                pub_truth.publish(m.float64_array(s.x_true))
                if images is not None:
                    images.state(k, s.x_true)
                for fr in s.frames:  # the pixel topic, or (--images) what camera-node reads
                    if images is None:
                        pub_cam.publish(m.point_stamped(fr.exposure_step * T_ns, *fr.z[:2]))
                    else:
                        images.publish(fr.exposure_step, T_ns)
                shown = pub_cam if images is None else images.pub
                if options.lockstep and s.frames and not _acked(shown, options.command_timeout):
                    node.get_logger().warning(
                        f"tick {k}: a camera frame not acknowledged within "
                        f"{options.command_timeout:g} s: the node may fuse it a tick late"
                    )
                sent_at[k] = time.time_ns()
                z = plan.encoders(k, s.z)
                pub_enc.publish(m.joint_state(ns, names, z[:n], z[n:]))
                if k and k % round(1.0 / lib.T) == 0:
                    print(f"sim-node: t = {k * lib.T:.1f} s", flush=True)
                    _warn_duplicate(node, warned)
                if options.lockstep or k == 0:  # free running starts on the first command
                    deadline = time.monotonic() + options.command_timeout
                    while len(commands) <= k:
                        left = deadline - time.monotonic()
                        if left <= 0:
                            raise RosError(
                                describe(
                                    f"sim-node tick {k} (t = {k * lib.T:.3f} s)",
                                    f"its command on {spec.commands}",
                                    f"none within {options.command_timeout:g} s",
                                    "start `amsfe node SCENARIO --controller amsfe` on the same "
                                    "ROS_DOMAIN_ID, or run without --lockstep",
                                )
                            )
                        ex.spin_once(timeout_sec=min(left, 0.05))
                        signals.check()
                    if intruders:  # (one may have come with the command of tick k)
                        _one_controller(node, spec.commands, (controller[0], intruders[0]), warned)
                    u = commands[k]
                    if k == 0:
                        t0 = time.perf_counter() - lib.T / options.rate
                        if not options.lockstep:  # where the harness finds a tick's wall time
                            epoch = time.time() - (time.perf_counter() - t0)
                            print(f"sim-node: tick 0 at wall clock {epoch:.6f} s", flush=True)
                else:
                    before = len(commands)
                    end = t0 + (k + 1) * lib.T / options.rate
                    if time.perf_counter() > end:
                        late += 1
                    while (left := end - time.perf_counter()) > 0:
                        ex.spin_once(timeout_sec=left)
                        signals.check()
                    ex.spin_once(timeout_sec=0.0)
                    signals.check()
                    stale += int(len(commands) == before)
                    if commands:
                        u = commands[-1]
                applied = plan.torque(k, u)
                pub_eff.publish(m.joint_state(ns, names, effort=applied))
                if k + 1 < arm.K:
                    arm.advance(applied)
        wall = time.perf_counter() - t0
        _acked(pub_eff, 1.0)
        ex.spin_once(timeout_sec=0.05)  # the last tick's estimate

        def latency(at: list[tuple[int, int]]) -> FloatArray:
            # the i-th message published answers the i-th sample (a node sends one per
            # sample); paired by the publisher's sequence number, so a message this arm's
            # queue dropped shifts nothing
            pairs = [(seq - 1, t) for seq, t in at if 1 <= seq <= arm.K]
            if not pairs:
                return np.zeros(0)
            i, t = (np.asarray(v, dtype=np.int64) for v in zip(*pairs, strict=True))
            return np.asarray((t - sent_at[i]) * 1e-9, dtype=float)

        return SimNodeReport(
            arm.K, len(commands), wall, late, stale, latency(cmd_at), latency(est_at)
        )
    finally:
        stop(ctx, *([node] if node is not None else []))


def _received(info: Any, count: int) -> tuple[int, int]:
    """(publication sequence number, receive stamp [ns]) of a message; the sequence number
    is the count of those received so far + 1 when the middleware gives none."""
    seq = info.get("publication_sequence_number")
    return (int(seq) if seq else count + 1, int(info["received_timestamp"]))


def _warn_duplicate(node: Any, warned: list[str]) -> None:
    """Warn (once) of another node with this one's name on the graph (the graph's node
    names may come later than its endpoints: asked at the start, at t = 1 s and before a
    refusal)."""
    if not warned and (dup := duplicate_name_warning(node)) is not None:
        warned.append(dup)
        node.get_logger().warning(dup)
        print(f"sim-node: warning: {dup}", flush=True)


def _one_controller(
    node: Any, topic: str, gids: tuple[bytes, bytes] | None, warned: list[str]
) -> None:
    """Raise when a lockstep arm sees two controllers: two publishers of ``topic`` on the
    graph (``gids`` None, at the start) or commands from the two publishers ``gids``.

    Raises:
        RosError: one line naming both nodes.
    """
    names = publisher_names(node, topic)
    _warn_duplicate(node, warned)
    if gids is None:
        if len(names) <= 1:
            return
        found = " and ".join(sorted(names.values()))
    else:
        found = " and ".join(names.get(g, f"a publisher (GID {g.hex()})") for g in gids)
    raise RosError(
        describe(
            f"sim-node --lockstep commands on {topic}",
            "one controller (a lockstep arm applies the k-th command received at tick k)",
            f"commands from {found}",
            "stop all but one controller on this ROS_DOMAIN_ID (or give each arm its own "
            "topics or domain)",
        )
    )


def _acked(pub: object, timeout: float) -> bool:
    """Wait until every reader of ``pub`` (reliable) acknowledged its messages [s]."""
    from rclpy.duration import Duration

    return bool(pub.wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9))))  # type: ignore[attr-defined]


def _wait_peers(ex: object, pub: object, sub: object | None, timeout: float) -> None:
    """Wait until ``pub`` has a subscriber and ``sub`` (if any) a publisher."""
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() < 1 or (  # type: ignore[attr-defined]
        sub is not None and sub.get_publisher_count() < 1  # type: ignore[attr-defined]
    ):
        if time.monotonic() > deadline:
            raise RosError(
                describe(
                    "sim-node start",
                    f"a subscriber of {pub.topic_name}"  # type: ignore[attr-defined]
                    + ("" if sub is None else f" and a publisher of {sub.topic_name}"),  # type: ignore[attr-defined]
                    f"none within {timeout:g} s",
                    "start `amsfe node SCENARIO` on the same ROS_DOMAIN_ID",
                )
            )
        ex.spin_once(timeout_sec=0.05)  # type: ignore[attr-defined]


class _Images:
    """``sim-node --images``: the true camera's image of each frame and its CameraInfo
    (:mod:`amsfe_sym.vision.sim_images`), from the true state at the frame's exposure; the
    marker fixed to its link when the robot spec ``robot`` gives ``[tracked] orientation``."""

    def __init__(self, node: Any, lib: ModelLibrary, seed: int, qos: Any, robot: str) -> None:
        from sensor_msgs.msg import CameraInfo, Image

        from amsfe_sym.logs.sim_marker import marker_pose_of
        from amsfe_sym.vision.sim_images import INFO_TOPIC, ImageOptions, SimulatedCamera

        rng = np.random.default_rng([int(seed), 35])  # (as amsfe simulate --bag --images)
        pose = marker_pose_of(robot, lib.manifest.raw.get("locked", {}))
        self.camera = SimulatedCamera(
            lib.manifest.camera, lib.function("tracked_point"), ImageOptions(), rng, pose
        )
        self.layout = lib.layout
        self.states: dict[int, FloatArray] = {}
        self.horizon = 8 * (lib.manifest.camera.period + lib.manifest.camera.delay) + 64
        self.Image, self.CameraInfo = Image, CameraInfo
        self.pub = node.create_publisher(Image, self.camera.image_topic, qos)
        self.pub_info = node.create_publisher(CameraInfo, INFO_TOPIC, qos)

    def state(self, k: int, x: FloatArray) -> None:
        """The true state at tick k (kept for the frames exposed then)."""
        self.states[k] = np.array(x, dtype=np.float64)
        self.states.pop(k - self.horizon, None)

    def publish(self, kappa: int, T_ns: int) -> None:
        """The image exposed at tick ``kappa`` and its CameraInfo."""
        from amsfe_sym.ros import messages as m

        x = self.states.get(kappa)
        if x is None:
            return
        grey = self.camera.image(x[self.layout["q"]], x[self.layout["theta"]])
        h, w = grey.shape
        hdr = m.Header(stamp=m.ns_to_stamp(kappa * T_ns), frame_id="camera")
        msg = self.Image(header=hdr, height=h, width=w, encoding="mono8", step=w)
        msg.data = grey.tobytes()
        i = self.camera.info
        info = self.CameraInfo(
            header=hdr, width=i.width, height=i.height, distortion_model=i.model,
            d=i.D.tolist(), k=i.K.ravel().tolist(), r=i.R.ravel().tolist(),
            p=i.P.ravel().tolist(),
        )  # fmt: skip
        self.pub.publish(msg)
        self.pub_info.publish(info)
