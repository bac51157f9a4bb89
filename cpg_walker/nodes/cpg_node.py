"""cpg_node: the learned humanoid CPG as a ROS node (``ros2 run cpg_walker cpg_node``).

Wiring around ``walker.cpg_driver.CPGDriver`` (the CPG on sim time, its feedback, /cmd_vel follower and
horizon): parameters, subscriptions, publishers, diagnostics. Every /clock tick gives /joint_targets
stamped with it (and, with ``lookahead``, the next period's), every ``horizon_period`` a /joint_trajectory
(the next ``horizon`` s, then ``horizon_stop`` s in which the stepping dies out: where pid_node goes if
this node dies), every ``monitor_period`` /cpg/state and /diagnostics. ``zeta``/``alpha`` command the
oscillators (the CPG's smoothed ζ/α), never a scaling of the output.
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from cpg_walker.nodes import cpg_params, specs
from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.messages import (
    FOOT_LOAD_FRAMES,
    IMU_FRAME,
    JointStateBuilder,
    JointTrajectoryBuilder,
    darray,
    stamp,
    stamp_ns,
)
from cpg_walker.nodes.params import by_name, declare, declare_params, descriptor, name_refusals
from cpg_walker.nodes.runtime import (
    HotPath,
    Throttle,
    exit_stats,
    gc_summary,
    parse_cli,
    run_main,
    scheduling_request,
)
from cpg_walker.nodes.validation import reason_key, to_ns, validate_imu, validate_load
from cpg_walker.timing import latency_summary
from cpg_walker.walker.cmd_vel import LIMIT_KEYS, CmdVelLimits, check_twist
from cpg_walker.walker.cpg_driver import CPGDriver, FeedbackFade
from cpg_walker.walker.feedback import FeedbackController
from cpg_walker.walker.governor import GovernorConfig, command_error
from cpg_walker.walker.learning import learning_settings, live_teaching_config, load_controller
from cpg_walker.walker.live_teaching import REFUSED, LiveTeacher


def state_layout(names, n_osc: int) -> MultiArrayLayout:
    """/cpg/state's layout: [dof (names in the label), oscillator (N) + output (1), value (3)]."""
    b, m = len(names), n_osc + 1
    return MultiArrayLayout(dim=[
        MultiArrayDimension(label="dof:" + ",".join(names), size=b, stride=b * m * 3),
        MultiArrayDimension(label=f"oscillator(0..{n_osc - 1}),output({n_osc})", size=m, stride=m * 3),
        MultiArrayDimension(label="phase_rad|frequency_hz|amplitude_rad;output:q|qd|offset", size=3,
                            stride=3),
    ], data_offset=0)


#: /cpg/teach messages held for the node (5 wall s of a teacher at 10 x real time, 100 Hz).
TEACH_DEPTH = 5000
#: /cpg/teach/state's values per joint.
TEACH_STATE_VALUES = ("learned_frequency_hz", "amplitude_rad", "error_deg")


def teach_state_layout(names) -> MultiArrayLayout:
    """/cpg/teach/state's layout: [dof (names in the label), value (TEACH_STATE_VALUES)]."""
    m = len(TEACH_STATE_VALUES)
    return MultiArrayLayout(dim=[
        MultiArrayDimension(label="dof:" + ",".join(names), size=len(names), stride=len(names) * m),
        MultiArrayDimension(label="|".join(TEACH_STATE_VALUES), size=m, stride=m)], data_offset=0)


#: cpg_node's parameter specs by name.
SPEC = by_name(specs.CPG)


