"""sim_node: the MuJoCo HOAP-2 as a ROS 2 node (``ros2 run cpg_walker sim_node``). See docs/ROS_INTERFACE.md.

The loop runs in ``main`` (not on a timer): for each control period k it publishes the state stamped
t_k = k * control_period, services callbacks (in lockstep until the torque stamped t_k has arrived), then
steps the physics for the period with the latest torque (zero-order hold). Pacing: ``realtime`` sleeps to
the wall schedule, ``fast`` never waits, ``lockstep`` waits for each period's command. In ``realtime`` a
period whose torque is late runs on the held one if that is at most ``max_torque_age`` old, else waits
for a recent one up to ``late_torque_wait`` wall s past the deadline (sim time pauses rather than the
physics running open loop), then goes on with the held torque and re-bases the schedule (see
docs/ROS_INTERFACE.md, "Pacing"). Parameter values: config/sim.yaml (``--params-file``).
"""

from __future__ import annotations

import time
from collections import deque

import mujoco
import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, String
from std_srvs.srv import Trigger

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes import specs
from cpg_walker.nodes.messages import (
    FOOT_LOAD_FRAMES,
    IMU_FRAME,
    ClockBuilder,
    ImuBuilder,
    JointStateBuilder,
    OdometryBuilder,
    WrenchBuilder,
    read_joint_command,
    stamp_ns,
    transform_stamped,
)
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
from cpg_walker.nodes.validation import check_finite_scalar, period_ns, reason_key
from cpg_walker.robot.contact import sole_wrenches
from cpg_walker.robot.frames import odom_transform
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.pid import ServoHold
from cpg_walker.robot.pusher import Pusher
from cpg_walker.robot.run_record import RunRecord
from cpg_walker.robot.urdf import read_urdf
from cpg_walker.timing import latency_summary

try:  # tf2_msgs is not on PyPI: a pip-only install has no live /tf (recordings carry /tf, see the docs)
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None


#: Wall s between services of the executor (parameters, services) while the loop runs.
SLOW_SPIN_PERIOD_S = 0.02
#: Realtime pacing more than this many wall s behind schedule re-bases the schedule instead of
#: catching up in a burst of periods.
MAX_LAG_S = 0.05
#: Wall s every node named wait_for_subscriber must stay subscribed before the first state (discovery of a
#: second node of that name can lag behind the first's subscriptions).
SUBSCRIBER_SETTLE_S = 0.5
#: Publish times kept for the latency statistics (by stamp); past the limit the oldest half is dropped
#: (answers to states that old never come).
PUBLISHED_KEEP = 256
#: Latency samples kept for the exit statistics (the newest; 400 sim s at the 2 ms period): a long run's
#: memory stays flat.
STATS_WINDOW = 200_000


