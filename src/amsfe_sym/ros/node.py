"""``amsfe node``: the generated estimator (and controller) of a scenario as the ROS 2 node
``amsfe_node`` (docs/how-to/ros.md).

It subscribes the encoders, the camera, the effort (its kind: :mod:`amsfe_sym.ros.effort`)
and, when it records, the truth of a simulated arm, on the topics of the topic spec (ROS
parameters override it; its ``[filter]``: :mod:`amsfe_sym.ros.spec_filter`); each encoder
sample goes through :class:`amsfe_sym.ros.live.LiveLoop` by its header stamp (after the
torque applied over the previous tick, waited for as the C node does:
:mod:`amsfe_sym.ros.torque_wait`); the node
publishes the estimate (JointState q, qd), its standard deviations, theta, the command (with
a controller; Float64MultiArray) and diagnostics (JSON: frames fused, refused, skipped, NIS).

Fail-safe (docs/how-to/ros.md, "Hold"): when a watchdog trips (docs/watchdogs.md; the spec's
``[watchdog]``) it publishes the hold command (:data:`~amsfe_sym.ros.tick.HoldKind`), says
why in one line (``hold: <reason>: ...``) and returns :data:`EXIT_HOLD`; on Ctrl-C or
SIGTERM it publishes the hold command and the interrupt goes on (the command line exits 130 /
143); at the end of ``duration`` it publishes the hold command and returns 0.  A record
(``--record``) is written on every one of these exits, saying why (``/amsfe/config`` ``stop``).
"""

from __future__ import annotations

import contextlib
import gc
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.interrupts import DeferredSignals
from amsfe_sym.errors import AmsfeError
from amsfe_sym.ros.effort import effort_values, live_effort
from amsfe_sym.ros.lifecycle import lifecycle_node
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.ros.middleware import (
    check_parameters,
    depth_for,
    executor,
    lean_events,
    qos_profile,
    spec_parameters,
    start,
    stop,
    waiting_line,
)
from amsfe_sym.ros.node_options import NodeOptions
from amsfe_sym.ros.node_stop import EXIT_HOLD, NodeReport, Stop, held_line, latency_line
from amsfe_sym.ros.outputs import (
    StdPublisher,
    std_due,
    std_every_parameter,
)
from amsfe_sym.ros.record import NodeRecord
from amsfe_sym.ros.spec_filter import live_filter
from amsfe_sym.ros.tick import TickOut
from amsfe_sym.ros.torque_wait import SubscriptionWait, TorqueWait
from amsfe_sym.ros.watchdog_reasons import Reason
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import joint_order

__all__ = ["EXIT_HOLD", "NodeOptions", "NodeReport", "run_node"]

FloatArray = NDArray[np.float64]

#: A node that has received no encoder sample says, every this many seconds [s, wall], which
#: topic it waits on and what the graph shows for it (:func:`~amsfe_sym.ros.middleware.
#: waiting_line`): it waited forever without a word.
WAITING_SAY_S = 10.0
ENCODER_TYPE = "sensor_msgs/msg/JointState"