class CPGNode(Node):
    """Wires parameters and topics to a CPGDriver (which also implements its output: this node).
    ``node_options`` go to rclpy's Node (``cli_args``, ``context``)."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.CPG_NODE], **node_options)
        v = {"governor": declare(self, "governor", descriptor(SPEC["governor"]))}  # alpha's range needs it
        v |= declare_params(self, [s for s in specs.cpg_specs(v["governor"]) if s.name != "governor"])
        governor = GovernorConfig.load() if v["governor"] else None
        for name in ("zeta", "alpha"):
            if reason := command_error(name, v[name], governor):
                raise ValueError(reason)
        self.scheduling = scheduling_request(v)  # applied once started (runtime.settle_process)
        fb_cfg, pathways = cpg_params.declare_feedback(self)
        limits = CmdVelLimits(**{k: float(v[f"cmd_vel.{k}"]) for k in LIMIT_KEYS})
        speed_map = cpg_params.load_speed_map(v["cmd_vel.speed_map"])
        cpg_file, n_osc = v["cpg_file"], v["n_oscillators"]
        self.diag_pub = self.create_publisher(DiagnosticArray, ifc.DIAGNOSTICS, ifc.DEPTH)
        self.state_pub = self.create_publisher(Float64MultiArray, ifc.CPG_STATE, ifc.DEPTH)
        self.pub = self.create_publisher(JointState, ifc.JOINT_TARGETS, ifc.DEPTH)
        self.traj_pub = self.create_publisher(JointTrajectory, ifc.JOINT_TRAJECTORY, 5)
        self.throttle = Throttle(1.0)
        self.driver: CPGDriver | None = None
        if not cpg_file:
            self._diagnostics(0, "learning", {})
            self.get_logger().info(f"learning the CPG (N={n_osc or 'of the learning settings'}) at "
                                   "start-up ...")
        try:
            n_learn = (n_osc or None) if not cpg_file else None
            ctrl, self.origin, self.converged = load_controller(cpg_file, n_learn)
        except FileNotFoundError as exc:
            raise ValueError(str(exc)) from None
        self.driver = CPGDriver(
            ctrl, self, feedback=FeedbackController(fb_cfg, pathways), feedback_on=v["feedback"],
            fade=FeedbackFade(v["feedback_fade"], v["sensor_timeout"]), zeta=v["zeta"], alpha=v["alpha"],
            speed_map=speed_map, cmd_vel_limits=limits, follow_cmd_vel=v["cmd_vel.follow"],
            lockstep=v["lockstep"], ankle_in_realtime=v["ankle_in_realtime"],
            ankle_for_side_step=v["ankle_for_side_step"], ankle_for_speed=v["ankle_for_speed"],
            sensor_wait_s=v["sensor_wait"],
            lookahead=v["lookahead"],
            monitor_period_ns=round(v["monitor_period"] * 1e9), horizon_s=v["horizon"],
            horizon_step_ns=round(v["horizon_step"] * 1e9), horizon_stop_s=v["horizon_stop"],
            horizon_period_ns=round(v["horizon_period"] * 1e9),
            rejoin_settle_ns=round(v["rejoin_settle"] * 1e9),
            governor=governor, teacher=self._teacher(v["teach"], ctrl.net.N), teach_steps=v["teach_steps"],
            teach_blend_s=v["teach_blend"])
        self.get_logger().info(f"CPG warmed up in {self.driver.warm_up():.3f} s")
        self.add_on_set_parameters_callback(self._on_set)
        name_refusals(self, lambda name, value: command_error(name, value, governor)
                      if name in ("zeta", "alpha") else None)  # why a zeta/alpha is out of range
        self.builder = JointStateBuilder(self.driver.source.names, fields=("position", "velocity"))
        self.traj_builder: tuple[int, JointTrajectoryBuilder] | None = None  # (offsets' id, builder)
        self.state_msg = Float64MultiArray(layout=state_layout(ctrl.names, ctrl.net.N))
        self.idle = self.driver.idle  # runtime.spin_hot calls it every executor period
        subs = [self.create_subscription(Clock, ifc.CLOCK, self._on_clock, 100),
                self.create_subscription(Imu, ifc.IMU, self._on_imu, 100)]
        for i, (side, frame) in enumerate(FOOT_LOAD_FRAMES):
            subs.append(self.create_subscription(
                WrenchStamped, ifc.foot_load_topic(side),
                lambda msg, i=i, frame=frame: self._on_load(i, frame, msg), 100))
        # /cmd_vel in the hot path too: a Twist is timed by the tick it arrives at (it has no stamp), so it
        # must not wait in the executor's queue (one callback per executor_period)
        subs.append(self.create_subscription(Twist, ifc.CMD_VEL, self._on_cmd_vel, ifc.DEPTH))
        subs.append(self.create_subscription(Bool, ifc.SIM_SERVO_HOLD, lambda msg: self.driver.servo_hold(
            msg.data), ifc.latched_qos()))
        self.teaching = self.driver.teacher is not None
        if self.teaching:
            # in the hot path: a teacher at 10 x real time sends 1000 samples per wall s; TEACH_DEPTH of them
            # wait while the node is busy (a sample lost is a gap in the teacher's time)
            subs.append(self.create_subscription(JointState, ifc.CPG_TEACH, self._on_teach, TEACH_DEPTH))
            self.create_service(Trigger, "~/take_over", self._on_take_over)
            self.create_service(Trigger, "~/save_taught", self._on_save_taught)
            self.teach_pub = self.create_publisher(Float64MultiArray, ifc.CPG_TEACH_STATE, ifc.DEPTH)
            self.teach_msg = Float64MultiArray(layout=teach_state_layout(self.driver.teacher.names))
        self.hot = HotPath(self, subs)
        self._diagnostics(0, "converged", {})
        d = self.driver
        self.get_logger().info(f"CPG N={ctrl.net.N} from {self.origin}; recording's opening steps to "
                               f"{d.source.handover:.3f} s, CPG from {d.walk_from_s:.3f} s")

    @staticmethod
    def _teacher(on: bool, n_oscillators: int) -> LiveTeacher | None:
        """The live learner of /cpg/teach (the learning settings', with the walking network's N)."""
        if not on:
            return None
        settings, params = learning_settings(n_oscillators)
        return LiveTeacher(settings, params, live_teaching_config())

    # ---------------------------------------------------------------- the driver's output
    def targets(self, t_ns: int, q: np.ndarray, qd: np.ndarray) -> None:
        self.pub.publish(self.builder.fill(t_ns, position=q, velocity=qd))

    def horizon(self, t_ns: int, offsets_ns: np.ndarray, q: np.ndarray, qd: np.ndarray) -> None:
        if self.traj_builder is None or self.traj_builder[0] != id(offsets_ns):
            self.traj_builder = (id(offsets_ns), JointTrajectoryBuilder(self.driver.source.names,
                                                                        offsets_ns.tolist()))
        self.traj_pub.publish(self.traj_builder[1].fill(t_ns, q, qd))

    def monitor(self, t_ns: int, state: np.ndarray, values: dict[str, str]) -> None:
        self.state_msg.data = darray(state)
        self.state_pub.publish(self.state_msg)
        self._diagnostics(t_ns, self.driver.stage, values)
        if self.teaching:
            progress = self.driver.teacher.progress()
            if "error_deg" in progress:  # learning
                self.teach_msg.data = darray(np.array([progress[k] for k in TEACH_STATE_VALUES]).T.ravel())
                self.teach_pub.publish(self.teach_msg)

    def log(self, level: str, text: str, key: str | None = None) -> None:
        if key is not None:
            self.throttle.warn(self, key, text)
        elif level == "warn":
            self.get_logger().warn(text)
        else:
            self.get_logger().info(text)

    # ---------------------------------------------------------------- topics
    def _on_clock(self, msg: Clock) -> None:
        self.driver.clock(to_ns(msg.clock.sec, msg.clock.nanosec))

    def _on_imu(self, msg: Imu) -> None:
        o, w = msg.orientation, msg.angular_velocity
        try:
            value = validate_imu(msg.header.frame_id, IMU_FRAME, (o.w, o.x, o.y, o.z), (w.x, w.y, w.z))
        except ValueError as exc:
            return self._drop(ifc.IMU, exc)
        self.driver.sample(0, stamp_ns(msg), value)

    def _on_load(self, i: int, frame: str, msg: WrenchStamped) -> None:
        try:
            value = validate_load(msg.header.frame_id, frame, msg.wrench.force.z)
        except ValueError as exc:
            return self._drop(ifc.foot_load_topic(FOOT_LOAD_FRAMES[i][0]), exc)
        self.driver.sample(1 + i, stamp_ns(msg), value)

    def _drop(self, topic: str, exc: ValueError) -> None:
        self.driver.dropped("sensors_dropped")
        self.throttle.warn(self, topic + " " + reason_key(exc), f"dropped {topic}: {exc}")

    def _on_cmd_vel(self, msg: Twist) -> None:
        lin, ang = msg.linear, msg.angular
        try:
            check_twist(lin.x, ang.z, (lin.z, ang.x, ang.y), linear_y=lin.y)
        except ValueError as exc:
            self.driver.cmd_vel_counts["dropped"] += 1
            self.throttle.warn(self, "/cmd_vel " + reason_key(exc), f"dropped /cmd_vel: {exc}")
            return
        self.driver.twist(lin.x, ang.z, lin.y)

    def _on_teach(self, msg: JointState) -> None:
        names, positions = list(msg.name), list(msg.position)
        if len(names) != len(positions) or not names:
            self.throttle.warn(self, "/cpg/teach malformed", f"dropped /cpg/teach: {len(names)} names, "
                               f"{len(positions)} positions")
            return
        self.driver.teach(stamp_ns(msg) / 1e9, names, positions)

    def _on_take_over(self, _request, response):
        try:
            response.message, response.success = self.driver.take_over(), True
            self.get_logger().info(response.message)
        except ValueError as exc:
            response.message, response.success = f"refused: {exc}", False
        return response

    def _on_save_taught(self, _request, response):
        try:
            path = self.driver.save_taught(self.get_parameter("teach_file").value)
            response.message, response.success = f"wrote {path}", True
        except (ValueError, OSError) as exc:
            response.message, response.success = f"refused: {exc}", False
        return response

    # ---------------------------------------------------------------- parameters
    def _on_set(self, params) -> SetParametersResult:
        """Validate every parameter of the request, then apply them all (between ticks: the callback runs
        in the node's one thread). A refusal's reason names the parameter."""
        d = self.driver
        values = {prm.name: prm.value for prm in params}
        modulation = {n: values[n] for n in ("zeta", "alpha") if n in values}
        try:
            for name, value in modulation.items():
                if reason := command_error(name, value, d.governor_config):
                    raise ValueError(reason)
            pathways = cpg_params.pathway_list(values["feedback_pathways"]) \
                if "feedback_pathways" in values else None
            for name in ("sensor_timeout", "feedback_fade", "sensor_wait"):
                if name in values:
                    cpg_params.check_value(SPEC[name], values[name])
            fb = d.source.fb
            fields = cpg_params.feedback_fields()
            fb_changes = {n[9:]: v for n, v in values.items()
                          if n.startswith("feedback.") and n[9:] in fields}
            cfg = cpg_params.check_feedback(fb_changes, fb.cfg)
            cmd_vel = {n[len("cmd_vel."):]: v for n, v in values.items() if n.startswith("cmd_vel.")}
            follow, limits, smap = cpg_params.check_cmd_vel(cmd_vel, d.cmd.limits)
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if fb_changes or pathways is not None:
            d.configure_feedback(cfg, pathways if pathways is not None else fb.pathways, fb_changes)
        if "feedback" in values:
            d.set_feedback(values["feedback"])
        d.fade.timeout_s = float(values.get("sensor_timeout", d.fade.timeout_s))
        d.fade.fade_s = float(values.get("feedback_fade", d.fade.fade_s))
        d.sensor_wait_s = float(values.get("sensor_wait", d.sensor_wait_s))
        if cmd_vel:
            d.set_cmd_vel(follow, limits, smap)
        if modulation:
            d.command(float(modulation.get("zeta", d.zeta)), float(modulation.get("alpha", d.alpha)))
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- diagnostics
    def _diagnostics(self, t_ns: int, stage: str, values: dict[str, str]) -> None:
        """/diagnostics 'cpg_walker/cpg': the stage (learning | converged | starting | walking) and the
        driver's status ``values`` of a monitored tick (none: as of now); WARN when learning did not
        converge and, on a monitored tick, when feedback is on with stale sensors or /cmd_vel's angular.z
        cannot turn the robot."""
        d = self.driver
        ok = stage == "learning" or self.converged
        level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
        text = stage if ok else f"{stage} (learning not converged)"
        head = {"state": stage, "overruns": str(d.timing.overruns if d else 0)}
        if d is not None:
            net = d.ctrl.net
            head.update({"n_oscillators": str(net.N), "cpg_file": self.origin,
                         "learning_converged": str(self.converged).lower()})
        monitored, values = bool(values), values or (d.status(t_ns) if d is not None else {})
        if monitored and values.get("feedback") in ("fading", "stale") \
                and values.get("feedback_enabled") == "true":
            level = DiagnosticStatus.WARN
            text += f"; feedback {values['feedback']} (sensor data {values['sensor_age_s']} s old)"
        if monitored and values.get("cmd_vel_turn", "ok") != "ok":
            level = DiagnosticStatus.WARN
            text += f"; /cmd_vel angular.z cannot turn: {values['cmd_vel_turn']}"
        status = DiagnosticStatus(level=level, name="cpg_walker/cpg", message=text, hardware_id="cpg",
                                  values=[KeyValue(key=k, value=v) for k, v in {**head, **values}.items()])
        arr = DiagnosticArray(status=[status])
        if d is not None and d.teacher is not None:
            tv = d.teach_status()
            refused = tv["teaching"] == REFUSED
            arr.status.append(DiagnosticStatus(
                level=DiagnosticStatus.WARN if refused else DiagnosticStatus.OK, name="cpg_walker/teaching",
                message=f"refused: {tv['teaching_reason']}" if refused else tv["teaching"], hardware_id="cpg",
                values=[KeyValue(key=k, value=v) for k, v in tv.items()]))
        arr.header.stamp = stamp(t_ns)
        self.diag_pub.publish(arr)

    def on_exit(self) -> None:
        d = self.driver
        exit_stats(self, {**d.summary(), "gc": gc_summary(self),
                          "horizon_work": latency_summary(d.horizon_work)})


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli(ifc.CPG_NODE, "The learned humanoid CPG: /joint_targets on /clock, zeta/alpha "
                     "modulation.", specs.node_help(ifc.CPG_NODE), argv)
    return run_main(argv, CPGNode)


if __name__ == "__main__":
    raise SystemExit(main())