class SimNode(Node):
    """Wires parameters, topics and services to a Hoap2Sim; ``run`` is the paced loop. ``node_options``
    go to rclpy's Node (e.g. ``cli_args=["--ros-args", "--params-file", ...]``, ``context``)."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.SIM_NODE], **node_options)
        self.sim = Hoap2Sim()

        v = declare_params(self, specs.SIM)
        self.pacing = v["pacing"]
        if self.pacing not in ifc.PACINGS:
            raise ValueError(f"pacing must be one of {ifc.PACINGS}, got {self.pacing!r}")
        self.period_ns = period_ns(v["control_period"])
        n = self.period_ns / (self.sim.dt * 1e9)
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ValueError(f"control_period must be a multiple of the physics timestep {self.sim.dt}")
        self.steps_per_period = round(n)
        self.rtf_target = float(v["real_time_factor"])
        self.duration_ns = round(v["duration"] * 1e9)
        describe = bool(v["publish_description"])
        self.stop_on_fall = bool(v["stop_on_fall"])
        self.wait_first = bool(v["wait_for_controller"])
        self.wait_subscriber = str(v["wait_for_subscriber"])
        self.resend_s = float(v["lockstep_resend"])
        self.late_wait_s = float(v["late_torque_wait"])
        self.max_age_ns = round(v["max_torque_age"] * 1e9)
        self.servo = ServoHold(float(v["servo_hold_after"]))
        odom, diag = v["odom_period"], v["diagnostics_period"]
        floor = float(v["imu_variance_floor"])
        self.record_path = v["record_path"]
        record_period = v["record_period"]
        scheduling = scheduling_request(v)  # applied once started (runtime.settle_process) ...
        if self.pacing != "realtime":  # ... and only with a wall-clock schedule to keep
            scheduling.update(realtime_priority=0, nice=0)
        self.scheduling = scheduling
        self.odom_every = max(1, round(odom * 1e9 / self.period_ns))
        self.diag_every = max(1, round(diag * 1e9 / self.period_ns))
        self.record = RunRecord(log_dt=self.period_ns * max(1, round(record_period * 1e9 / self.period_ns))
                                / 1e9)
        self.record_every = max(1, round(self.record.log_dt * 1e9 / self.period_ns))
        self.pusher = Pusher(self.sim)
        self.start_xy = self.sim.base_pose()[0][:2].copy()  # where the walk is measured from (and ~/reset)
        checked = self._on_set(self.get_parameters(["push.force", "push.body"]))  # as a later change is
        if not checked.successful:
            raise ValueError(checked.reason)
        self.throttle = Throttle(1.0)
        self.add_on_set_parameters_callback(self._on_set)

        self.pub_clock = self.create_publisher(Clock, ifc.CLOCK, ifc.DEPTH)
        self.pub_js = self.create_publisher(JointState, ifc.JOINT_STATES, ifc.DEPTH)
        self.pub_imu = self.create_publisher(Imu, ifc.IMU, ifc.DEPTH)
        self.pub_feet = [self.create_publisher(WrenchStamped, ifc.foot_load_topic(s), ifc.DEPTH)
                         for s, _ in FOOT_LOAD_FRAMES]
        self.pub_odom = self.create_publisher(Odometry, ifc.ODOM_GROUND_TRUTH, ifc.DEPTH)
        latched = ifc.latched_qos()
        self.pub_fallen = self.create_publisher(Bool, ifc.SIM_FALLEN, latched)
        self.pub_hold = self.create_publisher(Bool, ifc.SIM_SERVO_HOLD, latched)  # on each change
        self.pub_hold.publish(Bool(data=False))
        self.pub_diag = self.create_publisher(DiagnosticArray, ifc.DIAGNOSTICS, ifc.DEPTH)
        if describe:  # once: transient local hands it to subscribers that join later
            self.pub_description = self.create_publisher(String, ifc.ROBOT_DESCRIPTION, latched)
            self.pub_description.publish(String(data=read_urdf()))
        self.pub_tf = (None if TFMessage is None or not v["publish_tf"]
                       else self.create_publisher(TFMessage, ifc.TF, 100))
        self.hot = HotPath(self, [self.create_subscription(JointState, ifc.JOINT_TORQUES,
                                                           self._on_torque, ifc.DEPTH)])
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/push", self._on_push)

        noise = {n: float(self.sim.model.sensor_noise[i]) for n, i in self._sensor_ids().items()}
        var = {n: (s * s if s > 0 else floor) for n, s in noise.items()}
        self.b_clock = ClockBuilder()
        self.b_js = JointStateBuilder(JOINT_NAMES)
        self.b_imu = ImuBuilder(IMU_FRAME, var["imu_quat"], var["imu_gyro"], var["imu_accel"])
        self.b_feet = [WrenchBuilder(frame) for _, frame in FOOT_LOAD_FRAMES]
        self.b_odom = OdometryBuilder()

        self.executor_ = SingleThreadedExecutor()
        self.executor_.add_node(self)
        self.next_slow = 0.0
        self.tau = np.zeros(len(JOINT_NAMES))
        self.tau_stamp = -1
        self.published_at: dict[int, float] = {}
        self.latencies: deque[float] = deque(maxlen=STATS_WINDOW)  # state -> torque, wall s
        self.late = 0  # realtime: periods whose torque was not there by the deadline, of which
        self.late_recent = 0  # ... ran on one at most max_torque_age old
        self.late_waited = 0  # ... waited for one that recent, and got it (late_torque_wait)
        self.late_held = 0  # ... did not: the period ran with the held torque
        self.late_wait_wall = 0.0  # wall s spent waiting past deadlines (in all, longest once)
        self.late_wait_max = 0.0
        self.held_stamp: int | None = None  # after a wait gave up: the held torque's stamp (no more
        #                                     waits until a newer torque arrives)
        self.resends = 0
        self.torques_rejected = 0  # malformed /joint_torques, or stamped ahead of the sim time
        self.torque_age = [0, 0, 0]  # sim ns a period's torque was old: periods (after the first), sum, max
        self.fallen = False
        self.k = 0
        self.wall_start = None
        self.cpu_start = 0.0
        self.wall_end = None
        self._publish_fallen()

    def _sensor_ids(self) -> dict[str, int]:
        m = self.sim.model
        return {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, n)
                for n in ("imu_gyro", "imu_accel", "imu_quat")}

    # ------------------------------------------------------------------------------- callbacks
    def _on_set(self, params) -> SetParametersResult:
        for prm in params:
            try:
                if prm.name == "real_time_factor":
                    self.rtf_target = check_finite_scalar(prm.name, prm.value, 0.01, 100.0)
                elif prm.name == "push.force":
                    f = np.asarray(list(prm.value or []), dtype=float)
                    if f.shape != (3,) or not np.all(np.isfinite(f)):
                        raise ValueError("push.force must be 3 finite numbers (N, world frame)")
                elif prm.name == "push.duration":
                    check_finite_scalar(prm.name, prm.value, 1e-4, 10.0)
                elif prm.name == "push.body":
                    self.pusher.body_id(str(prm.value))
                elif prm.name == "lockstep_resend":
                    self.resend_s = check_finite_scalar(prm.name, prm.value, 0.001, 10.0)
                elif prm.name == "late_torque_wait":
                    self.late_wait_s = check_finite_scalar(prm.name, prm.value, 0.0, 10.0)
            except (ValueError, TypeError) as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _on_torque(self, msg: JointState) -> None:
        try:
            cmd = read_joint_command(msg, require="effort")
        except ValueError as exc:
            self.torques_rejected += 1
            self.throttle.warn(self, reason_key(exc),
                               f"rejected /joint_torques: {exc}")
            return
        t = stamp_ns(msg)
        if t > self.k * self.period_ns:  # answers a state not yet published: a corrupt or foreign stamp,
            self.torques_rejected += 1   # which would otherwise make every real torque after it look old
            self.throttle.warn(self, "future stamp", f"rejected /joint_torques stamped {t / 1e9:.9g} s, "
                               f"ahead of the sim time {self.k * self.period_ns / 1e9:.9g} s")
            return
        if t < self.tau_stamp:
            return  # an older answer arriving late: ignore
        if t != self.tau_stamp:
            sent = self.published_at.get(t)
            if sent is not None:
                self.latencies.append(time.perf_counter() - sent)
        tau = np.zeros(len(JOINT_NAMES))
        tau[cmd.index] = cmd.effort
        self.tau, self.tau_stamp = tau, t

    def _torque(self, t_ns: int) -> np.ndarray:
        """The torque for the period from t_ns: the controller's newest; once it is older than
        servo_hold_after (the controller is gone), the servos' own hold (ServoHold)."""
        if self.tau_stamp < 0 or not self.servo.after_ns or t_ns - self.tau_stamp <= self.servo.after_ns:
            if self.servo.active:
                self.servo.active = False
                self.pub_hold.publish(Bool(data=False))
                self.get_logger().info(f"torques resumed at sim {t_ns / 1e9:.3f} s: servo hold off")
            return self.tau
        sim = self.sim
        q, qd = sim.data.qpos[sim._qadr], sim.data.qvel[sim._dadr]
        if not self.servo.active:
            self.get_logger().warn(
                f"no torque newer than {self.tau_stamp / 1e9:.3f} s at sim {t_ns / 1e9:.3f} s: the servos "
                "hold their posture")
            self.pub_hold.publish(Bool(data=True))
        return self.servo.torque(q, qd, self.period_ns / 1e9)

    def _on_reset(self, request, response):
        self.sim.reset()
        self.start_xy = self.sim.base_pose()[0][:2].copy()
        self.pusher.clear()
        self.fallen = False
        self._publish_fallen()
        response.success = True
        response.message = f"reset to standing at sim time {self.k * self.period_ns / 1e9:.3f} s"
        return response

    def _on_push(self, request, response):
        g = self.get_parameter
        try:
            force = np.asarray(list(g("push.force").value), dtype=float)
            body, dur = str(g("push.body").value), float(g("push.duration").value)
            self.pusher.push(body, force, dur)
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success = True
        response.message = f"pushing {body} with {force.tolist()} N for {dur} s"
        return response

    # ------------------------------------------------------------------------------ publishing
    def _publish_fallen(self) -> None:
        self.pub_fallen.publish(Bool(data=self.fallen))

    def publish_state(self, t_ns: int) -> None:
        sim = self.sim
        msg = self.b_js.fill(t_ns, sim.data.qpos[sim._qadr], sim.data.qvel[sim._dadr],
                             sim.data.actuator_force[sim._act])
        self.published_at[t_ns] = time.perf_counter()
        self.pub_js.publish(msg)
        self.pub_clock.publish(self.b_clock.fill(t_ns))
        self._publish_sensors(t_ns)
        if self.pub_tf is not None:
            self.pub_tf.publish(TFMessage(transforms=[
                transform_stamped(t_ns, odom_transform(sim.model, sim.data))]))
        if self.k % self.odom_every == 0:
            pos, quat = sim.base_pose()
            lin, ang = sim.base_velocity()
            self.pub_odom.publish(self.b_odom.fill(t_ns, pos, quat, lin, ang))
        if self.k % self.diag_every == 0:
            self._publish_diagnostics(t_ns)
        if len(self.published_at) > PUBLISHED_KEEP:
            for key in sorted(self.published_at)[:PUBLISHED_KEEP // 2]:
                del self.published_at[key]

    def _publish_sensors(self, t_ns: int) -> None:
        """/imu and /foot_load/{left,right} of the current state, stamped t_ns (after its /clock)."""
        sim = self.sim
        imu = sim.imu()
        self.pub_imu.publish(self.b_imu.fill(t_ns, imu.gyro, imu.accel, imu.quat))
        for pub, b, (f, tq) in zip(self.pub_feet, self.b_feet, sole_wrenches(sim), strict=True):
            pub.publish(b.fill(t_ns, f, tq))

    def resend_state(self, t_ns: int) -> None:
        """Lockstep, no answer yet: the state of t_ns again (the sim has not stepped), sensors included
        (cpg_node's feedback waits for the sensor samples of each tick; one lost at start-up, before
        discovery completed, comes again)."""
        sim = self.sim
        self.pub_clock.publish(self.b_clock.fill(t_ns))
        self.pub_js.publish(self.b_js.fill(t_ns, sim.data.qpos[sim._qadr], sim.data.qvel[sim._dadr],
                                           sim.data.actuator_force[sim._act]))
        self._publish_sensors(t_ns)
        self.resends += 1

    def achieved_rtf(self) -> float:
        if self.wall_start is None:
            return 0.0
        wall = (self.wall_end or time.perf_counter()) - self.wall_start
        return (self.k * self.period_ns / 1e9) / wall if wall > 0 else 0.0

    def _publish_diagnostics(self, t_ns: int) -> None:
        st = DiagnosticStatus(name="cpg_walker/sim", hardware_id="mujoco_hoap2")
        st.level = DiagnosticStatus.ERROR if self.fallen else DiagnosticStatus.OK
        st.message = "fallen" if self.fallen else "ok"
        st.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ("sim_time_s", f"{t_ns / 1e9:.3f}"), ("pacing", self.pacing),
            ("real_time_factor", f"{self.achieved_rtf():.3f}"), ("fallen", self.fallen),
            ("fall_criterion", f"torso z < {self.sim.min_torso_height} m or tilt > "
                               f"{self.sim.max_tilt_deg} deg"),
            ("late_commands", self.late), ("late_recent", self.late_recent),
            ("late_waited", self.late_waited), ("late_held", self.late_held), ("resends", self.resends),
            ("torques_rejected", self.torques_rejected), ("servo_hold", self.servo.active),
            ("servo_holds", self.servo.entries))]
        msg = DiagnosticArray(status=[st])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
        self.pub_diag.publish(msg)

    # ------------------------------------------------------------------------------------ loop
    def _wait_for_torque(self, t_ns: int) -> bool:
        """Spin until the torque stamped t_ns arrived; re-send the state every ``lockstep_resend``."""
        last = time.perf_counter()
        while self.tau_stamp != t_ns:
            if not rclpy.ok():
                return False
            self.hot.poll(0.005)
            now = time.perf_counter()
            self.slow_spin(now)
            if self.tau_stamp != t_ns and now - last > self.resend_s:
                text = f"waiting for controller: no /joint_torques stamped {t_ns / 1e9:.3f} s yet"
                if self.k == 0:  # start-up: the controller's discovery is still under way
                    self.get_logger().info(text, throttle_duration_sec=2.0)
                else:
                    self.get_logger().warn(text, throttle_duration_sec=2.0)
                self.resend_state(t_ns)
                last = now
        return True

    def _wait_late(self, t_ns: int, deadline: float) -> None:
        """Realtime, the torque stamped t_ns missed its deadline. A torque at most max_torque_age old is
        used as it is (zero-order hold). An older one is not: the period waits, up to late_torque_wait
        wall s past the deadline, until one that recent has arrived (sim time pauses; the caller then
        re-bases the schedule, no catch-up burst). If none comes, the period runs with the held torque,
        and no period waits again until a newer torque than that one has arrived (a dead controller
        must not slow the sim down to one period per wait)."""
        oldest = t_ns - self.max_age_ns
        if self.tau_stamp >= oldest:
            self.late_recent += 1
            return
        if self.held_stamp is not None:
            if self.tau_stamp <= self.held_stamp:
                self.late_held += 1
                return
            self.held_stamp = None
        w0 = time.perf_counter()
        give_up = deadline + self.late_wait_s
        while self.tau_stamp < oldest and rclpy.ok():
            now = time.perf_counter()
            if now >= give_up:
                self.hot.poll(0.0)  # what arrived while this process was not running
                break
            self.hot.poll(min(give_up - now, 0.005))
            self.slow_spin(time.perf_counter())
        waited = time.perf_counter() - w0
        self.late_wait_wall += waited
        self.late_wait_max = max(self.late_wait_max, waited)
        if self.tau_stamp >= oldest:
            self.late_waited += 1
        else:
            self.late_held += 1
            self.held_stamp = self.tau_stamp
            self.throttle.warn(
                self, "held torque", f"no /joint_torques for {t_ns / 1e9:.3f} s within "
                f"{self.late_wait_s:g} wall s of its deadline: going on with the held torque")

    def slow_spin(self, now: float) -> None:
        """Parameters and services, through the executor, at most every SLOW_SPIN_PERIOD_S of wall time."""
        if now >= self.next_slow:
            spin_once_guarded(self, self.executor_, 0.0)
            self.next_slow = now + SLOW_SPIN_PERIOD_S

    def state_topics(self) -> list[str]:
        """The topics of the state published every period (/clock, /joint_states, /imu, /foot_load/*)."""
        return [pub.topic_name for pub in (self.pub_clock, self.pub_js, self.pub_imu, *self.pub_feet)]

    def command_topics(self) -> list[str]:
        """The controllers' topics of every period that have a publisher (/joint_targets, /joint_torques)."""
        return [t for t in (ifc.JOINT_TARGETS, ifc.JOINT_TORQUES) if self.count_publishers(t) > 0]

    def _wait_for_subscriber(self, topics: list[str]) -> bool:
        """Until every node named ``wait_for_subscriber`` (at least one) has a subscription on each of
        ``topics``: before the first state on the state topics, and once the controllers have answered it
        (their publishers exist now) on theirs, so a recorder that finds topics by scanning has the run
        from its first period (a cpg_node started late under load was found 0.7 sim s in, in lockstep)."""
        name = self.wait_subscriber
        since = None  # wall time from which every node of that name seen has subscribed

        def records(topic: str, info) -> bool:
            # a subscription of that node; on /clock a reliable one: a recorder under use_sim_time also has
            # its time source's best-effort /clock subscription, which is not the recording's (counted as
            # the recording's, the first /clock went out before the recorder subscribed to it, in CI)
            return info.node_name == name and (
                topic != ifc.CLOCK or info.qos_profile.reliability == ReliabilityPolicy.RELIABLE)

        while rclpy.ok():
            nodes = max(1, sum(n == name for n, _ in self.get_node_names_and_namespaces()))
            missing = [t for t in topics  # every node of that name (e.g. a second recorder)
                       if sum(records(t, i) for i in self.get_subscriptions_info_by_topic(t)) < nodes]
            now = time.monotonic()
            since = None if missing else (since or now)
            # held for SUBSCRIBER_SETTLE_S: a second node of that name still being discovered (a recorder
            # started just before) is counted too, instead of the run starting without it
            if since is not None and now - since >= SUBSCRIBER_SETTLE_S:
                self.get_logger().info(f"{name} subscribes to {', '.join(topics)}: going on")
                return True
            self.get_logger().info(f"waiting for {name} to subscribe to {', '.join(missing)}",
                                   throttle_duration_sec=2.0)
            self.slow_spin(time.perf_counter())
            time.sleep(0.01)
        return False

    def run(self) -> None:
        lockstep, realtime = self.pacing == ifc.LOCKSTEP, self.pacing == "realtime"
        if self.wait_subscriber and not self._wait_for_subscriber(self.state_topics()):
            return
        self.get_logger().info(
            f"pacing={self.pacing} control_period={self.period_ns / 1e9} s physics={self.sim.dt} s "
            f"({self.steps_per_period} steps/period)")
        sched_origin = 0.0
        rtf_in_use = self.rtf_target
        while rclpy.ok():
            t_ns = self.k * self.period_ns
            self.publish_state(t_ns)
            waits = lockstep or (self.k == 0 and self.wait_first)
            if waits and not self._wait_for_torque(t_ns):
                break
            if self.k == 0 and self.wait_subscriber and not self._wait_for_subscriber(self.command_topics()):
                break
            if self.k == 0:  # the run's clocks start now, after any start-up wait for the controller
                self.cpu_start = time.process_time()
                self.wall_start = time.perf_counter()
                sched_origin = self.wall_start
            if waits:
                pass
            elif realtime:
                if self.rtf_target != rtf_in_use:  # re-base the schedule on a factor change
                    sched_origin = time.perf_counter() - self.k * self.period_ns / 1e9 / self.rtf_target
                    rtf_in_use = self.rtf_target
                deadline = sched_origin + (self.k + 1) * self.period_ns / 1e9 / self.rtf_target
                self.hot.poll(0.0)
                while True:
                    remaining = deadline - time.perf_counter()
                    if remaining <= 0 or self.tau_stamp == t_ns:
                        break
                    self.hot.poll(remaining)
                self.slow_spin(time.perf_counter())
                if self.tau_stamp != t_ns:
                    self.late += 1
                    self._wait_late(t_ns, deadline)
                remaining = deadline - time.perf_counter()
                if remaining > 0:
                    time.sleep(remaining)
                elif remaining < -MAX_LAG_S:  # far behind: do not try to catch up in a burst
                    sched_origin -= remaining
            else:
                self.hot.poll(0.0)
                self.slow_spin(time.perf_counter())
            if self.k:
                age, old = self.torque_age, t_ns - self.tau_stamp
                age[0], age[1], age[2] = age[0] + 1, age[1] + old, max(age[2], old)
            self.pusher.update()
            self.sim.step(self._torque(t_ns), self.steps_per_period)
            self.k += 1
            t_next = self.k * self.period_ns
            if self.record_path and self.k % self.record_every == 0:  # kept only to be written
                self.record.sample(t_next / 1e9, self.sim)
            if not self.fallen and self.sim.has_fallen():
                self.fallen = True
                self.record.mark_fall(t_next / 1e9, self.sim)
                self._publish_fallen()
                self._publish_diagnostics(t_next)
                self.get_logger().warn(f"robot has fallen at sim time {t_next / 1e9:.3f} s")
                if self.stop_on_fall:
                    break
            if self.duration_ns and t_next >= self.duration_ns:
                break
        self.wall_end = time.perf_counter()

    def _outcome(self) -> str:
        """The run in words for the closing log line: the fall, or how far the base went."""
        moved = float(np.linalg.norm(self.sim.base_pose()[0][:2] - self.start_xy))
        if self.record.fell:
            return f"the robot FELL at {self.record.fall_time_s:.3f} s"
        return f"no fall; base {moved:.3f} m from where it started"

    def on_exit(self) -> None:
        if self.wall_end is None:
            self.wall_end = time.perf_counter()
        n, total, longest = self.torque_age
        stats = {
            "pacing": self.pacing, "control_period_s": self.period_ns / 1e9, "physics_dt_s": self.sim.dt,
            "periods": self.k, "sim_s": self.k * self.period_ns / 1e9,
            "wall_s": round((self.wall_end - self.wall_start) if self.wall_start else 0.0, 4),
            "real_time_factor": round(self.achieved_rtf(), 4), "late_commands": self.late,
            "late_recent": self.late_recent, "late_waited": self.late_waited, "late_held": self.late_held,
            "late_wait_wall_s": round(self.late_wait_wall, 3),
            "late_wait_max_s": round(self.late_wait_max, 4),
            "servo_holds": self.servo.entries,
            "resends": self.resends, "cpu_s": round(time.process_time() - self.cpu_start, 3),
            "latency": latency_summary(list(self.latencies)[1:]),
            "torque_age_s": {"mean": round(total / max(n, 1) / 1e9, 6), "max": round(longest / 1e9, 6)},
            "gc": gc_summary(self),
        }
        self.record.stats = stats
        exit_stats(self, stats, f"done: {stats['sim_s']:.3f} sim s in {stats['wall_s']:.3f} wall s, "
                               f"real-time factor {stats['real_time_factor']:.3f}, late commands "
                               f"{self.late} (ran on the previous {self.late_recent}, waited "
                               f"{self.late_waited}, held {self.late_held}); {self._outcome()}")
        if self.record_path:
            self.record.save(self.record_path)



def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("sim_node", "MuJoCo HOAP-2 simulation node (publishes /clock).",
                     specs.node_help(ifc.SIM_NODE), argv)
    return run_main(argv, SimNode, loop=SimNode.run)


if __name__ == "__main__":
    raise SystemExit(main())
