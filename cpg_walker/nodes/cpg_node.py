"""cpg_node: the learned humanoid CPG as a ROS node (``ros2 run cpg_walker cpg_node``).

Wiring around ``walker.cpg_driver.CPGDriver`` (the CPG on sim time, its feedback, /cmd_vel follower and
horizon): parameters, subscriptions, publishers, diagnostics. Every /clock tick gives /joint_targets
stamped with it (and, with ``lookahead``, the next period's), every ``horizon_step`` a /joint_trajectory
(the next ``horizon`` s, then ``horizon_stop`` s in which the stepping dies out: where pid_node goes if
this node dies), every ``monitor_period`` /cpg/state and /diagnostics. ``zeta``/``alpha`` command the
oscillators (the CPG's smoothed ζ/α), never a scaling of the output.
"""

from __future__ import annotations

import json

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from trajectory_msgs.msg import JointTrajectory

from cpg_walker.nodes import cpg_params
from cpg_walker.nodes.messages import (
    FOOT_LOAD_FRAMES,
    IMU_FRAME,
    JointStateBuilder,
    JointTrajectoryBuilder,
    darray,
    stamp,
    stamp_ns,
)
from cpg_walker.nodes.runtime import (
    HotPath,
    Throttle,
    bool_param,
    declare,
    declare_scheduling,
    exit_log,
    float_param,
    gc_summary,
    int_param,
    parse_cli,
    run_main,
    str_param,
)
from cpg_walker.nodes.validation import check_finite_scalar, reason_key, to_ns, validate_imu, validate_load
from cpg_walker.timing import latency_summary
from cpg_walker.walker.cmd_vel import check_twist
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE, modulation_error
from cpg_walker.walker.cpg_driver import CPGDriver, FeedbackFade
from cpg_walker.walker.feedback import FeedbackController
from cpg_walker.walker.learning import load_controller

INTERFACE = """\
subscribes: /clock (rosgraph_msgs/Clock), /imu (sensor_msgs/Imu), /foot_load/left and /foot_load/right
  (geometry_msgs/WrenchStamped) - the feedback pathways' sensors, on sim time; /cmd_vel
  (geometry_msgs/Twist; cmd_vel.*); /sim/servo_hold (std_msgs/Bool, latched: on release the gait
  re-enters from the standing crouch)
publishes: /joint_targets (sensor_msgs/JointState), /joint_trajectory (trajectory_msgs/JointTrajectory),
  /cpg/state (std_msgs/Float64MultiArray), /diagnostics (diagnostic_msgs/DiagnosticArray)
parameters: docs/reference/cpg.md"""


def state_layout(names, n_osc: int) -> MultiArrayLayout:
    """/cpg/state's layout: [dof (names in the label), oscillator (N) + output (1), value (3)]."""
    b, m = len(names), n_osc + 1
    return MultiArrayLayout(dim=[
        MultiArrayDimension(label="dof:" + ",".join(names), size=b, stride=b * m * 3),
        MultiArrayDimension(label=f"oscillator(0..{n_osc - 1}),output({n_osc})", size=m, stride=m * 3),
        MultiArrayDimension(label="phase_rad|frequency_hz|amplitude_rad;output:q|qd|offset", size=3,
                            stride=3),
    ], data_offset=0)


