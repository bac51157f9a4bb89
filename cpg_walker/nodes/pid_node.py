"""pid_node: the HOAP-2 joint servos as a ROS 2 node (``ros2 run cpg_walker pid_node``).

Answers every ``/joint_states`` sample with ``/joint_torques`` stamped like the sample, from the PID law
(cpg_walker.robot.pid.PidLaw) towards the latest ``/joint_targets``. See docs/ROS_INTERFACE.md.
"""

from __future__ import annotations

import time

import numpy as np

from cpg_walker.nodes.runtime import float_param, parse_cli, plain_param, run_main

INTERFACE = """\
subscribes: /joint_targets (sensor_msgs/JointState: position, optional velocity, any subset of joints by
  name), /joint_states (sensor_msgs/JointState)
publishes: /joint_torques (sensor_msgs/JointState: name + effort N*m, stamp = the answered state's)
parameters: kp.<group>, ki.<group>, kd.<group> for group in leg, arm, body, head (and kp.<joint>... for
  per-joint overrides in the config), max_torque, integral_limit, max_velocity (settable, validated);
  config_file (default config/pid.yaml), target_timeout (sim s), lockstep, wait_for_targets,
  target_wait and startup_wait (wall s)"""

GAIN_RANGES = {"kp": 2000.0, "ki": 2000.0, "kd": 200.0}


