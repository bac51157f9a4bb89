"""odom_node: the leg odometry as a ROS 2 node (``ros2 run cpg_walker odom_node``). See docs/ROS_INTERFACE.md.

Assembles each sensor sample from the four topics of one stamp (``/joint_states``, ``/imu``,
``/foot_load/left``, ``/foot_load/right``, which sim_node publishes together every control period; a part
lost on the way is replaced by the previous sample's), feeds it to
cpg_walker.robot.odometry.LegOdometry, and publishes ``/odom`` (nav_msgs/Odometry, frame ``odom``,
child ``base_link``, with a covariance) every ``publish_period`` of sim time and, with ``publish_tf``
(where tf2_msgs imports), ``odom -> base_link`` on ``/tf``. Only what a real HOAP-2 senses is used, never
``/odom/ground_truth``. A malformed message is dropped with a throttled warning. Parameter values:
config/odom.yaml (``--params-file``).
"""

from __future__ import annotations

import time

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes import specs
from cpg_walker.nodes.messages import FOOT_LOAD_FRAMES, IMU_FRAME, stamp, stamp_ns, transform_stamped
from cpg_walker.nodes.params import declare_params
from cpg_walker.nodes.runtime import (
    HotPath,
    Throttle,
    exit_stats,
    gc_summary,
    parse_cli,
    run_main,
    scheduling_request,
    spin_once_guarded,
)
from cpg_walker.nodes.validation import period_ns, reason_key, validate_imu, validate_load
from cpg_walker.robot.frames import BASE_LINK, ODOM_FRAME, Transform
from cpg_walker.robot.odometry import LegOdometry, OdometryConfig
from cpg_walker.timing import CLOCK_RESET_S

try:  # tf2_msgs is not on PyPI: a pip-only install has no live /tf (as sim_node)
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

#: Incomplete samples (a topic's message lost) kept by stamp before the oldest are dropped.
PENDING_KEEP = 64
#: Wall s between takes of the waiting messages: in batches, not woken by each of the ~2000 messages per
#: sim s (the CPU cost; /odom is then up to this much later in wall time). The subscriptions' depth holds
#: a batch of every topic with room to spare (a 2 ms control period: 2.5 messages per 5 ms at 1x).
BATCH_S = 0.005
SUB_DEPTH = 100
#: Wall s between services of the executor (parameters, /clock of use_sim_time).
EXECUTOR_PERIOD_S = 0.02
#: The parts of one sample: /joint_states, /imu, /foot_load/left, /foot_load/right.
PARTS = 4