class CPGNode(Node):
    """Wires parameters and topics to a CPGDriver (which also implements its output: this node).
    ``node_options`` go to rclpy's Node (``cli_args``, ``context``)."""

    def __init__(self, **node_options) -> None:
        super().__init__("cpg", **node_options)
        p = lambda name, descriptor: declare(self, name, descriptor)  # noqa: E731
        cpg_file = p("cpg_file", str_param(
            "learned CPG YAML (a path, or a name in the package's config/); '' = learn at start-up",
            read_only=True))
        n_osc = p("n_oscillators", int_param(
            "oscillators per DOF when learning at start-up (0 = the learning settings' N)", 0, 20,
            read_only=True))
        zeta = p("zeta", float_param("frequency ratio ζ of the oscillators (negative: backwards)",
                                     *ZETA_RANGE))
        alpha = p("alpha", float_param("amplitude (step length) scale α of the oscillators", *ALPHA_RANGE))
        for name, value in (("zeta", zeta), ("alpha", alpha)):
            if reason := modulation_error(name, value):
                raise ValueError(reason)
        ro = {"read_only": True}
        timing = {
            "lookahead": p("lookahead", bool_param("also send the next period's target on each tick", **ro)),
            "monitor_period_ns": round(p("monitor_period", float_param(
                "sim s between /cpg/state and /diagnostics messages", 0.002, 60.0, **ro)) * 1e9),
            "horizon_s": p("horizon", float_param(
                "sim s of future targets in each /joint_trajectory (0 = none published)", 0.0, 5.0, **ro)),
            "horizon_step_ns": round(p("horizon_step", float_param(
                "sim s between /joint_trajectory points and between messages", 0.002, 1.0, **ro)) * 1e9),
            "horizon_stop_s": p("horizon_stop", float_param(
                "sim s after the horizon over which its stepping dies out (alpha -> 0): where pid_node goes "
                "when this node is gone", 0.0, 10.0, **ro)),
            "rejoin_settle_ns": round(p("rejoin_settle", float_param(
                "sim s a node that joined a running sim (realtime pacing) stands by before it re-enters the "
                "gait (pid_node holds the crouch meanwhile); lockstep re-enters at once", 0.0, 10.0,
                **ro)) * 1e9),
        }
        self.scheduling = declare_scheduling(self)  # applied once started (runtime.settle_process)
        lockstep = p("lockstep", bool_param(
            "wait for the sensor samples stamped like each /clock tick (deterministic; with the sim's "
            "lockstep pacing)", **ro))
        feedback_on = p("feedback", bool_param(
            "close the sensory feedback pathways (false: the open-loop CPG)"))
        fb_cfg, pathways, fb_settings = cpg_params.declare_feedback(self)
        follow, limits, speed_map = cpg_params.declare_cmd_vel(self)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.state_pub = self.create_publisher(Float64MultiArray, "/cpg/state", 10)
        self.pub = self.create_publisher(JointState, "/joint_targets", 10)
        self.traj_pub = self.create_publisher(JointTrajectory, "/joint_trajectory", 5)
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
        fade = FeedbackFade(fb_settings["feedback_fade"], fb_settings["sensor_timeout"])
        self.driver = CPGDriver(
            ctrl, self, feedback=FeedbackController(fb_cfg, pathways), feedback_on=feedback_on, fade=fade,
            zeta=zeta, alpha=alpha, speed_map=speed_map, cmd_vel_limits=limits, follow_cmd_vel=follow,
            lockstep=lockstep, sensor_wait_s=fb_settings["sensor_wait"], **timing)
        self.get_logger().info(f"CPG warmed up in {self.driver.warm_up():.3f} s")
        self.add_on_set_parameters_callback(self._on_set)
        self.builder = JointStateBuilder(self.driver.source.names, fields=("position", "velocity"))
        self.traj_builder: tuple[int, JointTrajectoryBuilder] | None = None  # (offsets' id, builder)
        self.state_msg = Float64MultiArray(layout=state_layout(ctrl.names, ctrl.net.N))
        self.idle = self.driver.idle  # runtime.spin_hot calls it every executor period
        subs = [self.create_subscription(Clock, "/clock", self._on_clock, 100),
                self.create_subscription(Imu, "/imu", self._on_imu, 100)]
        for i, (side, frame) in enumerate(FOOT_LOAD_FRAMES):
            subs.append(self.create_subscription(
                WrenchStamped, f"/foot_load/{side}",
                lambda msg, i=i, frame=frame: self._on_load(i, frame, msg), 100))
        # /cmd_vel in the hot path too: a Twist is timed by the tick it arrives at (it has no stamp), so it
        # must not wait in the executor's queue (one callback per executor_period)
        subs.append(self.create_subscription(Twist, "/cmd_vel", self._on_cmd_vel, 10))
        subs.append(self.create_subscription(Bool, "/sim/servo_hold", lambda msg: self.driver.servo_hold(
            msg.data), QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.TRANSIENT_LOCAL)))
        self.hot = HotPath(self, subs)
        self._diagnostics(0, "converged", {})
        d = self.driver
        self.get_logger().info(f"CPG N={ctrl.net.N} from {self.origin}; recording's opening steps to "
                               f"{d.source.handover:.3f} s, CPG from {d.walk_from_s:.3f} s")

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
            return self._drop("/imu", exc)
        self.driver.sample(0, stamp_ns(msg), value)

    def _on_load(self, i: int, frame: str, msg: WrenchStamped) -> None:
        try:
            value = validate_load(msg.header.frame_id, frame, msg.wrench.force.z)
        except ValueError as exc:
            return self._drop(f"/foot_load/{FOOT_LOAD_FRAMES[i][0]}", exc)
        self.driver.sample(1 + i, stamp_ns(msg), value)

    def _drop(self, topic: str, exc: ValueError) -> None:
        self.driver.dropped("sensors_dropped")
        self.throttle.warn(self, topic + " " + reason_key(exc), f"dropped {topic}: {exc}")

    def _on_cmd_vel(self, msg: Twist) -> None:
        lin, ang = msg.linear, msg.angular
        try:
            check_twist(lin.x, ang.z, (lin.y, lin.z, ang.x, ang.y))
        except ValueError as exc:
            self.driver.cmd_vel_counts["dropped"] += 1
            self.throttle.warn(self, "/cmd_vel " + reason_key(exc), f"dropped /cmd_vel: {exc}")
            return
        self.driver.twist(lin.x, ang.z)

    # ---------------------------------------------------------------- parameters
    def _on_set(self, params) -> SetParametersResult:
        """Validate every parameter of the request, then apply them all (between ticks: the callback runs
        in the node's one thread). A refusal's reason names the parameter."""
        d = self.driver
        values = {prm.name: prm.value for prm in params}
        modulation = {n: values[n] for n in ("zeta", "alpha") if n in values}
        try:
            for name, value in modulation.items():
                if reason := modulation_error(name, value):
                    raise ValueError(reason)
            pathways = cpg_params.pathway_list(values["feedback_pathways"]) \
                if "feedback_pathways" in values else None
            for name, (lo, hi) in cpg_params.FEEDBACK_RANGES.items():
                if name in values:
                    check_finite_scalar(name, values[name], lo, hi)
            fb = d.source.fb
            fields = cpg_params.config_fields()
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
        arr.header.stamp = stamp(t_ns)
        self.diag_pub.publish(arr)

    def on_exit(self) -> None:
        d = self.driver
        exit_log(self, "stats " + json.dumps({**d.summary(), "gc": gc_summary(self),
                                              "horizon_work": latency_summary(d.horizon_work)}))


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("cpg_node", "The learned humanoid CPG: /joint_targets on /clock, zeta/alpha modulation.",
                     INTERFACE, argv)
    return run_main(argv, CPGNode)


if __name__ == "__main__":
    raise SystemExit(main())