class _Node:
    """The rclpy side: subscriptions feed the :class:`LiveLoop`, each tick publishes."""

    def __init__(
        self, ctx: Any, sc: Scenario, lib: ModelLibrary, options: NodeOptions, node: Any
    ) -> None:
        from amsfe_sym.ros import messages as m

        self.m, self.node, self.lib, self.options = m, node, lib, options
        self.spec = spec = spec_parameters(node, options.spec, tuple(lib.manifest.joints))
        sc = live_filter(sc, spec)  # the spec's [filter] over the scenario's, as on a log
        self.names = tuple(spec.joint_names or lib.manifest.joints)
        self.effort_kind = spec.effort_kind or "applied"
        self.live = LiveLoop(
            sc,
            lib,
            controller=options.controller,
            compiled=options.compiled,
            grid_tolerance=spec.grid_tolerance,
            max_gap_steps=spec.max_gap_steps,
            effort=live_effort(spec),
            watchdog=spec.watchdog.with_timeout(options.encoder_timeout),
            exposure_shift=spec.exposure_shift(lib.T),
        )
        self.n = lib.n
        self.std_every = std_every_parameter(node, options.std_every)
        check_parameters(node)  # every parameter declared: a mistyped -p name is refused
        self.record = (  # the folder claimed now: a second writer is refused before it starts
            None
            if options.record is None
            else NodeRecord(sc, lib, spec, self.names, out=options.record)
        )
        self.last: TickOut | None = None
        self.last_rx: float | None = None
        self.stop: Stop | None = None
        self.end_k = None if options.duration is None else round(options.duration / lib.T)
        self._orders: dict[tuple[str, ...], list[int]] = {}
        self._first_command = True
        #: Per command: its publication minus the middleware's receipt of the sample it
        #: answers (system clock [ns]): the node's own latency (docs/live-load.md).
        self.latency_ns: list[int] = []
        self._rx_ns = 0
        self._rx_frames: list[tuple[int, FloatArray, int]] = []
        # one message object a topic, filled in each tick (publish serializes at once)
        self._msg_est = m.joint_state(0, self.names)
        self._msg_cmd = m.Float64MultiArray()
        #: Samples are processed only while active (a managed node: between activate and
        #: deactivate; an unmanaged one: always).
        self.active = not options.managed
        qos = qos_profile(spec)
        # the subscriptions hold 5 s at the encoders' rate, as play's publishers do
        # (middleware.depth_for: one rule for both ends; a slow moment loses no sample)
        sub_qos = qos_profile(spec, depth=depth_for(1.0 / lib.T, spec))
        sub_events, pub_events = lean_events(node)
        # the camera is subscribed first: a frame and a sample ready at once, the frame first
        node.create_subscription(
            m.PointStamped, spec.camera, self.on_frame, sub_qos, event_callbacks=sub_events
        )
        if self.record is not None:  # the truth only goes into a record (for its NEES)
            node.create_subscription(
                m.Float64MultiArray, spec.truth, self.on_truth, sub_qos, event_callbacks=sub_events
            )
        read = self.effort_kind != "none"
        #: The wait for the torque applied over the previous tick (ros/torque_wait.py).
        self.torque_wait = TorqueWait(lib.T, options.controller)
        self._effort_wait: SubscriptionWait | None = None
        if read and spec.effort != spec.encoders:
            sub_eff = node.create_subscription(
                m.JointState, spec.effort, self.on_effort, sub_qos, event_callbacks=sub_events
            )
            if self.effort_kind == "applied":  # the C node's await_effort
                self._effort_wait = SubscriptionWait(
                    ctx, sub_eff, lambda msg, _: self.on_effort(msg)
                )
        self.effort_in_encoders = read and spec.effort == spec.encoders
        node.create_subscription(
            m.JointState, spec.encoders, self.on_encoders, sub_qos, event_callbacks=sub_events
        )
        ev = {"event_callbacks": pub_events}
        self.pub_est = node.create_publisher(m.JointState, spec.estimate, qos, **ev)
        self.std = StdPublisher(
            m,
            node.create_publisher(m.JointState, spec.estimate_std, qos, **ev),
            node.create_publisher(m.Float64MultiArray, spec.theta, qos, **ev),
            self.names,
            self.n,
            lib.layout["theta"],
        )
        self.pub_diag = node.create_publisher(m.String, spec.diagnostics, qos, **ev)
        self.pub_cmd = (
            node.create_publisher(m.Float64MultiArray, spec.commands, qos, **ev)
            if options.controller
            else None
        )

    # ---------------------------------------------------------------- callbacks
    def _order(self, names: Any) -> list[int] | None:
        """The robot's joints' indices in ``names`` (None: one is missing; the node stops)."""
        key = tuple(names)
        if key not in self._orders:
            where = f"{self.spec.encoders} JointState names"
            try:
                self._orders[key] = joint_order(key, self.names, where)
            except AmsfeError as exc:  # the robot's joints are not all in the message
                self.stop = Stop(str(exc), 2, exc)
                return None
        return self._orders[key]

    def on_frame(self, msg: Any, info: Any) -> None:
        if not self.active:
            return
        ns = self.m.stamp_ns(msg.header.stamp)
        pixel = np.array([msg.point.x, msg.point.y])
        sent = int(info["source_timestamp"])
        self.live.frame(ns, pixel, sent)
        if self.record is not None:  # before the first sample too: see LiveLoop.frame
            self._rx_frames.append((ns, pixel, sent))

    def on_truth(self, msg: Any, info: Any) -> None:
        if self.record is not None:  # matched to its tick by its source timestamp
            self.record.truth_sent(int(info["source_timestamp"]), self.m.values(msg.data))

    def on_effort(self, msg: Any) -> None:
        if self.stop is not None or not self.active:
            return
        if (idx := self._order(msg.name)) is None:
            return
        ns = self.m.stamp_ns(msg.header.stamp)
        self.torque_wait.received(self.live.tick_of(ns))
        self._effort(ns, effort_values(self.m, msg, idx, self.n))

    def _effort(self, ns: int, eff: FloatArray) -> None:
        """An effort sample [as logged] to the loop by its kind, and to the record."""
        self.live.effort(ns, eff)
        if self.record is not None:
            self.record.applied(ns, eff)

    def on_encoders(self, msg: Any, info: Any) -> None:
        if self.stop is not None or not self.active:
            return
        if self._first_command and self.pub_cmd is not None:
            self._wait_subscriber()  # before the watchdog's clock starts
        taken = time.monotonic()
        self._rx_ns = int(info["received_timestamp"])
        if (idx := self._order(msg.name)) is None:
            return
        try:
            pos, vel = self.m.values(msg.position), self.m.values(msg.velocity)
            if pos.size != len(msg.name) or vel.size != len(msg.name):
                z = np.full(2 * self.n, np.nan)
            else:
                z = np.concatenate([pos[idx], vel[idx]])
            ns = self.m.stamp_ns(msg.header.stamp)
            if self.effort_in_encoders and self.effort_kind == "joint_torque":
                self._effort(ns, effort_values(self.m, msg, idx, self.n))  # of this sample
            if self._effort_wait is not None and self._await_torque(ns):
                taken = time.monotonic()  # a wait is not the tick's compute time (the C node)
            if self.stop is not None:  # a torque taken meanwhile stopped the node (bad input)
                return
            watched = self.live.watch(
                ns, z, int(info["source_timestamp"]), taken=taken, clock=time.monotonic
            )
        except AmsfeError as exc:
            self.stop = Stop(f"hold: the estimator stopped: {exc}", EXIT_HOLD)
            return
        if self._held(watched.reason):
            return
        out = watched.out
        if out is None:
            return
        applied = self.effort_in_encoders and self.effort_kind == "applied"
        if applied and len(msg.effort) > 0:  # the torque over the next tick
            self._effort(ns, effort_values(self.m, msg, idx, self.n))
        self._publish(out, z, int(info["source_timestamp"]))
        self.last_rx = time.monotonic()  # after the work: a slow first tick is no silence

    def _await_torque(self, ns: int) -> bool:
        """Take the torques already received, then wait for the one applied over the tick
        before the sample stamped ``ns`` when it is due (:class:`TorqueWait`): True when it
        waited."""
        waiter = self._effort_wait
        assert waiter is not None
        waiter.take()
        k = self.live.tick_of(ns)
        if k is None or not self.torque_wait.due(k, self.live.k, lambda: waiter.publishers() > 0):
            return False
        self.torque_wait.wait(k, waiter.block, stopped=lambda: self.stop is not None)
        return True

    # ---------------------------------------------------------------- outputs
    def _held(self, reason: Reason) -> bool:
        """Stop on the watchdog's hold, if any (its line, :data:`EXIT_HOLD`)."""
        hold = self.live.watchdog.hold
        if reason != Reason.NONE and hold is not None:
            self.stop = Stop(hold.line(), EXIT_HOLD, watchdog=hold.name)
        return self.stop is not None

    def idle(self) -> None:
        """The watchdog's idle call (the encoders' publishers counted only when silent)."""
        count = self.node.count_publishers
        self._held(
            self.live.watchdog.idle_counting(time.monotonic(), lambda: count(self.spec.encoders))
        )

    def _publish(self, out: TickOut, z: FloatArray, sent: int) -> None:
        m, n, ns = self.m, self.n, out.stamp_ns
        self.last = out
        if out.u is not None and self.pub_cmd is not None:  # first: the arm waits for it
            self._msg_cmd.data = m.doubles(out.u)
            self.pub_cmd.publish(self._msg_cmd)
            self.latency_ns.append(time.time_ns() - self._rx_ns)
        x = out.x_hat
        est = self._msg_est
        est.header.stamp.sec, est.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        est.position, est.velocity = m.doubles(x[:n]), m.doubles(x[n : 2 * n])
        self.pub_est.publish(est)
        if std_due(out.k, self.std_every, self.end_k):
            self.std.publish(out)
        rep = out.report
        if out.k == 0 or (rep is not None and (rep.frames_applied or rep.frames_rejected)):
            text = json.dumps(self.diagnostics(out))
            self.pub_diag.publish(m.String(data=text))
            if self.record is not None:
                self.record.diagnostics(ns, text)
        if self.record is not None:
            self._record(out, z, sent)
        if self.end_k is not None and out.k >= self.end_k:
            self.stop = Stop(f"done: {out.k + 1} ticks ({out.t:.3f} s of samples)", 0)

    def _record(self, out: TickOut, z: FloatArray, sent: int) -> None:
        rec = self.record
        assert rec is not None
        ns = out.stamp_ns
        rec.encoders(ns, z, sent)
        keep = []
        if out.k == 0:  # sent before the first sample: skipped by the loop, not recorded
            self._rx_frames = [f for f in self._rx_frames if f[2] > sent]
        for exposure_ns, pixel, frame_sent in self._rx_frames:  # logged at their arrival
            if frame_sent <= sent:
                rec.frame(ns, exposure_ns, pixel)
            else:
                keep.append((exposure_ns, pixel, frame_sent))
        self._rx_frames = keep
        L = self.lib.layout
        std = np.sqrt(np.maximum(out.P_diag, 0.0))
        rec.outputs(ns, out.x_hat, std, out.x_hat[L["theta"]], out.u)
        if out.u is not None and self.effort_kind == "none":  # its command is the applied one
            rec.applied(ns, out.u)

    def _wait_subscriber(self) -> None:
        assert self.pub_cmd is not None
        self._first_command = False
        deadline = time.monotonic() + self.options.subscriber_wait
        while self.pub_cmd.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        if self.pub_cmd.get_subscription_count() < 1:
            self.node.get_logger().warning(
                f"no subscriber on {self.spec.commands} after "
                f"{self.options.subscriber_wait:g} s: commands go nowhere"
            )

    def diagnostics(self, out: TickOut | None) -> dict[str, Any]:
        """The diagnostics JSON: tick, frames fused, refused and skipped by reason, NIS."""
        c = self.live.counters
        d: dict[str, Any] = {
            "k": None if out is None else out.k,
            "t": None if out is None else out.t,
            "frames_fused": c.get("frames_applied", 0),
            "frames_refused": c.get("frames_rejected", 0),
            "refused": {k: v for k, v in c.items() if k.startswith("refused_") and v},
            "skipped": dict(self.live.skipped),
        }
        if out is not None and out.report is not None:
            d["frame_nis"] = list(out.report.frame_nis)
            d["encoder_nis"] = out.report.encoder_nis
        return d

    def activate(self) -> None:
        """Lifecycle ``activate``: process samples (the watchdog's clock from the next)."""
        self.live.watchdog.reset()
        self.active = True

    def deactivate(self) -> None:
        """Lifecycle ``deactivate``: publish the hold and stop processing."""
        self.active, self.last_rx = False, None
        self.hold()

    def shut_down(self) -> None:
        """Lifecycle ``shutdown``: stop the node."""
        self.active = False
        self.stop = Stop("shut down by its lifecycle manager", 0)

    def hold(self) -> FloatArray | None:
        """Publish the last estimate's ``estimate_std`` and ``theta`` if they are not out
        yet, then the hold command (with a controller): returns it."""
        if self.last is not None and self.std.k != self.last.k:
            with contextlib.suppress(Exception):  # a context already down cannot publish
                self.std.publish(self.last)
        if self.pub_cmd is None:
            return None
        u = self.live.hold_command(self.options.hold, self.last)
        if self.record is not None:
            self.record.hold(self.last.stamp_ns if self.last is not None else 0, u)
        try:
            self.pub_cmd.publish(self.m.float64_array(u))
            from rclpy.duration import Duration

            self.pub_cmd.wait_for_all_acked(Duration(seconds=0.5))
        except Exception:  # a context already down cannot publish
            return None
        return u


