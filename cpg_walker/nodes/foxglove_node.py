"""foxglove_node: a live view of the walking robot in Foxglove (``ros2 run cpg_walker foxglove_node``;
``--foxglove`` on ``cpg-walker graph``, ``walk`` and ``demo`` starts it).

It runs a foxglove-sdk WebSocket server (bound to 127.0.0.1 unless ``host`` says otherwise) and shows the
graph's topics on it (channels and encodings: foxglove_view.py), at most ``display_rate`` times per wall
second and only while a client is subscribed to a channel. It only listens, best effort (a reader that
falls behind drops; it never makes a publisher resend or wait), and spends no Python per message: the
shown topics (depth 1) are on a hidden node that no executor spins, taken raw at a display tick and
decoded only for a subscribed channel; the sole loads (every sample: touchdowns) are drained each tick and
read from their CDR. Its own process, wall time (sim time would subscribe /clock), nice 10
(config/foxglove.yaml). Foxglove's parameter panel gets and sets the forwarded parameters of the other
nodes through their parameter services (foxglove_params.py).
"""

from __future__ import annotations

import math
import struct
import time

import foxglove
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from foxglove.channels import FrameTransformsChannel, JointStatesChannel
from foxglove.messages import (
    FrameTransform,
    FrameTransforms,
    JointState,
    JointStates,
    Quaternion,
    Timestamp,
    Vector3,
)
from foxglove.websocket import Capability
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterEvent
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState as RosJointState
from std_msgs.msg import Float64MultiArray

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes import specs
from cpg_walker.nodes.foxglove_params import ParameterForwarder
from cpg_walker.nodes.foxglove_view import (
    CONTACT_SCHEMA,
    CPG_STATE_SCHEMA,
    DIAGNOSTICS_SCHEMA,
    READY,
    STRING_SCHEMA,
    TEACH_STATE_SCHEMA,
    TOUCHDOWN_SCHEMA,
    Contacts,
    Poser,
    cpg_layout,
    cpg_state,
    diagnostics,
    is_loopback,
    stamp_dict,
    teach_state,
    wrench_load,
)
from cpg_walker.nodes.messages import stamp_ns
from cpg_walker.nodes.params import declare_params
from cpg_walker.nodes.runtime import (
    HotPath,
    Throttle,
    exit_stats,
    parse_cli,
    run_main,
    scheduling_request,
)
from cpg_walker.robot.urdf import read_urdf

#: The shown topics: only the newest message is kept (by the middleware) until the next display.
NEWEST = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
#: The sole loads: every sample (touchdowns), taken at least every LOADS_PERIOD_S (depth: 128 ms at
#: 500 Hz).
LOADS = QoSProfile(depth=64, reliability=ReliabilityPolicy.BEST_EFFORT)
LOADS_PERIOD_S = 0.05


