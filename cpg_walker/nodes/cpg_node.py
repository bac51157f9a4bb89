"""cpg_node: the learned humanoid CPG as a ROS node (``ros2 run cpg_walker cpg_node``).

Thin wiring around ``walker.gait_source.CPGGaitSource``: on every ``/clock`` tick it advances the CPG to the
tick's sim time and publishes ``/joint_targets`` stamped with it, and (``lookahead``) also the next
period's target, exactly like target_player_node, so lockstep runs stay deterministic. ``zeta``/``alpha``
are the oscillators' modulation commands (HumanoidCPG's smoothed ζ/α), never a scaling of the output.
Every ``horizon_step`` of sim time it also publishes the next ``horizon`` seconds of targets, and then
``horizon_stop`` seconds in which the stepping dies out (a foreseen stop: where pid_node goes if this node
dies), as
``/joint_trajectory`` (``CPGGaitSource.forecast``: the CPG stepped ahead on a copy of its state), which
pid_node follows when the live targets are late; the live targets are unaffected by it. Its points are
at every tick until the next message is due (a target late by a few ticks is then on a point: what the
tick would have sent), then every ``horizon_step``.

Sensory feedback (``feedback``, walker/feedback.py through ``FeedbackGaitSource``): the node subscribes
/imu and /foot_load/{left,right} and, on every new tick t, feeds the samples to the source
(``observe``) before it computes the tick's targets. In ``lockstep`` it waits for the samples stamped t
(up to ``sensor_wait`` wall s), so the target stamped t + period depends on the state stamped t only
(bit-reproducible); otherwise it takes the newest samples. Stale or missing samples (none newer than
``sensor_timeout`` sim s) fade the pathways' weight out over ``feedback_fade`` sim s (`FeedbackFade`),
and back in when samples return; malformed ones are dropped with a throttled warning. The horizon's
forecast holds the feedback g of the last step (`CPGNetwork.forecast`) and foresees no reset.
"""

from __future__ import annotations

import inspect
import json
import math
import time
from collections import deque
from dataclasses import asdict, fields
from typing import get_type_hints

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
    CLOCK_JUMP_NS,
    ActivityStats,
    HotPath,
    StampGuard,
    Throttle,
    TickStats,
    bool_param,
    declare,
    declare_scheduling,
    exit_log,
    float_param,
    gc_summary,
    int_param,
    latency_summary,
    packaged_parameters,
    parse_cli,
    run_main,
    str_param,
    strs_param,
)
from cpg_walker.nodes.validation import check_finite_scalar, reason_key, to_ns, validate_imu, validate_load
from cpg_walker.walker import feedback as feedback_core
from cpg_walker.walker import storage
from cpg_walker.walker.cmd_vel import (
    LIMIT_KEYS,
    CmdVelFollower,
    CmdVelLimits,
    CmdVelOutput,
    SpeedMap,
    apply_output,
    check_twist,
)
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE, HumanoidCPG, modulation_error
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig, FeedbackController
from cpg_walker.walker.gait_source import FeedbackGaitSource, _smootherstep, stop_fade
from cpg_walker.walker.learning import load_controller

STATE_FIELDS = ("phase_rad", "frequency_hz", "amplitude_rad")

INTERFACE = """\
subscribes: /clock (rosgraph_msgs/Clock), /imu (sensor_msgs/Imu, frame 'imu': orientation + angular
  velocity), /foot_load/left and /foot_load/right (geometry_msgs/WrenchStamped, sole frames: force.z =
  sole load N) - the sensors of the feedback pathways, on sim time; /cmd_vel (geometry_msgs/Twist):
  followed from its first message on (cmd_vel.follow): linear.x -> zeta/alpha through the measured speed
  map, angular.z -> the heading pathway's turn rate; no message for cmd_vel.timeout sim s -> alpha 0
  (stands), the next resumes; a sign change of linear.x stops stepping before zeta changes sign;
  /sim/servo_hold (std_msgs/Bool, latched): on its release the gait re-enters from the standing crouch
publishes:
  /joint_targets (sensor_msgs/JointState): position + velocity of all 25 joints (the 10 CPG DOFs; the
    others follow the recording, then hold its mean), stamped with the tick (and with lookahead the next)
  /cpg/state (std_msgs/Float64MultiArray, every monitor_period of sim time): layout dims
    [dof (10, names in the dof label), oscillator (N + 1), value (3)]; rows 0..N-1 of a DOF are its
    oscillators' [phase rad, frequency Hz (with zeta), amplitude rad (gain*alpha)], row N is the DOF's
    output [target q rad, target qd rad/s, offset rad]
  /joint_trajectory (trajectory_msgs/JointTrajectory, every horizon_step of sim time): the targets of
    all 25 joints (positions, velocities) at stamp + every tick period up to horizon_step, then
    every horizon_step up to horizon (the forecast), then on to horizon + horizon_stop with the steps
    dying out to the gait's standing posture (alpha -> 0: the stop pid_node follows if this node dies)
  /diagnostics (diagnostic_msgs/DiagnosticArray, every monitor_period): status 'cpg_walker/cpg' with
    state (learning | converged | starting | walking), zeta, alpha (commanded and applied), N, overruns,
    feedback (off | active | fading | stale), feedback_weight, sensor_age_s, sensors_dropped, clock_dropped
parameters: cpg_file (learned YAML; '' = learn at start-up), n_oscillators (N when learning; 0 = the
  learning settings'), zeta [-2, 2] and alpha [0, 2] (settable at run time), lookahead, monitor_period
  (sim s), horizon, horizon_stop and horizon_step (sim s; horizon 0 = no /joint_trajectory),
  rejoin_settle (sim s a node joining a running sim stands by, realtime), realtime_priority, nice,
  cpu_affinity (OS scheduling); feedback (bool), feedback_pathways (names from walker/feedback.py; default:
  the feedback core's),
  feedback.<field> for every FeedbackConfig field (defaults: config/feedback.yaml), sensor_timeout and
  feedback_fade (sim s), sensor_wait (wall s) - all settable at run time, validated; lockstep (wait for
  each tick's sensor samples); cmd_vel.follow, cmd_vel.timeout (sim s), cmd_vel.max_linear_x,
  cmd_vel.min_linear_x (m/s), cmd_vel.max_angular_z (rad/s), cmd_vel.stand_below (m/s),
  cmd_vel.alpha_fall_rate (per sim s: alpha falls at most this fast), cmd_vel.speed_map (file) - settable
  at run time, validated; a zeta/alpha set while following /cmd_vel holds until the next /cmd_vel message.
  /diagnostics adds cmd_vel (off | waiting | following | standing
  | reversing | ramping | timed_out | parameters), the last command, its zeta/alpha/turn rate,
  cmd_vel_turn (ok, or why angular.z cannot turn: feedback off, no heading pathway, standing; WARN)"""