def run_node(
    sc: Scenario, lib: ModelLibrary, options: NodeOptions, say: Callable[[str], None] = print
) -> NodeReport:
    """Run the node until a stop (module docstring); the record is written on every exit.
    ``say`` gets the one line of why it stopped and the hold command, as soon as the hold
    command is out (before the record is written).

    Raises:
        KeyboardInterrupt: Ctrl-C or SIGTERM (after the hold and the record).
        RosError: rclpy missing or failing to start.
        ConfigError: bad parameters, a joint missing from the encoders' names.
    """
    ctx = start(list(options.ros_args), options.domain_id)
    import rclpy

    holder: list[_Node] = []
    down: list[bool] = []  # a managed node's shutdown transition happened
    if options.managed:
        node = lifecycle_node(ctx, lambda n: _Node(ctx, sc, lib, options, n), holder, down)
    else:
        node = rclpy.create_node("amsfe_node", context=ctx)
    state: _Node | None = None
    hold: FloatArray | None = None
    reason, code = "shutdown", 0
    try:
        if not options.managed:
            holder.append(_Node(ctx, sc, lib, options, node))
        ex = executor(ctx)
        ex.add_node(node)
        gc.collect()
        gc.freeze()  # the startup's objects (rclpy, numpy, the library): never rescanned
        quiet_since, said = time.monotonic(), 0.0  # nothing received yet: said every 10 s
        with DeferredSignals() as signals:  # raised between spins, not inside rclpy's C++
            while ctx.ok() and not down and (not holder or holder[-1].stop is None):
                ex.spin_once(timeout_sec=0.05)
                signals.check()
                state = holder[-1] if holder else None
                last = None if state is None or not state.active else state.last_rx
                silent = time.monotonic() - quiet_since
                if state and state.active and last is None and silent > said + WAITING_SAY_S:
                    said = silent - silent % WAITING_SAY_S
                    say(waiting_line(node, state.spec.encoders, ENCODER_TYPE, round(silent)))
                if state is not None and state.active and state.stop is None:
                    state.idle()  # the watchdog: silence, the node stalled
        state = holder[-1] if holder else None
        if state is not None and state.record is not None and state.stop is not None:
            _await_last_truth(ex, state.record)
        if state is None:  # a managed node shut down before it was configured
            say("node: shut down before it was configured")
            return NodeReport(0, "shutdown", 0, None, {}, None)
        if state.stop is not None:
            reason, code = state.stop.reason, state.stop.code
        if state.record is not None:
            state.record.stopped(reason, code, None if state.stop is None else state.stop.watchdog)
        hold = state.hold()
        bad_input = state.stop is not None and state.stop.error is not None
        say(
            "node: stopped on bad input" + held_line(hold)
            if bad_input
            else f"node: {reason}" + held_line(hold)
        )
    except KeyboardInterrupt:
        reason = "hold: interrupted (SIGINT or SIGTERM)"
        state = holder[-1] if holder else None
        if state is not None:
            if state.record is not None:
                state.record.stopped("hold: interrupted", None, None)
            hold = state.hold()
            say("node: hold: interrupted" + held_line(hold))
        raise
    finally:
        if state is not None and state.record is not None and options.record is not None:
            try:
                state.record.write(options.record, reason=reason)
            finally:
                stop(ctx, node)
        else:
            stop(ctx, node)
    if state.stop is not None and state.stop.error is not None:
        raise state.stop.error
    if state.latency_ns:
        say(latency_line(np.asarray(state.latency_ns, dtype=float) * 1e-9))
    if (waited := state.torque_wait.line()) is not None:  # the C node's line
        say(waited)
    counters = {**state.live.counters, **state.live.skipped}
    return NodeReport(state.live.k + 1, reason, code, hold, counters, options.record)


#: Longest wait at the stop for the truth of the last recorded ticks [s, wall].
TRUTH_WAIT_S = 1.0


def _await_last_truth(ex: Any, record: NodeRecord) -> None:
    """Spin until the truth of every recorded tick has come, at most :data:`TRUTH_WAIT_S`:
    the arm sends a tick's truth before its encoder sample, but DDS orders no deliveries
    across topics, so the last tick's can arrive after the node stopped on that sample (the
    record would then miss it; the C node takes what came once more before it writes its
    record).  A truth that never comes leaves its tick without one, counted in the record's
    metadata."""
    end = time.monotonic() + TRUTH_WAIT_S
    while record.awaiting_truth and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)
