"""cpg_node: the learned humanoid CPG as a ROS node (``ros2 run cpg_walker cpg_node``).

Thin wiring around ``cpg.humanoid.CPGGaitSource``: on every ``/clock`` tick it advances the CPG to the
tick's sim time and publishes ``/joint_targets`` stamped with it, and (``lookahead``) also the next
period's target, exactly like target_player_node, so lockstep runs stay deterministic. ``zeta``/``alpha``
are the oscillators' modulation commands (HumanoidCPG's smoothed ζ/α), never a scaling of the output.
"""

from __future__ import annotations

import math

from cpg_walker.nodes.runtime import float_param, int_param, parse_cli, plain_param, run_main
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE, modulation_error

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
  /diagnostics (diagnostic_msgs/DiagnosticArray, every monitor_period): status 'cpg_walker/cpg' with
    state (learning | converged | starting | walking), zeta, alpha (commanded and applied), N, overruns
parameters: cpg_file (learned YAML; '' = learn at start-up), n_oscillators (N when learning),
  zeta [-2, 2] and alpha [0, 2] (settable at run time), lookahead, monitor_period (sim s)"""


def state_layout(names, n_osc: int):
    """The MultiArrayLayout of /cpg/state (see INTERFACE)."""
    from std_msgs.msg import MultiArrayDimension, MultiArrayLayout

    b, m = len(names), n_osc + 1
    return MultiArrayLayout(dim=[
        MultiArrayDimension(label="dof:" + ",".join(names), size=b, stride=b * m * 3),
        MultiArrayDimension(label=f"oscillator(0..{n_osc - 1}),output({n_osc})", size=m, stride=m * 3),
        MultiArrayDimension(label="phase_rad|frequency_hz|amplitude_rad;output:q|qd|offset", size=3,
                            stride=3),
    ], data_offset=0)


def state_vector(ctrl):
    """/cpg/state's data: (B, N + 1, 3) flattened, from the controller's current network state."""
    import numpy as np

    net = ctrl.net
    q, qd = ctrl.joint_targets()
    osc = np.stack([net.phases(), net.frequencies() / (2 * math.pi), np.abs(net.amplitudes())], axis=-1)
    out = np.stack([q, qd, net.offset], axis=-1)[:, None, :]
    return np.concatenate([osc, out], axis=1).ravel()


def _make_node():
    from time import perf_counter

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from cpg_walker.nodes.messages import JointStateBuilder, darray, stamp
    from cpg_walker.nodes.runtime import ActivityStats, HotPath, TickStats, exit_log
    from cpg_walker.nodes.validation import to_ns
    from cpg_walker.walker.controller import HumanoidCPG
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import load_controller

    class CPGNode(Node):
        def __init__(self) -> None:
            super().__init__("cpg")
            p = self.declare_parameter
            p("cpg_file", "cpg_humanoid.yaml",
              plain_param("learned CPG YAML (a path, or a name in the package's config/); '' = learn at "
                          "start-up", read_only=True))
            p("n_oscillators", 3, int_param("oscillators per DOF when learning at start-up", 1, 20,
                                            read_only=True))
            p("zeta", 1.0, float_param("frequency ratio ζ of the oscillators (negative: backwards)",
                                       *ZETA_RANGE))
            p("alpha", 1.0, float_param("amplitude (step length) scale α of the oscillators", *ALPHA_RANGE))
            p("lookahead", True, plain_param("also send the next period's target on each tick",
                                             read_only=True))
            p("monitor_period", 0.1, float_param("sim s between /cpg/state and /diagnostics messages",
                                                 0.002, 60.0, read_only=True))
            g = self.get_parameter
            for name in ("zeta", "alpha"):
                reason = modulation_error(name, g(name).value)
                if reason:
                    raise ValueError(reason)
            self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
            self.state_pub = self.create_publisher(Float64MultiArray, "/cpg/state", 10)
            self.pub = self.create_publisher(JointState, "/joint_targets", 10)
            self.timing = TickStats()
            self.phase = "learning"
            self.ctrl, self.origin, self.converged = self._controller(g("cpg_file").value,
                                                                      g("n_oscillators").value)
            self.source = CPGGaitSource(self.ctrl, zeta=g("zeta").value, alpha=g("alpha").value)
            self.walk_from_s = self.source.handover + self.source.blend
            self._warm_up()
            self.phase = "converged"
            self.add_on_set_parameters_callback(self._on_set)
            self.lookahead = bool(g("lookahead").value)
            self.monitor_ns = round(g("monitor_period").value * 1e9)
            self.next_monitor_ns = 0
            self.last_tick_ns: int | None = None
            self.sent_ns: int | None = None
            self.recent: dict[int, tuple] = {}  # last published targets by stamp (re-sent ticks)
            self.builder = JointStateBuilder(self.source.names)
            self.state_msg = Float64MultiArray(layout=state_layout(self.ctrl.names, self.ctrl.net.N))
            self.activity = ActivityStats()
            self.hot = HotPath(self, [self.create_subscription(Clock, "/clock", self._on_clock, 100)])
            self._diagnostics(0)
            self.get_logger().info(f"CPG N={self.ctrl.net.N} from {self.origin}; recording's opening steps "
                                   f"to {self.source.handover:.3f} s, CPG from {self.walk_from_s:.3f} s")

        def _controller(self, cpg_file: str, n: int) -> tuple[HumanoidCPG, str, bool]:
            if not cpg_file:
                self._diagnostics(0)
                self.get_logger().info(f"learning the CPG (N={n}) at start-up ...")
            try:
                return load_controller(cpg_file, n if not cpg_file else None)
            except FileNotFoundError as exc:
                raise ValueError(str(exc)) from None

        def _warm_up(self) -> None:
            """Step a copy of the CPG (with the modulation filters moving) a few times: compiled kernels
            are compiled or loaded on first use (about 1 s with numba), which must not happen at the
            hand-over tick mid-walk (in real time the robot would go without targets and fall)."""
            import time

            t0 = time.perf_counter()
            spare = HumanoidCPG.from_dict(self.ctrl.to_dict())
            spare.set_zeta(0.9 * spare.zeta_command or 0.9)
            spare.set_alpha(0.9 * spare.alpha_command or 0.9)
            for _ in range(3):
                spare.step(self.source.h)
                spare.joint_targets()
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
            w0 = perf_counter()
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
            if t_ns >= self.next_monitor_ns:
                self.phase = "walking" if t_ns >= self.walk_from_s * 1e9 else "starting"
                self._monitor(t_ns)
                self.next_monitor_ns = t_ns + self.monitor_ns
            self.timing.tick(w0, t_ns, perf_counter() - w0)  # overrun: work longer than the period

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

        # ---------------------------------------------------------------- monitoring
        def _monitor(self, t_ns: int) -> None:
            self.state_msg.data = darray(state_vector(self.ctrl))
            self.state_pub.publish(self.state_msg)
            self._diagnostics(t_ns)

        def _diagnostics(self, t_ns: int) -> None:
            ok = self.phase != "learning" and getattr(self, "converged", True)
            ctrl = getattr(self, "ctrl", None)
            values = {"state": self.phase, "overruns": str(self.timing.overruns)}
            if ctrl is not None:
                values.update({"zeta_command": f"{ctrl.zeta_command:g}", "zeta": f"{ctrl.zeta:.6g}",
                               "alpha_command": f"{ctrl.alpha_command:g}", "alpha": f"{ctrl.alpha:.6g}",
                               "n_oscillators": str(ctrl.net.N), "cpg_file": self.origin,
                               "learning_converged": str(self.converged).lower()})
            level = DiagnosticStatus.OK if ok or self.phase == "learning" else DiagnosticStatus.WARN
            text = self.phase if ok or self.phase == "learning" else f"{self.phase} (learning not converged)"
            status = DiagnosticStatus(level=level, name="cpg_walker/cpg", message=text, hardware_id="cpg",
                                      values=[KeyValue(key=k, value=v) for k, v in values.items()])
            arr = DiagnosticArray(status=[status])
            arr.header.stamp = stamp(t_ns)
            self.diag_pub.publish(arr)

        def on_exit(self) -> None:
            import json

            timing = self.timing.summary()
            exit_log(self, "stats " + json.dumps({**self.activity.summary(), "overruns": timing["overruns"],
                                                  "tick": timing}))

    return CPGNode()


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("cpg_node", "The learned humanoid CPG: /joint_targets on /clock, zeta/alpha modulation.",
                     INTERFACE, argv)
    return run_main(argv, _make_node)


if __name__ == "__main__":
    raise SystemExit(main())