class FoxgloveNode(Node):
    """The bridge: ROS subscriptions in, Foxglove channels out; ``display()`` shows the newest state."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.FOXGLOVE_NODE], **node_options)
        if self.get_parameter("use_sim_time").value:
            # its times are the messages' stamps; sim time would subscribe /clock: a callback per tick
            from rclpy.parameter import Parameter

            self.set_parameters([Parameter("use_sim_time", value=False)])
        v = declare_params(self, specs.FOXGLOVE)
        host, port = str(v["host"]), int(v["port"])
        self.display_period = 1.0 / float(v["display_rate"])
        timeout = float(v["service_timeout"])
        targets = list(v["parameters"] or [])
        self.scheduling = scheduling_request(v)
        if not host:
            raise ValueError("host must not be empty (127.0.0.1: this machine only)")

        self.ctx = foxglove.Context()
        self.urdf = read_urdf()
        self.ch_tf = FrameTransformsChannel(ifc.TF, context=self.ctx)
        self.ch_js = JointStatesChannel(ifc.JOINT_STATES, context=self.ctx)
        self.ch_jt = JointStatesChannel(ifc.JOINT_TARGETS, context=self.ctx)
        self.ch_cpg = foxglove.Channel(ifc.CPG_STATE, schema=CPG_STATE_SCHEMA, context=self.ctx)
        self.ch_contact = foxglove.Channel(ifc.CONTACT, schema=CONTACT_SCHEMA, context=self.ctx)
        self.ch_touchdown = foxglove.Channel(ifc.CONTACT_TOUCHDOWN, schema=TOUCHDOWN_SCHEMA, context=self.ctx)
        self.ch_diag = foxglove.Channel(ifc.DIAGNOSTICS, schema=DIAGNOSTICS_SCHEMA, context=self.ctx)
        self.ch_teach = foxglove.Channel(ifc.CPG_TEACH_STATE, schema=TEACH_STATE_SCHEMA, context=self.ctx)
        self.ch_desc = foxglove.Channel(ifc.ROBOT_DESCRIPTION, schema=STRING_SCHEMA, context=self.ctx)
        self.send_description = False

        def subscribed(topic: str) -> None:  # an sdk thread: only a flag, the main loop sends it
            if topic == ifc.ROBOT_DESCRIPTION:
                self.send_description = True

        self.params = ParameterForwarder(self, targets, {ifc.ROBOT_DESCRIPTION: self.urdf}, timeout,
                                         subscribed)
        try:
            self.server = foxglove.start_server(
                name="cpg_walker", host=host, port=port, context=self.ctx, server_listener=self.params,
                capabilities=[Capability.Parameters, Capability.Time])
        except Exception as exc:  # the sdk raises its own error types for a bind failure
            raise ValueError(f"cannot start the Foxglove server on {host}:{port}: {exc}") from None
        self.params.server = self.server

        self.latest: dict[str, bytes] = {}
        self.shown: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.contacts = Contacts()
        self.poser = Poser()
        self.warn = Throttle(5.0)
        # the high-rate topics on a hidden node that no executor spins: their messages are taken (raw, no
        # deserialization) only when due, by the HotPaths below, never one Python callback per message
        self.taker = rclpy.create_node("_foxglove_taker", context=self.context,
                                       start_parameter_services=False)
        self.newest = HotPath(self.taker, [
            self.taker.create_subscription(cls, t, lambda b, t=t: self._keep(t, b), NEWEST, raw=True)
            for cls, t in ((RosJointState, ifc.JOINT_STATES), (RosJointState, ifc.JOINT_TARGETS),
                           (Odometry, ifc.ODOM_GROUND_TRUTH))])
        self.loads = HotPath(self.taker, [
            self.taker.create_subscription(WrenchStamped, ifc.foot_load_topic(s),
                                           lambda b, s=s: self._load(s, b), LOADS, raw=True)
            for s in ifc.FOOT_LOAD_SIDES])
        self.create_subscription(Float64MultiArray, ifc.CPG_STATE, self._cpg_state, 10)
        self.create_subscription(DiagnosticArray, ifc.DIAGNOSTICS, self._diagnostics, 50)
        self.create_subscription(Float64MultiArray, ifc.CPG_TEACH_STATE, self._teach_state, 10)
        self.create_subscription(ParameterEvent, ifc.PARAMETER_EVENTS, self._parameter_event, 50)
        self.last_cpg = 0.0
        where = ("bound to localhost only (--foxglove HOST:PORT for another interface)" if is_loopback(host)
                 else f"listening on {host}: reachable from other machines")
        self.get_logger().info(f"{READY} ws://{'127.0.0.1' if host in ('0.0.0.0', '::') else host}:"
                               f"{self.server.port} in Foxglove (Open connection -> Foxglove WebSocket); "
                               f"{where}; forwarding parameters {', '.join(self.params.targets) or 'none'}")

    # ------------------------------------------------------------------ ROS side (main thread)
    def _keep(self, topic: str, data: bytes) -> None:
        self.latest[topic] = data
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _load(self, side: str, data: bytes) -> None:
        self.counts[side] = self.counts.get(side, 0) + 1
        try:
            t_ns, load = wrench_load(data)
        except (ValueError, struct.error) as exc:  # a malformed message: dropped
            self._warn(ifc.foot_load_topic(side), exc)
            return
        self.contacts.add(side, t_ns, load if math.isfinite(load) else 0.0)

    def _warn(self, what: str, exc: Exception) -> None:
        self.warn.warn(self, what, f"dropped a malformed {what} message: {exc}")

    def _cpg_state(self, msg: Float64MultiArray) -> None:
        now = time.monotonic()
        if not self.ch_cpg.has_sinks() or now - self.last_cpg < self.display_period:
            return
        self.last_cpg = now
        try:
            names, n_osc = cpg_layout(msg.layout.dim)
            t_ns = self.newest_stamp_ns()
            self.ch_cpg.log(cpg_state(names, n_osc, msg.data, t_ns), log_time=t_ns)
        except (ValueError, TypeError) as exc:
            self._warn(ifc.CPG_STATE, exc)

    def _teach_state(self, msg: Float64MultiArray) -> None:
        if self.ch_teach.has_sinks():
            try:
                t_ns = self.newest_stamp_ns()
                self.ch_teach.log(teach_state(msg.layout.dim, msg.data, t_ns), log_time=t_ns)
            except (ValueError, TypeError) as exc:
                self._warn(ifc.CPG_TEACH_STATE, exc)

    def _diagnostics(self, msg: DiagnosticArray) -> None:
        if self.ch_diag.has_sinks():
            t_ns = stamp_ns(msg)
            self.ch_diag.log(diagnostics(msg.status, t_ns), log_time=t_ns)

    def _parameter_event(self, msg: ParameterEvent) -> None:
        changed = self.params.changed(msg.node.lstrip("/"), [*msg.new_parameters, *msg.changed_parameters])
        if changed:
            self.server.publish_parameter_values(changed)

    def newest_stamp_ns(self) -> int:
        return max(self.shown.get(ifc.JOINT_STATES, 0), self.contacts.t_ns, 0)

    # ------------------------------------------------------------------ what the clients see
    def _joint_states(self, topic: str, channel, needed: bool = False) -> RosJointState | None:
        """The newest message of ``topic``, shown on ``channel`` if a client subscribes to it (and decoded
        only then, or when ``needed``)."""
        data = self.latest.pop(topic, None)
        if data is None or not (needed or channel.has_sinks()):
            return None
        try:
            msg = deserialize_message(data, RosJointState)
        except Exception as exc:
            self._warn(topic, exc)
            return None
        t_ns = stamp_ns(msg)
        self.shown[topic] = t_ns
        if channel.has_sinks():
            n = len(msg.name)
            pos, vel, eff = list(msg.position), list(msg.velocity), list(msg.effort)
            joints = [JointState(name=msg.name[i], position=pos[i] if i < len(pos) else None,
                                 velocity=vel[i] if i < len(vel) else None,
                                 effort=eff[i] if i < len(eff) else None) for i in range(n)]
            channel.log(JointStates(timestamp=Timestamp(**stamp_dict(t_ns)), joints=joints), log_time=t_ns)
        return msg

    def display(self) -> None:
        """Show the newest joint states, targets, link transforms and contact state (each at most once per
        display period, and only while a client subscribes to it: nothing is taken or decoded otherwise)."""
        robot = any(c.has_sinks() for c in (self.ch_tf, self.ch_js, self.ch_jt))
        t_ns = self._show_robot() if robot else None
        if self.contacts.t_ns > self.shown.get(ifc.CONTACT, -1) and self.ch_contact.has_sinks():
            self.shown[ifc.CONTACT] = self.contacts.t_ns
            self.ch_contact.log(self.contacts.state(), log_time=self.contacts.t_ns)
        if self.send_description:
            self.send_description = False
            self.ch_desc.log({"data": self.urdf})
        t_ns = t_ns if t_ns is not None else self.contacts.t_ns
        if t_ns >= 0:
            self.server.broadcast_time(t_ns)

    def _show_robot(self) -> int | None:
        """/joint_states, /joint_targets and /tf from the newest messages; the joint states' stamp."""
        self.newest.drain()  # the newest of each (depth 1); the ground truth stays until a newer one
        js = self._joint_states(ifc.JOINT_STATES, self.ch_js, needed=self.ch_tf.has_sinks())
        self._joint_states(ifc.JOINT_TARGETS, self.ch_jt)
        if js is None:
            return None
        t_ns = stamp_ns(js)
        odom = self.latest.get(ifc.ODOM_GROUND_TRUTH)
        if odom is not None and self.ch_tf.has_sinks():
            try:
                o = deserialize_message(odom, Odometry).pose.pose
            except Exception as exc:
                self._warn(ifc.ODOM_GROUND_TRUTH, exc)
                return t_ns
            p, q = o.position, o.orientation
            poses = self.poser.transforms((p.x, p.y, p.z), (q.w, q.x, q.y, q.z),
                                          zip(js.name, js.position, strict=False))
            stamp = Timestamp(**stamp_dict(t_ns))
            self.ch_tf.log(FrameTransforms(transforms=[frame_transform(stamp, t) for t in poses]),
                           log_time=t_ns)
        return t_ns

    def flush_touchdowns(self) -> None:
        """One /contact/touchdown message per detected step (never throttled: they are events)."""
        events, self.contacts.touchdowns = self.contacts.touchdowns, []
        for side, t_ns in events:
            self.ch_touchdown.log({"timestamp": stamp_dict(t_ns), "side": side,
                                   "count": len(self.contacts.detector.events[side])}, log_time=t_ns)

    def on_exit(self) -> None:
        self.server.stop()
        self.taker.destroy_node()
        exit_stats(self, {"cpu_s": round(time.process_time(), 2), "received": self.counts,
                          "touchdowns": self.contacts.detector.events})


