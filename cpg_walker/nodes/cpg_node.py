"""cpg_node: the learned humanoid CPG as a ROS node (``ros2 run cpg_walker cpg_node``).

Thin wiring around ``cpg.humanoid.CPGGaitSource``: on every ``/clock`` tick it advances the CPG to the
tick's sim time and publishes ``/joint_targets`` stamped with it, and (``lookahead``) also the next
period's target, exactly like target_player_node, so lockstep runs stay deterministic. ``zeta``/``alpha``
are the oscillators' modulation commands (HumanoidCPG's smoothed ζ/α), never a scaling of the output.
Every ``horizon_step`` of sim time it also publishes the next ``horizon`` seconds of targets as
``/joint_trajectory`` (``CPGGaitSource.forecast``: the CPG stepped ahead on a copy of its state), which
pid_node follows when the live targets are late; the live targets are unaffected by it. Its points are
at every tick until the next message is due (a target late by a few ticks is then on a point: what the
tick would have sent), then every ``horizon_step``.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from trajectory_msgs.msg import JointTrajectory

from cpg_walker.nodes.messages import JointStateBuilder, JointTrajectoryBuilder, darray, stamp
from cpg_walker.nodes.runtime import (
    ActivityStats,
    HotPath,
    TickStats,
    bool_param,
    declare,
    declare_scheduling,
    exit_log,
    float_param,
    gc_summary,
    int_param,
    latency_summary,
    parse_cli,
    run_main,
    str_param,
)
from cpg_walker.nodes.validation import to_ns
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE, HumanoidCPG, modulation_error
from cpg_walker.walker.gait_source import CPGGaitSource
from cpg_walker.walker.learning import load_controller

STATE_FIELDS = ("phase_rad", "frequency_hz", "amplitude_rad")

INTERFACE = """\
subscribes: /clock (rosgraph_msgs/Clock)
publishes:
  /joint_targets (sensor_msgs/JointState): position + velocity of all 25 joints (the 10 CPG DOFs; the
    others follow the recording, then hold its mean), stamped with the tick (and with lookahead the next)
  /cpg/state (std_msgs/Float64MultiArray, every monitor_period of sim time): layout dims
    [dof (10, names in the dof label), oscillator (N + 1), value (3)]; rows 0..N-1 of a DOF are its
    oscillators' [phase rad, frequency Hz (with zeta), amplitude rad (gain*alpha)], row N is the DOF's
    output [target q rad, target qd rad/s, offset rad]
  /joint_trajectory (trajectory_msgs/JointTrajectory, every horizon_step of sim time): the targets of
    all 25 joints (positions, velocities) at stamp + every tick period up to horizon_step, then
    every horizon_step up to horizon (the forecast)
  /diagnostics (diagnostic_msgs/DiagnosticArray, every monitor_period): status 'cpg_walker/cpg' with
    state (learning | converged | starting | walking), zeta, alpha (commanded and applied), N, overruns