class OdomNode(Node):
    """Sensor samples by stamp -> LegOdometry -> /odom (and /tf). ``node_options`` go to rclpy's Node."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.ODOM_NODE], **node_options)
        v = declare_params(self, specs.ODOM)
        self.scheduling = scheduling_request(v)  # applied once started (runtime.settle_process)
        self.config = OdometryConfig.from_params(v)
        self.odom = LegOdometry(self.config)
        self.period_ns = period_ns(v["publish_period"])
        self.pub = self.create_publisher(Odometry, ifc.ODOM, ifc.DEPTH)
        self.pub_tf = (self.create_publisher(TFMessage, ifc.TF, 100)
                       if v["publish_tf"] and TFMessage is not None else None)
        self.msg = Odometry()
        self.msg.header.frame_id, self.msg.child_frame_id = ODOM_FRAME, BASE_LINK
        self.pending: dict[int, list] = {}
        self.last_ns: int | None = None  # stamp of the last sample processed
        self.next_pub_ns = 0
        #: samples processed, /odom published, messages dropped (malformed), samples skipped (parts lost
        #: before the first complete one), parts lost (the previous value stood in), samples the estimator
        #: refused, sim restarts
        self.counts = {"samples": 0, "published": 0, "dropped": 0, "incomplete": 0, "filled": 0,
                       "rejected": 0, "clock_resets": 0}
        self.newest = [-1] * PARTS  # the newest stamp of each topic
        self.last_parts: list | None = None
        self.received = [0] * PARTS
        self.throttle = Throttle(1.0)
        subs = [self.create_subscription(JointState, ifc.JOINT_STATES, self._on_joints, SUB_DEPTH),
                self.create_subscription(Imu, ifc.IMU, self._on_imu, SUB_DEPTH)]
        for i, (side, frame) in enumerate(FOOT_LOAD_FRAMES):
            subs.append(self.create_subscription(
                WrenchStamped, ifc.foot_load_topic(side),
                lambda msg, i=i, frame=frame: self._on_load(i, frame, msg), SUB_DEPTH))
        self.hot = HotPath(self, subs)
        self.cpu_start = time.process_time()
        tf = "and /tf" if self.pub_tf is not None else "(no /tf: " + (
            "publish_tf false)" if not v["publish_tf"] else "tf2_msgs not installed)")
        self.get_logger().info(f"leg odometry: /odom every {self.period_ns / 1e9:g} sim s {tf}")

    # ------------------------------------------------------------------------------- callbacks
    def _drop(self, topic: str, exc: Exception) -> None:
        self.counts["dropped"] += 1
        self.throttle.warn(self, topic + " " + reason_key(exc), f"dropped {topic}: {exc}")

    def _on_joints(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name):
            return self._drop(ifc.JOINT_STATES, ValueError(f"{len(msg.name)} names but {len(msg.position)} "
                                                           "positions"))
        self._part(stamp_ns(msg), 0, (msg.name, msg.position))

    def _on_imu(self, msg: Imu) -> None:
        o, w = msg.orientation, msg.angular_velocity
        try:
            value = validate_imu(msg.header.frame_id, IMU_FRAME, (o.w, o.x, o.y, o.z), (w.x, w.y, w.z))
        except ValueError as exc:
            return self._drop(ifc.IMU, exc)
        self._part(stamp_ns(msg), 1, value)

    def _on_load(self, i: int, frame: str, msg: WrenchStamped) -> None:
        try:
            value = validate_load(msg.header.frame_id, frame, msg.wrench.force.z)
        except ValueError as exc:
            return self._drop(ifc.foot_load_topic(FOOT_LOAD_FRAMES[i][0]), exc)
        self._part(stamp_ns(msg), 2 + i, value)

    def _part(self, t_ns: int, k: int, value) -> None:
        """One part of the sample stamped ``t_ns``, kept until ``flush``."""
        if self.last_ns is not None and t_ns <= self.last_ns:
            if self.last_ns - t_ns <= CLOCK_RESET_S * 1e9:
                return  # a re-sent or stale message: that stamp is done
            self._clock_reset(t_ns)
        parts = self.pending.get(t_ns)
        if parts is None:
            parts = self.pending[t_ns] = [None] * PARTS
        parts[k] = value
        self.received[k] += 1
        self.newest[k] = max(self.newest[k], t_ns)

    def flush(self) -> None:
        """Process the kept samples in stamp order: each once every topic has a message that new (or
        when PENDING_KEEP are waiting). A part still missing then was lost (the middleware drops
        messages when this process is not scheduled in time): the previous sample's value stands in."""
        if not self.pending:
            return
        ready = min(self.newest)
        for t_ns in sorted(self.pending):
            if t_ns > ready and len(self.pending) <= PENDING_KEEP:
                break
            parts = self.pending.pop(t_ns)
            missing = [k for k in range(PARTS) if parts[k] is None]
            if missing:
                if self.last_parts is None:
                    self.counts["incomplete"] += 1
                    continue
                for k in missing:
                    parts[k] = self.last_parts[k]
                self.counts["filled"] += len(missing)
            self._sample(t_ns, parts)

    def _clock_reset(self, t_ns: int) -> None:
        """A stamp more than CLOCK_RESET_S before the last sample's: the sim restarted; start over."""
        self.get_logger().warn(f"sensor stamps went back from {self.last_ns / 1e9:.3f} s to "
                               f"{t_ns / 1e9:.3f} s (sim restarted): the odometry starts over at the origin")
        self.odom = LegOdometry(self.config, self.odom.kin)
        self.pending.clear()
        self.newest = [-1] * PARTS
        self.last_parts = None
        self.last_ns = None
        self.next_pub_ns = 0
        self.counts["clock_resets"] += 1

    def _sample(self, t_ns: int, parts: list) -> None:
        (names, positions), (quat, gyro), left, right = parts
        try:
            self.odom.update(t_ns / 1e9, names, positions, quat, gyro, (left, right))
        except ValueError as exc:
            self.counts["rejected"] += 1
            self.throttle.warn(self, "sample " + reason_key(exc), f"dropped the sensor sample of "
                               f"{t_ns / 1e9:.3f} s: {exc}")
            return
        self.last_ns = t_ns
        self.last_parts = parts
        self.counts["samples"] += 1
        if t_ns >= self.next_pub_ns:
            self.next_pub_ns = (t_ns // self.period_ns + 1) * self.period_ns
            self._publish(t_ns)

    def _publish(self, t_ns: int) -> None:
        est = self.odom.estimate()
        m = self.msg
        m.header.stamp = stamp(t_ns)
        p, q = m.pose.pose.position, m.pose.pose.orientation
        p.x, p.y, p.z = (float(x) for x in est.position)
        q.w, q.x, q.y, q.z = (float(x) for x in est.quat_wxyz)
        tl, ta = m.twist.twist.linear, m.twist.twist.angular
        tl.x, tl.y, tl.z = (float(x) for x in est.linear)
        ta.x, ta.y, ta.z = (float(x) for x in est.angular)
        m.pose.covariance = est.pose_covariance.reshape(36)
        m.twist.covariance = est.twist_covariance.reshape(36)
        self.pub.publish(m)
        if self.pub_tf is not None:
            self.pub_tf.publish(TFMessage(transforms=[transform_stamped(
                t_ns, Transform(ODOM_FRAME, BASE_LINK, est.position, est.quat_wxyz))]))
        self.counts["published"] += 1

    def run(self) -> None:
        """Take the waiting messages every BATCH_S wall s (HotPath.drain), the rest through an executor
        every EXECUTOR_PERIOD_S."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor()
        executor.add_node(self)
        next_slow = 0.0
        while rclpy.ok():
            self.hot.drain()
            self.flush()
            now = time.monotonic()
            if now >= next_slow:
                spin_once_guarded(self, executor, 0.0)
                next_slow = now + EXECUTOR_PERIOD_S
            time.sleep(BATCH_S)

    def on_exit(self) -> None:
        est = self.odom.estimate() if self.odom.t is not None else None
        exit_stats(self, {**self.counts, "received": dict(zip(
                              (ifc.JOINT_STATES, ifc.IMU, *ifc.FOOT_LOADS), self.received, strict=True)),
                          "cpu_s": round(time.process_time() - self.cpu_start, 3),
                          "distance_m": None if est is None else round(est.distance_m, 4),
                          "turned_rad": None if est is None else round(est.turned_rad, 4),
                          "gc": gc_summary(self)})


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("odom_node", "HOAP-2 leg odometry: /joint_states + /imu + /foot_load/* -> /odom.",
                     specs.node_help(ifc.ODOM_NODE), argv)
    return run_main(argv, OdomNode, loop=OdomNode.run)


if __name__ == "__main__":
    raise SystemExit(main())