def frame_transform(stamp: Timestamp, p) -> FrameTransform:
    """A robot/frames.py Transform as Foxglove's FrameTransform."""
    (x, y, z), (qw, qx, qy, qz) = p.translation.tolist(), p.quat_wxyz.tolist()
    return FrameTransform(timestamp=stamp, parent_frame_id=p.parent, child_frame_id=p.child,
                          translation=Vector3(x=x, y=y, z=z), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def spin_bridge(node: FoxgloveNode) -> None:
    """Every tick (the display period, at most LOADS_PERIOD_S) take the sole loads that came (touchdowns)
    and show the newest state; in between, the executor waits for the low-rate topics and the parameter
    services' answers (one wake-up per tick and per such message: little CPU while idle)."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    period = min(node.display_period, LOADS_PERIOD_S)
    next_tick = 0.0
    while rclpy.ok():
        now = time.monotonic()
        if now >= next_tick:
            node.loads.drain()
            node.flush_touchdowns()
            node.display()
            next_tick = max(next_tick + period, now)
        executor.spin_once(timeout_sec=max(0.0, next_tick - time.monotonic()))


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("foxglove_node", "A live view of the graph in Foxglove (WebSocket server).",
                     specs.node_help(ifc.FOXGLOVE_NODE), argv)
    return run_main(argv, FoxgloveNode, spin_bridge)


if __name__ == "__main__":
    raise SystemExit(main())