parameters: cpg_file (learned YAML; '' = learn at start-up), n_oscillators (N when learning; 0 = the
  learning settings'), zeta [-2, 2] and alpha [0, 2] (settable at run time), lookahead, monitor_period
  (sim s), horizon and horizon_step (sim s; horizon 0 = no /joint_trajectory), realtime_priority, nice,
  cpu_affinity (OS scheduling)"""

#: The start-up warm-up commands this fraction of the current zeta/alpha (0.9 of 0 is 0: then this value
#: itself), so the modulation filters move too while the compiled kernels load.
WARM_UP_COMMAND = 0.9
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
        n_points = round(horizon * 1e9 / self.horizon_step_ns)
        if horizon > 0 and n_points < 1:
            raise ValueError(f"horizon ({horizon} s) must be 0 or at least horizon_step")
        # the coarse points (step to horizon); the tick-spaced head is added once the tick period is known
        self.horizon_ns = np.arange(1, n_points + 1, dtype=np.int64) * self.horizon_step_ns if horizon > 0 \
            else None
        for name, value in (("zeta", zeta), ("alpha", alpha)):
            reason = modulation_error(name, value)
            if reason:
                raise ValueError(reason)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.state_pub = self.create_publisher(Float64MultiArray, "/cpg/state", 10)
        self.pub = self.create_publisher(JointState, "/joint_targets", 10)
        self.traj_pub = self.create_publisher(JointTrajectory, "/joint_trajectory", 5)
        self.timing = TickStats()
        self.stage = "learning"
        self.ctrl, self.origin, self.converged = self._controller(cpg_file, n_osc or None)
        self.source = CPGGaitSource(self.ctrl, zeta=zeta, alpha=alpha)
        self.walk_from_s = self.source.handover + self.source.blend
        self._warm_up()
        self.stage = "converged"
        self.add_on_set_parameters_callback(self._on_set)
        self.next_monitor_ns = 0
        self.last_tick_ns: int | None = None
        self.sent_ns: int | None = None
        self.recent: dict[int, tuple] = {}  # last published targets by stamp (re-sent ticks)
        self.builder = JointStateBuilder(self.source.names, fields=("position", "velocity"))
        self.next_horizon_ns = 0
        self.horizon_work: list[float] = []
        self.traj_builder: JointTrajectoryBuilder | None = None
        self.traj_offsets_ns: np.ndarray | None = None
        self.traj_period_ns: int | None = None
        self.tick_ns: int | None = None  # the smallest step seen between /clock ticks
        self.state_msg = Float64MultiArray(layout=state_layout(self.ctrl.names, self.ctrl.net.N))
        self.activity = ActivityStats()
        self.monitor_due: tuple[int, np.ndarray] | None = None
        self.idle = self._flush_monitor
        self.hot = HotPath(self, [self.create_subscription(Clock, "/clock", self._on_clock, 100)])
        self._diagnostics(0)
        self.get_logger().info(f"CPG N={self.ctrl.net.N} from {self.origin}; recording's opening steps "
                               f"to {self.source.handover:.3f} s, CPG from {self.walk_from_s:.3f} s")

    def _controller(self, cpg_file: str, n: int | None) -> tuple[HumanoidCPG, str, bool]:
        if not cpg_file:
            self._diagnostics(0)
            self.get_logger().info(f"learning the CPG (N={n or 'of the learning settings'}) at start-up ...")
        try:
            return load_controller(cpg_file, n if not cpg_file else None)
        except FileNotFoundError as exc:
            raise ValueError(str(exc)) from None

    def _warm_up(self) -> None:
        """Step a copy of the CPG (with the modulation filters moving) a few times: compiled kernels
        are compiled or loaded on first use (about 1 s with numba), which must not happen at the
        hand-over tick mid-walk (in real time the robot would go without targets and fall)."""
        t0 = time.perf_counter()
        spare = HumanoidCPG.from_dict(self.ctrl.to_dict())
        spare.set_zeta(WARM_UP_COMMAND * spare.zeta_command or WARM_UP_COMMAND)
        spare.set_alpha(WARM_UP_COMMAND * spare.alpha_command or WARM_UP_COMMAND)
        for _ in range(3):
            spare.step(self.source.h)
            spare.joint_targets()
        if self.horizon_ns is not None:  # the forecast with the filters moving, then settled
            offsets = np.concatenate(([0.0, self.source.h], self.horizon_ns / 1e9))
            spare.forecast(offsets)
            spare.set_modulation_state(spare.zeta_command, spare.alpha_command)
            spare.forecast(offsets)
        state_vector(spare)
        self.get_logger().info(f"CPG warmed up in {time.perf_counter() - t0:.3f} s")

    # ---------------------------------------------------------------- parameters
    def _on_set(self, params) -> SetParametersResult:
        changes = {}
        for prm in params:
            if prm.name in ("zeta", "alpha"):
                reason = modulation_error(prm.name, prm.value)
                if reason:
                    return SetParametersResult(successful=False, reason=reason)
                changes[prm.name] = float(prm.value)
        if changes:
            self._command(changes.get("zeta", self.get_parameter("zeta").value),
                          changes.get("alpha", self.get_parameter("alpha").value))
        return SetParametersResult(successful=True)

    def _command(self, zeta: float, alpha: float) -> None:
        """Before the CPG has taken over, the command waits for the end of the cross-fade."""
        src = self.source
        if src._t_net < self.walk_from_s:
            src.schedule = [(self.walk_from_s, zeta, alpha)]
        else:
            self.ctrl.set_zeta(zeta)
            self.ctrl.set_alpha(alpha)
        self.get_logger().info(f"commanded zeta={zeta:g}, alpha={alpha:g}")

    # ---------------------------------------------------------------- clock
    def _on_clock(self, msg: Clock) -> None:
        w0 = time.perf_counter()
        self.activity.tick()
        t_ns = to_ns(msg.clock.sec, msg.clock.nanosec)
        if t_ns != self.sent_ns:
            self._publish(t_ns)
        period = None
        if self.last_tick_ns is not None and t_ns > self.last_tick_ns:
            period = t_ns - self.last_tick_ns
            if self.lookahead:
                self._publish(t_ns + period)
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
        self.pub.publish(self.builder.fill(t_ns, position=q, velocity=qd))
        self.sent_ns = t_ns

    def _publish_horizon(self, t_ns: int, period_ns: int) -> None:
        """/joint_trajectory from t_ns (the newest target sent): points every tick period up to
        horizon_step, then every horizon_step to horizon."""
        w0 = time.perf_counter()
        if period_ns != self.traj_period_ns:  # the first message (or a shorter period seen since)
            head = np.arange(0, self.horizon_step_ns, period_ns, dtype=np.int64)
            self.traj_offsets_ns = np.concatenate((head, self.horizon_ns))
            self.traj_builder = JointTrajectoryBuilder(self.source.names, self.traj_offsets_ns.tolist())
            self.traj_period_ns = period_ns
        q, qd = self.source.forecast((t_ns + self.traj_offsets_ns) / 1e9)
        self.traj_pub.publish(self.traj_builder.fill(t_ns, q, qd))
        if len(self.horizon_work) < 100_000:
            self.horizon_work.append(time.perf_counter() - w0)

    # ---------------------------------------------------------------- monitoring
    def _monitor(self, t_ns: int) -> None:
        """Read /cpg/state's data in the tick (the CPG state of ``t_ns``); publish it and /diagnostics from
        the node's idle step (``idle``: runtime.spin_hot calls it every 20 ms of wall time), so a monitor
        tick costs one state read, not two message builds and publishes (about 150 us of CPU). Without an
        idle step the next monitor tick publishes the pending one first."""
        self.idle()
        self.monitor_due = (t_ns, state_vector(self.ctrl))

    def _flush_monitor(self) -> None:
        due, self.monitor_due = self.monitor_due, None
        if due is None:
            return
        t_ns, data = due
        self.state_msg.data = darray(data)
        self.state_pub.publish(self.state_msg)
        self._diagnostics(t_ns)

    def _diagnostics(self, t_ns: int) -> None:
        ok = self.stage != "learning" and getattr(self, "converged", True)
        ctrl = getattr(self, "ctrl", None)
        values = {"state": self.stage, "overruns": str(self.timing.overruns)}
        if ctrl is not None:
            values.update({"zeta_command": f"{ctrl.zeta_command:g}", "zeta": f"{ctrl.zeta:.6g}",
                           "alpha_command": f"{ctrl.alpha_command:g}", "alpha": f"{ctrl.alpha:.6g}",
                           "n_oscillators": str(ctrl.net.N), "cpg_file": self.origin,
                           "learning_converged": str(self.converged).lower()})
        level = DiagnosticStatus.OK if ok or self.stage == "learning" else DiagnosticStatus.WARN
        text = self.stage if ok or self.stage == "learning" else f"{self.stage} (learning not converged)"
        status = DiagnosticStatus(level=level, name="cpg_walker/cpg", message=text, hardware_id="cpg",
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = stamp(t_ns)
        self.diag_pub.publish(arr)

    def on_exit(self) -> None:
        timing = self.timing.summary()
        exit_log(self, "stats " + json.dumps({**self.activity.summary(), "overruns": timing["overruns"],
                                              "tick": timing, "gc": gc_summary(self),
                                              "horizon_work": latency_summary(self.horizon_work)}))



def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("cpg_node", "The learned humanoid CPG: /joint_targets on /clock, zeta/alpha modulation.",
                     INTERFACE, argv)
    return run_main(argv, CPGNode)


if __name__ == "__main__":
    raise SystemExit(main())