def _make_node():
    import rclpy
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from cpg_walker.nodes.messages import JointStateBuilder, read_joint_command, stamp_ns
    from cpg_walker.nodes.runtime import ActivityStats, HotPath, Throttle, exit_log
    from cpg_walker.nodes.validation import check_finite_scalar, reason_key
    from cpg_walker.robot.hoap2 import default_standing_posture
    from cpg_walker.robot.joints import JOINT_NAMES, MAX_TORQUE_NM
    from cpg_walker.robot.pid import PidLaw, load_pid_config

    class PidNode(Node):
        """Parameters <-> a PidLaw config; state and target callbacks; the target watchdog."""

        def __init__(self) -> None:
            super().__init__("pid")
            p = self.declare_parameter
            p("config_file", "", plain_param("PID YAML ('' = config/pid.yaml)", read_only=True))
            path = self.get_parameter("config_file").value or None
            self.cfg = load_pid_config(path)
            self.gain_keys: list[tuple[str, str]] = []  # (parameter name, group or joint)
            for group, gains in self.cfg["groups"].items():
                for key in ("kp", "ki", "kd"):
                    p(f"{key}.{group}", float(gains.get(key, 0.0)),
                      float_param(f"{key} of the {group} joints", 0.0, GAIN_RANGES[key]))
                    self.gain_keys.append((f"{key}.{group}", group))
            for joint, gains in (self.cfg.get("joints") or {}).items():
                for key, value in gains.items():
                    p(f"{key}.{joint}", float(value), float_param(f"{key} of {joint} (override)", 0.0,
                                                                  GAIN_RANGES[key]))
                    self.gain_keys.append((f"{key}.{joint}", joint))
            p("max_torque", float(self.cfg.get("max_torque", MAX_TORQUE_NM)),
              float_param("N*m torque clamp", 0.0, MAX_TORQUE_NM))
            p("integral_limit", float(self.cfg.get("integral_limit", 0.5)),
              float_param("N*m anti-windup clamp", 0.0, 100.0))
            p("max_velocity", float(self.cfg.get("max_velocity", 5.0)),
              float_param("rad/s beyond which no torque speeds a joint up further", 0.0, 100.0))
            p("target_timeout", 0.1, float_param("sim s without a target before holding the last posture",
                                                 1e-3, 1e3))
            p("lockstep", False, plain_param("answer state t_k only with the target stamped t_k",
                                             read_only=True))
            p("wait_for_targets", False, plain_param("do not answer before the first target has arrived; "
                                                     "in lockstep, wait for the target of every period",
                                                     read_only=True))
            p("target_wait", 0.5, float_param("lockstep: wall s to wait for a target before the watchdog "
                                              "trips", 1e-3, 1e3))
            p("startup_wait", 30.0, float_param("lockstep: wall s to wait for the first target", 1e-3, 1e4))
            g = self.get_parameter
            self.timeout_ns = round(g("target_timeout").value * 1e9)
            self.lockstep = bool(g("lockstep").value)
            self.wait_targets = bool(g("wait_for_targets").value)
            self.target_wait = float(g("target_wait").value)
            self.startup_wait = float(g("startup_wait").value)
            self.law = self._build_law({})
            self.nominal_dt = 1.0 / float(self.cfg.get("rate_hz", 500.0))
            self.add_on_set_parameters_callback(self._on_set)

            self.names = list(JOINT_NAMES)
            self.q_target = np.array(default_standing_posture(), dtype=float)
            self.v_target = np.zeros(len(JOINT_NAMES))
            self.targets_by_stamp: dict[int, object] = {}
            self.last_target_ns: int | None = None  # sim time of the last accepted target
            self.tripped = False
            self.latest_state_ns = 0
            self.last_state_ns: int | None = None
            self.answered_ns: int | None = None
            self.pending = None  # (t_ns, q, v, wall time) waiting for its target (lockstep)
            self.b_tau = JointStateBuilder(JOINT_NAMES)
            self.pub = self.create_publisher(JointState, "/joint_torques", 10)
            subs = [self.create_subscription(JointState, "/joint_targets", self._on_target, 10),
                    self.create_subscription(JointState, "/joint_states", self._on_state, 10)]
            self.activity = ActivityStats()
            self.throttle = Throttle(1.0)
            self.hot = HotPath(self, subs)
            self.idle = self._check_wait
            self._ok = rclpy.ok
            self.get_logger().info(f"PID on {len(self.names)} joints, lockstep={self.lockstep}, "
                                   f"wait_for_targets={self.wait_targets}")

        # ------------------------------------------------------------------------------ parameters
        def _build_law(self, changes: dict) -> PidLaw:
            cfg = {**self.cfg, "groups": {k: dict(v) for k, v in self.cfg["groups"].items()},
                   "joints": {k: dict(v) for k, v in (self.cfg.get("joints") or {}).items()}}
            for name, owner in self.gain_keys:
                key = name.split(".", 1)[0]
                value = changes.get(name, self.get_parameter(name).value)
                target = cfg["groups"][owner] if owner in cfg["groups"] else cfg["joints"][owner]
                target[key] = float(value)
            for name in ("max_torque", "integral_limit", "max_velocity"):
                cfg[name] = float(changes.get(name, self.get_parameter(name).value))
            return PidLaw.from_config(config=cfg)

        def _on_set(self, params) -> SetParametersResult:
            changes = {}
            gain_names = {n for n, _ in self.gain_keys} | {"max_torque", "integral_limit", "max_velocity"}
            try:
                for prm in params:
                    if prm.name in gain_names:
                        changes[prm.name] = check_finite_scalar(prm.name, prm.value, 0.0)
                    elif prm.name in ("target_timeout", "target_wait", "startup_wait"):
                        check_finite_scalar(prm.name, prm.value, 1e-3)
                law = self._build_law(changes) if changes else None
            except (ValueError, TypeError) as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            if law is not None:
                law.integral = self.law.integral.copy()
                self.law = law
            for prm in params:
                if prm.name == "target_timeout":
                    self.timeout_ns = round(float(prm.value) * 1e9)
                elif prm.name == "target_wait":
                    self.target_wait = float(prm.value)
                elif prm.name == "startup_wait":
                    self.startup_wait = float(prm.value)
            return SetParametersResult(successful=True)

        # ------------------------------------------------------------------------------- callbacks
        def _on_target(self, msg: JointState) -> None:
            try:
                cmd = read_joint_command(msg, require="position")
            except ValueError as exc:
                self.throttle.warn(self, reason_key(exc),
                                   f"rejected /joint_targets: {exc}")
                return
            if self.lockstep:
                t = stamp_ns(msg)
                self.targets_by_stamp.setdefault(t, []).append(cmd)
                if len(self.targets_by_stamp) > 512:
                    for key in sorted(self.targets_by_stamp)[:256]:
                        del self.targets_by_stamp[key]
                if self.tripped and t >= self.latest_state_ns:
                    self._untrip()
                if self.pending is not None and self.pending[0] in self.targets_by_stamp:
                    t_ns, q, v, _ = self.pending
                    self.pending = None
                    self._answer(t_ns, q, v)
            else:
                self._apply(cmd)
                self.last_target_ns = self.latest_state_ns
                if self.tripped:
                    self._untrip()
                if self.pending is not None:
                    t_ns, q, v, _ = self.pending
                    self.pending = None
                    self._answer(t_ns, q, v)

        def _apply(self, cmd) -> None:
            self.q_target[cmd.index] = cmd.position
            self.v_target[cmd.index] = 0.0 if cmd.velocity is None else cmd.velocity

        def _untrip(self) -> None:
            self.tripped = False
            self.get_logger().info("targets resumed")

        def _trip(self, why: str) -> None:
            if not self.tripped:
                self.tripped = True
                self.v_target[:] = 0.0
                self.get_logger().warn(f"targets stale ({why}): holding the last target posture")
            else:
                self.get_logger().warn(f"targets still stale ({why}): holding the last target posture",
                                       throttle_duration_sec=2.0)

        def _on_state(self, msg: JointState) -> None:
            self.activity.tick()
            if msg.name == self.names and len(msg.position) == len(msg.velocity) == len(self.names):
                q, v = np.asarray(msg.position), np.asarray(msg.velocity)
                if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                    self.get_logger().warn("rejected /joint_states: non-finite value",
                                           throttle_duration_sec=1.0)
                    return
            else:
                self.get_logger().warn("rejected /joint_states: expected position and velocity of all "
                                       f"{len(self.names)} joints in order", throttle_duration_sec=1.0)
                return
            t = stamp_ns(msg)
            if t == self.answered_ns:  # a re-sent state: answer again, identically
                self.pub.publish(self.b_tau.msg)
                return
            if self.last_state_ns is not None and t < self.last_state_ns:
                return  # older than what was answered: stale duplicate
            self.latest_state_ns = max(self.latest_state_ns, t)
            if self._must_wait(t):
                self.pending = (t, q, v, time.monotonic())
                return
            self._answer(t, q, v)

        def _must_wait(self, t_ns: int) -> bool:
            if not self.wait_targets or self.tripped:
                return False
            if self.lockstep:
                return t_ns not in self.targets_by_stamp
            return self.last_target_ns is None  # before the first target only

        def _check_wait(self) -> None:
            if self.pending is None or not self.wait_targets:
                return
            limit = self.target_wait if self.last_target_ns is not None else self.startup_wait
            waited = time.monotonic() - self.pending[3]
            if waited > limit:
                t_ns, q, v, _ = self.pending
                self.pending = None
                self._trip(f"no target for {t_ns / 1e9:.3f} s after {waited:.2f} wall s")
                self._answer(t_ns, q, v)

        def _answer(self, t_ns: int, q: np.ndarray, v: np.ndarray) -> None:
            if self.lockstep:
                for cmd in self.targets_by_stamp.pop(t_ns, ()):
                    self._apply(cmd)
                    self.last_target_ns = t_ns
                for key in [k for k in self.targets_by_stamp if k < t_ns]:
                    del self.targets_by_stamp[key]
            if (not self.tripped and self.last_target_ns is not None
                    and t_ns - self.last_target_ns > self.timeout_ns):
                self._trip(f"last target {(t_ns - self.last_target_ns) / 1e9:.3f} sim s old")
            elif self.tripped:
                self._trip("no fresh target")
            dt = self.nominal_dt if self.last_state_ns is None else (t_ns - self.last_state_ns) / 1e9
            if dt <= 0:
                dt = self.nominal_dt
            tau = self.law.step(self.q_target, self.v_target, q, v, dt)
            self.last_state_ns = t_ns
            self.answered_ns = t_ns
            self.pub.publish(self.b_tau.fill(t_ns, effort=tau))

        def on_exit(self) -> None:
            import json

            exit_log(self, "stats " + json.dumps(self.activity.summary()))

    return PidNode()


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("pid_node", "HOAP-2 joint PID servos: /joint_targets + /joint_states -> /joint_torques.",
                     INTERFACE, argv)
    return run_main(argv, _make_node)


if __name__ == "__main__":
    raise SystemExit(main())