#: The float ``cmd_vel.*`` parameters: (key, description, min, max); their values: config/cpg.yaml.
CMD_VEL_PARAMS = (
    ("timeout", "sim s without a /cmd_vel message before stepping stops (alpha -> 0)", 0.01, 60.0),
    ("max_linear_x", "largest forward linear.x followed (m/s; larger is clamped)", 0.0, 1.0),
    ("min_linear_x", "most negative (backward) linear.x followed (m/s; smaller is clamped)", -1.0, 0.0),
    ("max_angular_z", "largest |angular.z| followed (rad/s; larger is clamped)", 0.0, 1.0),
    ("stand_below", "|linear.x| below this (m/s): stand (alpha 0)", 0.0, 0.1),
    ("alpha_fall_rate", "the alpha command falls at most this much per sim s (a stop takes 1/rate s)",
     0.01, 100.0),
)
assert tuple(k for k, *_ in CMD_VEL_PARAMS) == LIMIT_KEYS


def load_speed_map(name: object) -> SpeedMap:
    """``cmd_vel.speed_map``'s file as a SpeedMap, else ValueError with the reason."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"cmd_vel.speed_map must name a speed map file, got {name!r}")
    try:
        return SpeedMap.load(name)
    except FileNotFoundError as exc:
        raise ValueError(f"cmd_vel.speed_map: {exc}") from None


def turn_unavailable(enabled: bool, weight: float, pathways: tuple[str, ...]) -> str:
    """Why angular.z cannot turn the robot ('' if it can): turning is the heading feedback pathway."""
    if "heading" not in pathways:
        return "the heading feedback pathway is not in feedback_pathways"
    if not enabled:
        return "feedback is off"
    if weight <= 0.0:
        return "feedback has faded out (stale sensors)"
    return ""


#: Sensor samples kept per topic, by stamp (lockstep takes the one stamped like its tick).
SENSOR_KEEP = 32
#: FeedbackConfig field types exposed as ROS parameters, and their parameter descriptors' makers.
FIELD_PARAMS = {float: float_param, str: str_param, bool: bool_param}


def observe(source: FeedbackGaitSource, t: float, quat_wxyz: np.ndarray, gyro: np.ndarray,
            loads: tuple[float, float]) -> None:
    """One tick's sensor samples to the source: ``observe(t, quat_wxyz, gyro, loads)`` (the feedback
    core's interface); a core that still takes ``observe(t, tilt, loads)`` gets the (roll, pitch) tilt of
    the orientation (robot.hoap2.tilt_from_quat). The one place that knows both."""
    if _QUAT_OBSERVE:
        source.observe(t, quat_wxyz, gyro, loads)
    else:
        from cpg_walker.robot.hoap2 import tilt_from_quat

        source.observe(t, tilt_from_quat(quat_wxyz), loads)


_QUAT_OBSERVE = "gyro" in inspect.signature(FeedbackGaitSource.observe).parameters


def configure(fb: FeedbackController, cfg: FeedbackConfig, pathways: tuple[str, ...]) -> None:
    """Give a running FeedbackController new constants and pathways between ticks (its ``set_config`` /
    ``set_pathways`` where the core has them)."""
    if hasattr(fb, "set_config") and hasattr(fb, "set_pathways"):
        fb.set_config(cfg)
        fb.set_pathways(pathways)
        return
    if hasattr(fb, "tilt"):
        fb.tilt.T = float(cfg.tilt_time_constant_s)
    fb.cfg, fb.pathways = cfg, tuple(pathways)


def pathway_list(value: object) -> tuple[str, ...]:
    """``feedback_pathways`` as a tuple of known, distinct names, else ValueError with the reason (the
    feedback core's ``check_pathways`` where it has one: its rules too)."""
    names = [str(v) for v in (value or [])]
    if not names:
        raise ValueError(f"feedback_pathways must name at least one of {list(PATHWAYS)} (feedback false: "
                         "none)")
    bad = [n for n in names if n not in PATHWAYS]
    if bad:
        raise ValueError(f"unknown feedback pathway(s) {bad}; choose from {list(PATHWAYS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"feedback_pathways names a pathway twice: {names}")
    return tuple(feedback_core.check_pathways(names))


def default_pathway_names() -> tuple[str, ...]:
    """The pathways ``feedback_pathways`` defaults to: config/feedback.yaml's ``pathways`` (the one home)."""
    return tuple(feedback_core.default_pathways())


def config_fields() -> dict[str, type]:
    """FeedbackConfig's fields and their types (the ``feedback.<field>`` parameters)."""
    hints = get_type_hints(FeedbackConfig)
    return {f.name: hints.get(f.name, object) for f in fields(FeedbackConfig)}


class FeedbackFade:
    """The weight w in [0, 1] of the feedback pathways. A ramp u moves at 1/``fade_s`` per sim s towards 1
    while feedback is on and the newest sensor sample is at most ``timeout_s`` sim s old, towards 0
    otherwise (``fade_s`` 0: at once); w = 6u^5 - 15u^4 + 10u^3 (smootherstep: w, dw/dt continuous, flat
    at both ends). Starts at 0: feedback fades in once the first samples are there."""

    def __init__(self, fade_s: float, timeout_s: float) -> None:
        self.fade_s, self.timeout_s = float(fade_s), float(timeout_s)
        self.u = 0.0
        self.weight = 0.0
        self.fresh = False

    def update(self, dt_s: float, enabled: bool, age_s: float | None) -> float:
        """Advance by ``dt_s`` sim s; ``age_s``: the newest sample's age (None: no sample yet)."""
        self.fresh = age_s is not None and age_s <= self.timeout_s
        want = 1.0 if enabled and self.fresh else 0.0
        if self.fade_s <= 0:
            self.u = want
        elif self.u < want:
            self.u = min(want, self.u + dt_s / self.fade_s)
        elif self.u > want:
            self.u = max(want, self.u - dt_s / self.fade_s)
        self.weight = _smootherstep(self.u)[0]
        return self.weight

    def state(self, enabled: bool) -> str:
        """off (disabled, faded out) | active (on, fresh samples; fading in while w < 1) | fading (w > 0
        going to 0: stale samples, or just turned off) | stale (on, no fresh samples, w = 0)."""
        if enabled and self.fresh:
            return "active"
        if self.weight > 0:
            return "fading"
        return "stale" if enabled else "off"


class SensorBuffer:
    """The last SENSOR_KEEP samples of one sensor topic, by stamp (ns)."""

    def __init__(self) -> None:
        self.samples: dict[int, object] = {}
        self.newest_ns: int | None = None

    def add(self, t_ns: int, value: object) -> None:
        self.samples[t_ns] = value
        if self.newest_ns is None or t_ns > self.newest_ns:
            self.newest_ns = t_ns
        if len(self.samples) > SENSOR_KEEP:
            del self.samples[min(self.samples)]

    def newest(self) -> tuple[int, object] | None:
        return None if self.newest_ns is None else (self.newest_ns, self.samples[self.newest_ns])


#: The start-up warm-up commands this fraction of the current zeta/alpha (0.9 of 0 is 0: then this value
#: itself), so the modulation filters move too while the compiled kernels load.
WARM_UP_COMMAND = 0.9
#: A first /clock tick later than this (sim s) means the node joined a running sim (restarted, or started
#: late): it re-enters the gait from the standing crouch (CPGGaitSource.reenter) instead of playing the
#: recording's opening steps from t = 0.
REJOIN_AFTER_S = 0.1
#: Targets kept by stamp, to re-send a re-sent tick's targets identically.
RECENT_KEEP = 4


def state_layout(names, n_osc: int):
    """The MultiArrayLayout of /cpg/state (see INTERFACE)."""
    b, m = len(names), n_osc + 1
    return MultiArrayLayout(dim=[
        MultiArrayDimension(label="dof:" + ",".join(names), size=b, stride=b * m * 3),
        MultiArrayDimension(label=f"oscillator(0..{n_osc - 1}),output({n_osc})", size=m, stride=m * 3),
        MultiArrayDimension(label="phase_rad|frequency_hz|amplitude_rad;output:q|qd|offset", size=3,
                            stride=3),
    ], data_offset=0)


def state_vector(ctrl):
    """/cpg/state's data: (B, N + 1, 3) flattened, from the controller's current network state."""
    net = ctrl.net
    q, qd = ctrl.joint_targets()
    osc = np.stack([net.phases(), net.frequencies() / (2 * math.pi), np.abs(net.amplitudes())], axis=-1)
    out = np.stack([q, qd, net.offset], axis=-1)[:, None, :]
    return np.concatenate([osc, out], axis=1).ravel()


class CPGNode(Node):
    """Wires parameters and topics to a CPGGaitSource. ``stage``: the node's lifecycle as reported on
    /diagnostics (learning -> converged -> starting -> walking); not an oscillator phase θ.
    ``node_options`` go to rclpy's Node (``cli_args``, ``context``)."""

    def __init__(self, **node_options) -> None:
        super().__init__("cpg", **node_options)
        cpg_file = declare(self, "cpg_file", str_param(
            "learned CPG YAML (a path, or a name in the package's config/); '' = learn at start-up",
            read_only=True))
        n_osc = declare(self, "n_oscillators", int_param(
            "oscillators per DOF when learning at start-up (0 = the learning settings' N)", 0, 20,
            read_only=True))
        zeta = declare(self, "zeta", float_param("frequency ratio ζ of the oscillators (negative: backwards)",
                                                 *ZETA_RANGE))
        alpha = declare(self, "alpha", float_param("amplitude (step length) scale α of the oscillators",
                                                   *ALPHA_RANGE))
        self.lookahead = bool(declare(self, "lookahead", bool_param(
            "also send the next period's target on each tick", read_only=True)))
        self.monitor_ns = round(declare(self, "monitor_period", float_param(
            "sim s between /cpg/state and /diagnostics messages", 0.002, 60.0, read_only=True)) * 1e9)
        self.scheduling = declare_scheduling(self)  # applied once started (runtime.settle_process)
        horizon = declare(self, "horizon", float_param(
            "sim s of future targets in each /joint_trajectory (0 = none published)", 0.0, 5.0,
            read_only=True))
        self.horizon_step_ns = round(declare(self, "horizon_step", float_param(
            "sim s between /joint_trajectory points and between messages", 0.002, 1.0,
            read_only=True)) * 1e9)
        horizon_stop = declare(self, "horizon_stop", float_param(
            "sim s after the horizon over which its stepping dies out (alpha -> 0): where pid_node goes when "
            "this node is gone", 0.0, 10.0, read_only=True))
        self.rejoin_settle_ns = round(declare(self, "rejoin_settle", float_param(
            "sim s a node that joined a running sim (realtime pacing) stands by before it re-enters the gait "
            "(pid_node holds the crouch meanwhile); lockstep re-enters at once", 0.0, 10.0,
            read_only=True)) * 1e9)
        self.join_seen_ns: int | None = None  # the first tick of a running sim, while standing by
        n_points = round((horizon + horizon_stop) * 1e9 / self.horizon_step_ns)
        if horizon > 0 and round(horizon * 1e9 / self.horizon_step_ns) < 1:
            raise ValueError(f"horizon ({horizon} s) must be 0 or at least horizon_step")
        # the coarse points (step to horizon + horizon_stop); the tick-spaced head is added once the tick
        # period is known
        self.horizon_ns = np.arange(1, n_points + 1, dtype=np.int64) * self.horizon_step_ns if horizon > 0 \
            else None
        self.horizon_s, self.horizon_stop_s = float(horizon), float(horizon_stop)
        for name, value in (("zeta", zeta), ("alpha", alpha)):
            reason = modulation_error(name, value)
            if reason:
                raise ValueError(reason)
        fb_cfg, pathways = self._declare_feedback()
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.state_pub = self.create_publisher(Float64MultiArray, "/cpg/state", 10)
        self.pub = self.create_publisher(JointState, "/joint_targets", 10)
        self.traj_pub = self.create_publisher(JointTrajectory, "/joint_trajectory", 5)
        self.timing = TickStats()
        self.stage = "learning"
        self.ctrl, self.origin, self.converged = self._controller(cpg_file, n_osc or None)
        self.learned = storage.to_dict(self.ctrl)  # the loaded network, to start over from (a sim reset)
        self._new_source(FeedbackController(fb_cfg, pathways), zeta, alpha)
        self._declare_cmd_vel(zeta)
        self._warm_up()
        self.stage = "converged"
        self.add_on_set_parameters_callback(self._on_set)
        self.next_monitor_ns = 0
        self.last_tick_ns: int | None = None
        self.sent_ns: int | None = None
        self.recent: dict[int, tuple] = {}  # last published targets by stamp (re-sent ticks)
        self.builder = JointStateBuilder(self.source.names, fields=("position", "velocity"))
        self.next_horizon_ns = 0
        self.horizon_work: deque[float] = deque(maxlen=10_000)  # wall s per horizon (the newest: flat memory)
        self.traj_builder: JointTrajectoryBuilder | None = None
        self.traj_offsets_ns: np.ndarray | None = None
        self.traj_fade: np.ndarray | None = None
        self.traj_period_ns: int | None = None
        self.tick_ns: int | None = None  # the smallest step seen between /clock ticks
        self.state_msg = Float64MultiArray(layout=state_layout(self.ctrl.names, self.ctrl.net.N))
        self.activity = ActivityStats()
        self.monitor_due: tuple[int, np.ndarray, dict[str, str]] | None = None
        self.idle = self._idle
        self.throttle = Throttle(1.0)
        self.imu = SensorBuffer()
        self.loads = [SensorBuffer() for _ in FOOT_LOAD_FRAMES]
        self.buffers = [self.imu, *self.loads]
        self.waiting: deque[tuple[int, float]] = deque()  # lockstep: ticks waiting for their samples
        self.sensors_gave_up = False  # a lockstep wait timed out: no waiting until the samples catch up
        self.sensor_stats = {"dropped": 0, "wait_timeouts": 0, "clock_dropped": 0, "targets_withheld": 0}
        self.clock_guard = StampGuard()  # a tick far from the last awaits confirmation
        self.clock_resets = 0
        self.fb_state = self.fade.state(self.fb_enabled)
        self.fb_age: float | None = None
        subs = [self.create_subscription(Clock, "/clock", self._on_clock, 100),
                self.create_subscription(Imu, "/imu", self._on_imu, 100)]
        for i, (side, frame) in enumerate(FOOT_LOAD_FRAMES):
            subs.append(self.create_subscription(
                WrenchStamped, f"/foot_load/{side}",
                lambda msg, i=i, frame=frame: self._on_load(i, frame, msg), 100))
        # /cmd_vel in the hot path too: a Twist is timed by the tick it arrives at (it has no stamp), so it
        # must not wait in the executor's queue (one callback per executor_period)
        subs.append(self.create_subscription(Twist, "/cmd_vel", self._on_cmd_vel, 10))
        self.servos_held = self.reenter_pending = False  # the sim's servos hold: re-enter on release
        self.reentries = 0
        subs.append(self.create_subscription(Bool, "/sim/servo_hold", self._on_servo_hold, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)))
        self.hot = HotPath(self, subs)
        self._diagnostics(0)
        self.get_logger().info(f"CPG N={self.ctrl.net.N} from {self.origin}; recording's opening steps "
                               f"to {self.source.handover:.3f} s, CPG from {self.walk_from_s:.3f} s")

    def _new_source(self, fb: FeedbackController, zeta: float, alpha: float) -> None:
        """The target source: the recording's opening steps from t = 0, then the CPG."""
        fb.weight = self.fade.weight
        self.source = FeedbackGaitSource(self.ctrl, fb, zeta=zeta, alpha=alpha)
        self.source.keep_traces = False  # plots' traces: a node's memory stays flat
        self.walk_from_s = self.source.handover + self.source.blend
        self.rejoined_at_s: float | None = None

    def _rejoin(self, t_ns: int, why: str = "joined a running sim") -> None:
        """Re-enter the gait at t_ns from the standing crouch, alpha ramping up from 0
        (CPGGaitSource.reenter; the parameters' zeta/alpha are commanded): the first tick is later than
        REJOIN_AFTER_S, or the sim's servos held the robot while the CPG went on (a controller was lost)."""
        zeta, alpha = self.get_parameter("zeta").value, self.get_parameter("alpha").value
        self.source.reenter(t_ns / 1e9, zeta, alpha)
        self.next_horizon_ns = 0  # a horizon of the re-entered gait at once: pid_node must not fall back
        # on the last one, the gait before the re-entry, when a target is late (seen: 128 switches
        # between the two in 1.3 s after a servo release, and a fall)
        self.recent.clear()
        self.walk_from_s = self.source.handover + self.source.blend
        self.rejoined_at_s = t_ns / 1e9
        self.reentries += 1
        self.get_logger().info(
            f"{why} at {t_ns / 1e9:.3f} s: re-entering the gait from the standing crouch "
            f"(CPG from phase 0, alpha ramping up from 0 to {alpha:g}, cross-fade over "
            f"{self.source.blend:g} s; walking from {self.walk_from_s:.3f} s)")

    def _on_servo_hold(self, msg: Bool) -> None:
        """/sim/servo_hold: while the servos hold the robot by themselves (no torques: pid_node lost) the
        CPG goes on stepping, so the gait's phase no longer matches the frozen robot; tracking it again
        from mid-stride fell in 7 of 11 in-process runs. On release the gait re-enters from the crouch."""
        if msg.data and not self.servos_held:
            self.servos_held = True
            self.get_logger().warn("the sim's servos hold the robot (no torques): the gait re-enters from "
                                   "the standing crouch when they are released")
        elif not msg.data and self.servos_held:
            self.servos_held, self.reenter_pending = False, True

    def _clock_reset(self, t_ns: int) -> None:
        """/clock went back by more than CLOCK_RESET_S (a restarted sim): start over from the loaded
        network, as a fresh node would (its first tick at t_ns)."""
        old = self.last_tick_ns
        self.get_logger().warn(f"/clock went back from {old / 1e9:.3f} s to {t_ns / 1e9:.3f} s (sim "
                               "restarted): starting the CPG over")
        self.ctrl = storage.from_dict(self.learned)
        fb = self.source.fb
        self.fade.u = self.fade.weight = 0.0
        self._new_source(FeedbackController(fb.cfg, fb.pathways), self.get_parameter("zeta").value,
                         self.get_parameter("alpha").value)
        self.last_tick_ns = self.sent_ns = None
        self.recent.clear()
        self.next_monitor_ns = self.next_horizon_ns = 0
        self.waiting.clear()
        self.imu = SensorBuffer()
        self.loads = [SensorBuffer() for _ in FOOT_LOAD_FRAMES]
        self.buffers = [self.imu, *self.loads]
        self.sensors_gave_up = False
        self.cmd = CmdVelFollower(self.cmd_map, self.cmd.limits, self.get_parameter("zeta").value)
        self.cmd_out, self.cmd_override = None, False
        self.servos_held = self.reenter_pending = False
        self.join_seen_ns = None
        self.clock_resets += 1

    def _declare_cmd_vel(self, zeta: float) -> None:
        """The ``cmd_vel.*`` parameters (config/cpg.yaml) and the follower (walker/cmd_vel.py)."""
        self.cmd_follow = bool(declare(self, "cmd_vel.follow", bool_param(
            "follow /cmd_vel from its first message on (false: ignore it; zeta/alpha parameters only)")))
        lim = {k: declare(self, f"cmd_vel.{k}", float_param(text, lo, hi))
               for k, text, lo, hi in CMD_VEL_PARAMS}
        limits = CmdVelLimits(**{k: float(v) for k, v in lim.items()})
        map_file = declare(self, "cmd_vel.speed_map", str_param(
            "measured speed vs zeta/alpha for linear.x (a path, or a name in the package's config/)"))
        self.cmd_map = load_speed_map(map_file)
        self.cmd = CmdVelFollower(self.cmd_map, limits, zeta)
        self.cmd_override = False  # a zeta/alpha parameter set while following: holds until the next Twist
        self.cmd_stats = {"received": 0, "dropped": 0, "ignored": 0}
        self.cmd_out = None  # the follower's last output (CmdVelOutput)
        self._cmd_logged: tuple | None = None  # (state, target) last logged
        self.cmd_turn = "ok"  # ok | why angular.z cannot turn the robot

    def _controller(self, cpg_file: str, n: int | None) -> tuple[HumanoidCPG, str, bool]:
        if not cpg_file:
            self._diagnostics(0)
            self.get_logger().info(f"learning the CPG (N={n or 'of the learning settings'}) at start-up ...")
        try:
            return load_controller(cpg_file, n if not cpg_file else None)
        except FileNotFoundError as exc:
            raise ValueError(str(exc)) from None

    def _declare_feedback(self) -> tuple[FeedbackConfig, tuple[str, ...]]:
        """The feedback parameters: ``lockstep``, ``feedback``, ``feedback_pathways``, ``sensor_timeout``,
        ``feedback_fade``, ``sensor_wait`` (config/cpg.yaml), and ``feedback.<field>`` for every
        FeedbackConfig field of a plain type, its default the value in config/feedback.yaml (the one
        home; the node's parameters file may override it). Validated: ValueError with the reason."""
        self.lockstep = bool(declare(self, "lockstep", bool_param(
            "wait for the sensor samples stamped like each /clock tick (deterministic; with the sim's "
            "lockstep pacing)", read_only=True)))
        self.fb_enabled = bool(declare(self, "feedback", bool_param(
            "close the sensory feedback pathways (false: the open-loop CPG)")))
        packaged = packaged_parameters(self)  # a bare start: the packaged params file's overrides
        descriptor = strs_param(f"feedback pathways in use, any of {', '.join(PATHWAYS)}")
        self.declare_parameter("feedback_pathways", list(packaged.get("feedback_pathways",
                                                                      default_pathway_names())), descriptor)
        pathways = pathway_list(self.get_parameter("feedback_pathways").value)
        timeout = check_finite_scalar("sensor_timeout", declare(self, "sensor_timeout", float_param(
            "sim s without a newer /imu or /foot_load sample before feedback fades out", 1e-3, 10.0)),
            1e-3, 10.0)
        fade = check_finite_scalar("feedback_fade", declare(self, "feedback_fade", float_param(
            "sim s over which feedback fades out (stale sensors, switched off) or back in", 0.0, 60.0)),
            0.0, 60.0)
        self.sensor_wait = check_finite_scalar("sensor_wait", declare(self, "sensor_wait", float_param(
            "lockstep: wall s to wait for a tick's sensor samples before going on with the newest",
            1e-3, 60.0)), 1e-3, 60.0)
        self.fade = FeedbackFade(fade, timeout)
        defaults = FeedbackConfig.load()
        self.fb_fields: dict[str, type] = {}
        for name, kind in config_fields().items():
            make = FIELD_PARAMS.get(kind)
            if make is None:
                self.get_logger().warn(f"FeedbackConfig.{name} ({kind}) is not a ROS parameter: only "
                                       f"{', '.join(t.__name__ for t in FIELD_PARAMS)} fields are")
                continue
            self.fb_fields[name] = kind
            default = packaged.get(f"feedback.{name}", getattr(defaults, name))
            self.declare_parameter(f"feedback.{name}", kind(default), make(
                f"FeedbackConfig.{name} (walker/feedback.py; default in config/feedback.yaml)"))
        values = {name: self._field_value(name, self.get_parameter(f"feedback.{name}").value)
                  for name in self.fb_fields}
        return FeedbackConfig.load(**values), pathways

    def _field_value(self, name: str, value: object) -> object:
        """A ``feedback.<name>`` value checked for its field's type (floats finite)."""
        kind = self.fb_fields[name]
        if kind is float:
            return check_finite_scalar(f"feedback.{name}", value)
        if not isinstance(value, kind):
            raise ValueError(f"feedback.{name} must be a {kind.__name__}, got {type(value).__name__}")
        return value

    def _warm_up(self) -> None:
        """Step a copy of the CPG (with the modulation filters moving) a few times: compiled kernels
        are compiled or loaded on first use (about 1 s with numba), which must not happen at the
        hand-over tick mid-walk (in real time the robot would go without targets and fall)."""
        t0 = time.perf_counter()
        spare = storage.from_dict(storage.to_dict(self.ctrl))
        spare.set_zeta(WARM_UP_COMMAND * spare.zeta_command or WARM_UP_COMMAND)
        spare.set_alpha(WARM_UP_COMMAND * spare.alpha_command or WARM_UP_COMMAND)
        for _ in range(3):
            spare.step(self.source.h)
            spare.joint_targets()
        if self.horizon_ns is not None:  # the forecast with the filters moving, then settled
            offsets = np.concatenate(([0.0, self.source.h], self.horizon_ns / 1e9))
            fade = stop_fade(offsets, self.horizon_s, self.horizon_stop_s)
            spare.forecast(offsets, fade)
            spare.set_modulation_state(spare.zeta_command, spare.alpha_command)
            spare.forecast(offsets)
            spare.forecast(offsets, fade)
        state_vector(spare)
        self.get_logger().info(f"CPG warmed up in {time.perf_counter() - t0:.3f} s")

    # ---------------------------------------------------------------- parameters
    def _on_set(self, params) -> SetParametersResult:
        """Validate every parameter of the request, then apply them all (between ticks: the callback runs
        in the node's one thread). A refusal's reason names the parameter (FeedbackConfig's own reason
        for a value it refuses)."""
        changes: dict[str, float] = {}
        fb_changes: dict[str, object] = {}
        cmd_changes: dict[str, object] = {}
        pathways = None
        try:
            for prm in params:
                name, value = prm.name, prm.value
                if name in ("zeta", "alpha"):
                    reason = modulation_error(name, value)
                    if reason:
                        raise ValueError(reason)
                    changes[name] = float(value)
                elif name == "feedback_pathways":
                    pathways = pathway_list(value)
                elif name.startswith("feedback.") and name[len("feedback."):] in self.fb_fields:
                    fb_changes[name[len("feedback."):]] = self._field_value(name[len("feedback."):], value)
                elif name in ("sensor_timeout", "sensor_wait"):
                    check_finite_scalar(name, value, 1e-3, 60.0 if name == "sensor_wait" else 10.0)
                elif name == "feedback_fade":
                    check_finite_scalar(name, value, 0.0, 60.0)
                elif name.startswith("cmd_vel."):
                    cmd_changes[name[len("cmd_vel."):]] = value
            cmd_apply = self._check_cmd_vel(cmd_changes)
            fb = self.source.fb
            cfg = FeedbackConfig.load(**{**asdict(fb.cfg), **fb_changes}) if fb_changes else fb.cfg
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if fb_changes or pathways is not None:
            configure(fb, cfg, pathways if pathways is not None else fb.pathways)
            self.get_logger().info(f"feedback pathways {list(fb.pathways)}"
                                   + (f"; {fb_changes}" if fb_changes else ""))
        for prm in params:
            if prm.name == "feedback":
                self.fb_enabled = bool(prm.value)
                self.get_logger().info(f"feedback {'on' if self.fb_enabled else 'off'} (fading "
                                       f"{'in' if self.fb_enabled else 'out'} over {self.fade.fade_s:g} s)")
            elif prm.name == "sensor_timeout":
                self.fade.timeout_s = float(prm.value)
            elif prm.name == "feedback_fade":
                self.fade.fade_s = float(prm.value)
            elif prm.name == "sensor_wait":
                self.sensor_wait = float(prm.value)
        cmd_apply()
        if changes:
            zeta = changes.get("zeta", self.get_parameter("zeta").value)
            self._command(zeta, changes.get("alpha", self.get_parameter("alpha").value))
            if self.cmd.last is not None and self.cmd_follow:
                self.cmd_override = True  # the parameter holds until the next /cmd_vel message
                self.cmd.zeta = float(zeta) if zeta else self.cmd.zeta
                self._turn(0.0)
                self.get_logger().info("zeta/alpha set while following /cmd_vel: they hold until the next "
                                       "/cmd_vel message")
        return SetParametersResult(successful=True)

    def _check_cmd_vel(self, changes: dict[str, object]):
        """Validate ``cmd_vel.*`` changes (ValueError with the reason); return the function applying them."""
        if not changes:
            return lambda: None
        follow = changes.pop("follow", None)
        if follow is not None and not isinstance(follow, bool):
            raise ValueError(f"cmd_vel.follow must be a bool, got {type(follow).__name__}")
        smap = None
        if "speed_map" in changes:
            smap = load_speed_map(changes.pop("speed_map"))
        limits = self.cmd.limits
        if changes:
            vals = {**limits.as_dict(),
                    **{k: check_finite_scalar(f"cmd_vel.{k}", v) for k, v in changes.items()}}
            limits = CmdVelLimits(**vals)

        def apply() -> None:
            if smap is not None:
                self.cmd.map = self.cmd_map = smap
            self.cmd.set_limits(limits)
            if follow is not None and follow != self.cmd_follow:
                self.cmd_follow = follow
                if not follow and self.cmd.last is not None:
                    self._stop_following("cmd_vel.follow set false")
                self.get_logger().info(f"cmd_vel.follow {str(follow).lower()}")
        return apply

    def _stop_following(self, why: str) -> None:
        """Back to the zeta/alpha parameters; the follower waits for a first message again."""
        zeta, alpha = self.get_parameter("zeta").value, self.get_parameter("alpha").value
        self.cmd = CmdVelFollower(self.cmd_map, self.cmd.limits, zeta)
        self.cmd_out, self.cmd_override = None, False
        self._turn(0.0)
        self._command(zeta, alpha)
        self.get_logger().info(f"{why}: not following /cmd_vel; zeta/alpha parameters again")

    def _turn(self, rate: float) -> None:
        fb = self.source.fb
        if rate == 0.0 and fb.turn_rate != 0.0:
            fb.hold_heading()
        fb.set_turn_rate(rate)

    # ---------------------------------------------------------------- /cmd_vel
    def _on_cmd_vel(self, msg: Twist) -> None:
        lin, ang = msg.linear, msg.angular
        try:
            check_twist(lin.x, ang.z, (lin.y, lin.z, ang.x, ang.y))
        except ValueError as exc:
            self.cmd_stats["dropped"] += 1
            self.throttle.warn(self, "/cmd_vel " + reason_key(exc), f"dropped /cmd_vel: {exc}")
            return
        if not self.cmd_follow:
            self.cmd_stats["ignored"] += 1
            return
        self.cmd_stats["received"] += 1
        t = (self.last_tick_ns or 0) / 1e9  # a Twist has no stamp: received at the newest tick's sim time
        if self.cmd.last is None:
            self.get_logger().info(f"following /cmd_vel from sim {t:.3f} s (timeout "
                                   f"{self.cmd.limits.timeout:g} sim s)")
        self.cmd_override = False
        self.cmd.command(t, float(lin.x), float(ang.z))

    def _cmd_vel_tick(self, t_ns: int) -> None:
        """Apply the follower's output for tick t_ns (once the CPG has taken over)."""
        if self.cmd.last is None or self.cmd_override or t_ns < self.walk_from_s * 1e9:
            return
        out = self.cmd.update(t_ns / 1e9, self.ctrl.zeta, self.ctrl.alpha)
        if out is None:
            return
        prev = self.cmd_out
        fb = self.source.fb
        reason = turn_unavailable(self.fb_enabled, self.fade.weight, fb.pathways)
        want = self.cmd.limits.clamp_angular(self.cmd.last[2])
        self.cmd_turn = reason if reason and want != 0.0 else "ok"
        if reason and out.turn_rate != 0.0:
            out = CmdVelOutput(out.zeta, out.alpha, 0.0, out.state)
        if reason and want != 0.0:
            self.throttle.warn(self, "/cmd_vel turn", f"/cmd_vel angular.z {want:g} rad/s cannot turn the "
                               f"robot: {reason}")
        if want != 0.0 and out.state == "standing":
            self.cmd_turn = "cannot turn in place (stands: |linear.x| < cmd_vel.stand_below)"
            self.throttle.warn(self, "/cmd_vel turn in place", f"/cmd_vel angular.z {want:g} rad/s with "
                               "linear.x ~ 0: the robot turns only while stepping; it stands")
        apply_output(self.ctrl, fb, out)
        key = (out.state, self.cmd.target)  # not each tick of an alpha ramp: a new state or command
        if prev is None or key != self._cmd_logged:
            self.get_logger().info(f"/cmd_vel {out.state}: zeta {out.zeta:.3g}, alpha {out.alpha:.3g}, turn "
                                   f"{out.turn_rate:.3g} rad/s at sim {t_ns / 1e9:.3f} s")
            self._cmd_logged = key
        self.cmd_out = out

    def _cmd_vel_values(self, t_ns: int) -> dict[str, str]:
        """The /cmd_vel part of /diagnostics."""
        c = self.cmd
        if not self.cmd_follow:
            state = "off"
        elif c.last is None:
            state = "waiting"
        elif self.cmd_override:
            state = "parameters"
        else:
            state = c.state
        v = {"cmd_vel": state, "cmd_vel_received": str(self.cmd_stats["received"]),
             "cmd_vel_dropped": str(self.cmd_stats["dropped"]), "cmd_vel_turn": self.cmd_turn}
        if c.last is not None:
            v.update({"cmd_vel_linear_x": f"{c.last[1]:g}", "cmd_vel_angular_z": f"{c.last[2]:g}",
                      "cmd_vel_age_s": f"{max(0.0, t_ns / 1e9 - c.last[0]):.3f}"})
        if self.cmd_out is not None:
            o = self.cmd_out
            v.update({"cmd_vel_zeta": f"{o.zeta:.6g}", "cmd_vel_alpha": f"{o.alpha:.6g}",
                      "cmd_vel_turn_rate": f"{o.turn_rate:.6g}"})
        return v

    def _command(self, zeta: float, alpha: float) -> None:
        """Before the CPG has taken over, the command waits for the end of the cross-fade."""
        src = self.source
        if src._t_net < self.walk_from_s:
            src.schedule = [(self.walk_from_s, zeta, alpha)]
        else:
            self.ctrl.set_zeta(zeta)
            self.ctrl.set_alpha(alpha)
        after = (self.last_tick_ns or 0) / 1e9 if src._t_net >= self.walk_from_s else self.walk_from_s
        self.get_logger().info(f"commanded zeta={zeta:g}, alpha={alpha:g} after sim {after:.3f} s")

    # ---------------------------------------------------------------- clock
    def _on_clock(self, msg: Clock) -> None:
        t_ns = to_ns(msg.clock.sec, msg.clock.nanosec)
        if t_ns < 0:  # sim time starts at 0: malformed, not a restarted sim
            self.sensor_stats["clock_dropped"] += 1
            self.throttle.warn(self, "/clock negative", f"dropped /clock {t_ns / 1e9:.9g} s: before 0")
            return
        verdict = self._clock_jump(t_ns)
        if verdict == StampGuard.DROP:
            return
        if verdict == StampGuard.RESET:
            self._clock_reset(t_ns)
        if self.last_tick_ns is None and not self.waiting and t_ns > REJOIN_AFTER_S * 1e9 \
                and self.rejoined_at_s is None:
            if self._standing_by(t_ns):
                return
            self._rejoin(t_ns)
        if self.reenter_pending and self.last_tick_ns is not None:
            self.reenter_pending = False
            self._rejoin(t_ns, "the servos were released")
        if self.last_tick_ns is not None and t_ns <= self.last_tick_ns:
            self._tick(t_ns)  # a re-sent (or old) tick: its targets again, from the cache
            return
        if any(t == t_ns for t, _ in self.waiting):
            return
        self.waiting.append((t_ns, time.monotonic()))
        self._run_waiting()

    def _standing_by(self, t_ns: int) -> bool:
        """Joined a running sim in realtime pacing: publish nothing for ``rejoin_settle`` sim s from the
        first tick (pid_node holds the crouch), so the gait starts once this node's start-up transients
        (its publishers being matched, first calls, a backlog of queued ticks) are over. In lockstep the
        sim waits for every answer: re-enter at once."""
        if self.lockstep or self.rejoin_settle_ns <= 0:
            return False
        seen = self.join_seen_ns
        if seen is not None and not 0 <= t_ns - seen <= self.rejoin_settle_ns + CLOCK_JUMP_NS:
            seen = None  # time went back, or jumped far ahead (a stray stamp: the guard has no tick yet)
        if seen is None:
            if self.join_seen_ns is None:
                self.get_logger().info(f"first /clock tick at {t_ns / 1e9:.3f} s, of a running sim: standing "
                                       f"by {self.rejoin_settle_ns / 1e9:g} s before re-entering the gait")
            self.join_seen_ns = seen = t_ns
        return t_ns - seen < self.rejoin_settle_ns

    def _clock_jump(self, t_ns: int) -> str:
        """The StampGuard's verdict on the tick t_ns (a stray far-future tick would otherwise end the walk,
        every real tick after it looking old; a stray old one would start the CPG over); a drop is
        counted (``clock_dropped``) and warned about, throttled."""
        last = self.last_tick_ns
        verdict = self.clock_guard.judge(last, t_ns)
        if verdict == StampGuard.DROP:
            self.sensor_stats["clock_dropped"] += 1
            self.throttle.warn(self, "/clock jump", f"dropped /clock {t_ns / 1e9:.9g} s: far from the last "
                               f"tick {last / 1e9:.9g} s, unconfirmed")
        return verdict

    def _run_waiting(self) -> None:
        """Run the queued ticks, in order, whose sensor samples are there (or need not be waited for)."""
        while self.waiting:
            t_ns, since = self.waiting[0]
            if not self._sensors_ready(t_ns, since):
                return
            self.waiting.popleft()
            self._tick(t_ns)

    def _sensors_ready(self, t_ns: int, since: float) -> bool:
        """Lockstep with feedback on (or fading): the samples stamped t_ns of every sensor topic, waited
        for up to sensor_wait wall s; after a wait timed out, no waiting until the samples catch up with
        the ticks (a dead sensor must not slow every tick down by sensor_wait)."""
        if not self.lockstep or self.sensors_gave_up or not (self.fb_enabled or self.fade.weight > 0):
            return True
        if all(t_ns in b.samples for b in self.buffers):
            return True
        waited = time.monotonic() - since
        if waited <= self.sensor_wait:
            return False
        self.sensors_gave_up = True
        self.sensor_stats["wait_timeouts"] += 1
        self.throttle.warn(self, "sensor wait", f"no /imu and /foot_load samples stamped {t_ns / 1e9:.3f} s "
                           f"after {waited:.2f} wall s: going on with the newest (not reproducible)")
        return True

    # ---------------------------------------------------------------- sensors
    def _on_imu(self, msg: Imu) -> None:
        o, w = msg.orientation, msg.angular_velocity
        try:
            value = validate_imu(msg.header.frame_id, IMU_FRAME, (o.w, o.x, o.y, o.z), (w.x, w.y, w.z))
        except ValueError as exc:
            self._drop("/imu", exc)
            return
        self.imu.add(stamp_ns(msg), value)
        self._sample_arrived()

    def _on_load(self, i: int, frame: str, msg: WrenchStamped) -> None:
        try:
            value = validate_load(msg.header.frame_id, frame, msg.wrench.force.z)
        except ValueError as exc:
            self._drop(f"/foot_load/{FOOT_LOAD_FRAMES[i][0]}", exc)
            return
        self.loads[i].add(stamp_ns(msg), value)
        self._sample_arrived()

    def _drop(self, topic: str, exc: ValueError) -> None:
        self.sensor_stats["dropped"] += 1
        self.throttle.warn(self, topic + " " + reason_key(exc), f"dropped {topic}: {exc}")

    def _sample_arrived(self) -> None:
        if self.sensors_gave_up and self.last_tick_ns is not None and all(
                b.newest_ns is not None and b.newest_ns >= self.last_tick_ns for b in self.buffers):
            self.sensors_gave_up = False  # caught up: wait again
        if self.waiting:
            self._run_waiting()

    def _sample(self, t_ns: int) -> tuple[int, np.ndarray, np.ndarray, tuple[float, float]] | None:
        """(stamp ns, quat, gyro, loads) for the tick t_ns: the samples stamped t_ns when all are there,
        else the newest of each (stamp: the oldest of them); None before every topic has one."""
        if all(t_ns in b.samples for b in self.buffers):
            (quat, gyro), left, right = (b.samples[t_ns] for b in self.buffers)
            return t_ns, quat, gyro, (left, right)
        newest = [b.newest() for b in self.buffers]
        if any(n is None for n in newest):
            return None
        (t_imu, (quat, gyro)), (t_l, left), (t_r, right) = newest
        return min(t_imu, t_l, t_r), quat, gyro, (left, right)

    def _feedback_tick(self, t_ns: int) -> None:
        """Feed the tick's sensor samples to the source and move the fade (before the tick's targets)."""
        dt = 0.0 if self.last_tick_ns is None else (t_ns - self.last_tick_ns) / 1e9
        sample = self._sample(t_ns)
        self.fb_age = None if sample is None else max(0, t_ns - sample[0]) / 1e9
        weight = self.fade.update(dt, self.fb_enabled, self.fb_age)
        self.source.fb.weight = weight
        if sample is not None and (weight > 0 or self.fb_enabled):
            observe(self.source, t_ns / 1e9, sample[1], sample[2], sample[3])
        else:
            self.source.feedback_g = None  # faded out and off: the open-loop CPG
        state = self.fade.state(self.fb_enabled)
        if state != self.fb_state:
            age = "no sample yet" if self.fb_age is None else f"newest sample {self.fb_age:.3f} s old"
            text = f"feedback {self.fb_state} -> {state} at sim {t_ns / 1e9:.3f} s ({age})"
            if state in ("fading", "stale") and self.fb_enabled:
                self.get_logger().warn(text)
            else:
                self.get_logger().info(text)
            self.fb_state = state

    def _tick(self, t_ns: int) -> None:
        """One /clock tick (its samples there, in lockstep): feedback, targets, horizon, monitoring."""
        w0 = time.perf_counter()
        self.activity.tick()
        new = self.last_tick_ns is None or t_ns > self.last_tick_ns
        if new:
            self._cmd_vel_tick(t_ns)
            self._feedback_tick(t_ns)
        if not new or t_ns != self.sent_ns:  # a re-sent tick: its target again (it may have been lost;
            self._publish(t_ns)               # the first tick has no lookahead to cover it)
        period = None
        if self.last_tick_ns is not None and t_ns > self.last_tick_ns:
            period = t_ns - self.last_tick_ns
            if self.lookahead:
                self._publish(t_ns + period)
        if new:
            self.last_tick_ns = t_ns
        if period is not None and (self.tick_ns is None or period < self.tick_ns):
            self.tick_ns = period  # the sim's control period (a skipped tick only gives a multiple)
        if self.horizon_ns is not None and self.tick_ns is not None and t_ns >= self.next_horizon_ns:
            self._publish_horizon(self.sent_ns, self.tick_ns)
            self.next_horizon_ns = t_ns + self.horizon_step_ns
        if t_ns >= self.next_monitor_ns:
            self.stage = "walking" if t_ns >= self.walk_from_s * 1e9 else "starting"
            self._monitor(t_ns)
            self.next_monitor_ns = t_ns + self.monitor_ns
        self.timing.tick(w0, t_ns, time.perf_counter() - w0)  # overrun: work longer than the period

    def _publish(self, t_ns: int) -> None:
        cached = self.recent.get(t_ns)
        if cached is None:
            cached = self.source.targets(t_ns / 1e9)
            self.recent[t_ns] = cached
            if len(self.recent) > 4:
                del self.recent[min(self.recent)]
        q, qd = cached
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):  # never to the servos: pid_node rides
            self.sensor_stats["targets_withheld"] += 1          # the gap on the horizon, then the crouch
            self.throttle.warn(self, "non-finite targets", f"withheld non-finite /joint_targets at sim "
                               f"{t_ns / 1e9:.3f} s ({self.sensor_stats['targets_withheld']} so far)")
            return
        self.pub.publish(self.builder.fill(t_ns, position=q, velocity=qd))
        self.sent_ns = t_ns

    def _publish_horizon(self, t_ns: int, period_ns: int) -> None:
        """/joint_trajectory from t_ns (the newest target sent): points every tick period up to
        horizon_step, then every horizon_step to horizon + horizon_stop; past horizon the forecast's
        stepping dies out (`stop_fade`), so a pid_node that follows it to its end (this node gone) has
        stopped the robot in the gait's standing posture before it blends to the crouch."""
        w0 = time.perf_counter()
        if period_ns != self.traj_period_ns:  # the first message (or a shorter period seen since)
            head = np.arange(0, self.horizon_step_ns, period_ns, dtype=np.int64)
            self.traj_offsets_ns = np.concatenate((head, self.horizon_ns))
            self.traj_fade = stop_fade(self.traj_offsets_ns / 1e9, self.horizon_s, self.horizon_stop_s) \
                if self.horizon_stop_s > 0 else None
            self.traj_builder = JointTrajectoryBuilder(self.source.names, self.traj_offsets_ns.tolist())
            self.traj_period_ns = period_ns
        q, qd = self.source.forecast((t_ns + self.traj_offsets_ns) / 1e9, self.traj_fade)
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            self.sensor_stats["targets_withheld"] += 1
            self.throttle.warn(self, "non-finite horizon", f"withheld a non-finite /joint_trajectory at sim "
                               f"{t_ns / 1e9:.3f} s")
            return
        self.traj_pub.publish(self.traj_builder.fill(t_ns, q, qd))
        if len(self.horizon_work) < 100_000:
            self.horizon_work.append(time.perf_counter() - w0)

    # ---------------------------------------------------------------- monitoring
    def _monitor(self, t_ns: int) -> None:
        """Read /cpg/state's data in the tick (the CPG state of ``t_ns``); publish it and /diagnostics from
        the node's idle step (``idle``: runtime.spin_hot calls it every 20 ms of wall time), so a monitor
        tick costs one state read, not two message builds and publishes (about 150 us of CPU). Without an
        idle step the next monitor tick publishes the pending one first."""
        self._flush_monitor()
        self.monitor_due = (t_ns, state_vector(self.ctrl), {**self._feedback_values(),
                                                             **self._cmd_vel_values(t_ns)})

    def _idle(self) -> None:
        """Every 20 ms of wall time (runtime.spin_hot): a lockstep tick whose samples are late may have
        waited long enough; the pending monitor messages."""
        if self.waiting:
            self._run_waiting()
        self._flush_monitor()

    def _flush_monitor(self) -> None:
        due, self.monitor_due = self.monitor_due, None
        if due is None:
            return
        t_ns, data, feedback = due
        self.state_msg.data = darray(data)
        self.state_pub.publish(self.state_msg)
        self._diagnostics(t_ns, feedback)

    def _feedback_values(self) -> dict[str, str]:
        """The feedback's part of /diagnostics, as of now."""
        fb = self.source.fb
        return {"feedback": self.fb_state, "feedback_enabled": str(self.fb_enabled).lower(),
                "feedback_weight": f"{self.fade.weight:.6g}",
                "sensor_age_s": "none" if self.fb_age is None else f"{self.fb_age:.3f}",
                "feedback_pathways": ",".join(fb.pathways), "phase_resets": str(len(fb.resets)),
                "sensors_dropped": str(self.sensor_stats["dropped"]),
                "sensor_wait_timeouts": str(self.sensor_stats["wait_timeouts"]),
                "clock_dropped": str(self.sensor_stats["clock_dropped"]),
                "targets_withheld": str(self.sensor_stats["targets_withheld"])}

    def _diagnostics(self, t_ns: int, feedback: dict[str, str] | None = None) -> None:
        ok = self.stage != "learning" and getattr(self, "converged", True)
        ctrl = getattr(self, "ctrl", None)
        values = {"state": self.stage, "overruns": str(self.timing.overruns)}
        if ctrl is not None:
            values.update({"zeta_command": f"{ctrl.zeta_command:g}", "zeta": f"{ctrl.zeta:.6g}",
                           "alpha_command": f"{ctrl.alpha_command:g}", "alpha": f"{ctrl.alpha:.6g}",
                           "n_oscillators": str(ctrl.net.N), "cpg_file": self.origin,
                           "learning_converged": str(self.converged).lower()})
        if getattr(self, "source", None) is not None:
            values.update(feedback or self._feedback_values())
        level = DiagnosticStatus.OK if ok or self.stage == "learning" else DiagnosticStatus.WARN
        text = self.stage if ok or self.stage == "learning" else f"{self.stage} (learning not converged)"
        if feedback is not None and feedback["feedback"] in ("fading", "stale") \
                and feedback["feedback_enabled"] == "true":
            level = max(level, DiagnosticStatus.WARN)
            text += f"; feedback {feedback['feedback']} (sensor data {feedback['sensor_age_s']} s old)"
        if feedback is not None and feedback.get("cmd_vel_turn", "ok") != "ok":
            level = max(level, DiagnosticStatus.WARN)
            text += f"; /cmd_vel angular.z cannot turn: {feedback['cmd_vel_turn']}"
        status = DiagnosticStatus(level=level, name="cpg_walker/cpg", message=text, hardware_id="cpg",
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = stamp(t_ns)
        self.diag_pub.publish(arr)

    def on_exit(self) -> None:
        timing = self.timing.summary()
        fb = self.source.fb
        feedback = {"enabled": self.fb_enabled, "state": self.fb_state, "weight": self.fade.weight,
                    "pathways": list(fb.pathways), "phase_resets": len(fb.resets),
                    "phase_reset_times_s": [round(t, 3) for t, _ in fb.resets[:100]], **self.sensor_stats}
        exit_log(self, "stats " + json.dumps({**self.activity.summary(), "overruns": timing["overruns"],
                                              "tick": timing, "gc": gc_summary(self),
                                              "horizon_work": latency_summary(self.horizon_work),
                                              "feedback": feedback, "cmd_vel": self.cmd_stats,
                                              "rejoined_at_s": self.rejoined_at_s,
                                              "reentries": self.reentries,
                                              "clock_resets": self.clock_resets}))



def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("cpg_node", "The learned humanoid CPG: /joint_targets on /clock, zeta/alpha modulation.",
                     INTERFACE, argv)
    return run_main(argv, CPGNode)


if __name__ == "__main__":
    raise SystemExit(main())
