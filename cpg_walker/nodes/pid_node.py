"""pid_node: the HOAP-2 joint servos as a ROS 2 node (``ros2 run cpg_walker pid_node``).

Answers every ``/joint_states`` sample with ``/joint_torques`` stamped like the sample, from the PID law
(cpg_walker.robot.pid.PidLaw) towards the latest ``/joint_targets``. Its gains and limits are ROS parameters
(values: config/pid.yaml via ``--params-file``, the file the in-process loop reads too). Outside lockstep,
when the state is newer than the newest target, it follows the source's ``/joint_trajectory`` horizon and,
past its end, blends to the standing crouch (cpg_walker.robot.trajectory.GapBridge). See
docs/ROS_INTERFACE.md.
"""

from __future__ import annotations

import time

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes import specs
from cpg_walker.nodes.messages import JointStateBuilder, read_joint_command, read_joint_trajectory, stamp_ns
from cpg_walker.nodes.params import declare_params, override_names
from cpg_walker.nodes.runtime import (
    HotPath,
    Throttle,
    exit_stats,
    gc_summary,
    parse_cli,
    run_main,
    scheduling_request,
)
from cpg_walker.nodes.validation import check_finite_scalar, reason_key
from cpg_walker.robot.hoap2 import default_standing_posture
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.pid import GAINS, LIMITS, PidLaw, gain_owner
from cpg_walker.robot.trajectory import HORIZON, LIVE, SAFE, GapBridge
from cpg_walker.timing import ActivityStats, StampGuard

#: Targets kept by stamp until the state of their stamp applies them (lockstep: waits for them; otherwise
#: every one stamped up to the state's stamp is applied); past the limit the oldest half is dropped (a
#: sim that far behind its controller has restarted).
TARGETS_KEEP = 512

class PidNode(Node):
    """Parameters <-> a PidLaw config; state and target callbacks; the target watchdog."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.PID_NODE], **node_options)
        # the gains: every group's (specs.PID), plus per-joint overrides given at start-up (kp.lleg_joint_4)
        group_gains = {spec.name for spec in specs.PID_GAINS}
        overrides = [n for g in GAINS for n in override_names(self, f"{g}.") if n not in group_gains]
        for name in overrides:
            gain_owner(name)  # a misspelt group or joint is an error naming it
        gains = (*specs.PID_GAINS, *(specs.gain(name) for name in overrides))
        v = declare_params(self, (*gains, *(spec for spec in specs.PID if spec.name not in group_gains)))
        self.gain_names = [spec.name for spec in gains]
        self.timeout_ns = round(v["target_timeout"] * 1e9)
        self.lockstep = bool(v["lockstep"])
        self.wait_targets = bool(v["wait_for_targets"])
        self.target_wait = float(v["target_wait"])
        self.startup_wait = float(v["startup_wait"])
        self.scheduling = scheduling_request(v)  # applied once started (runtime.settle_process)
        safe_blend = float(v["safe_blend"])
        resume_blend = float(v["resume_blend"])
        self.law = self._build_law({})
        self.add_on_set_parameters_callback(self._on_set)

        self.names = list(JOINT_NAMES)
        self.q_target = np.array(default_standing_posture(), dtype=float)
        self.v_target = np.zeros(len(JOINT_NAMES))
        self.targets_by_stamp: dict[int, object] = {}
        self.last_target_ns: int | None = None  # sim time of the last accepted target
        self.live_ns: int | None = None  # outside lockstep: the newest stamp among the applied targets
        self.bridge = GapBridge(default_standing_posture(), safe_blend, resume_blend)
        self.gap = {"horizon_entries": 0, "horizon_states": 0, "safe_entries": 0, "safe_states": 0,
                    "longest_gap_s": 0.0}
        self.gap_warned = False
        self.tripped = False
        self.clock_resets = 0
        self.stamp_guard = StampGuard()  # a state stamped far from the last awaits confirmation
        self.join: tuple[int, np.ndarray] | None = None  # (first state ns, posture): joined a running sim
        self.joined_at_s: float | None = None  # sim s it joined a running sim at (the stats)
        self.latest_state_ns = 0
        self.last_state_ns: int | None = None
        self.answered_ns: int | None = None
        self.pending = None  # (t_ns, q, v, wall time) waiting for its target (lockstep)
        self.b_tau = JointStateBuilder(JOINT_NAMES, fields=("effort",))
        self.pub = self.create_publisher(JointState, ifc.JOINT_TORQUES, ifc.DEPTH)
        subs = [self.create_subscription(JointState, ifc.JOINT_TARGETS, self._on_target, ifc.DEPTH),
                self.create_subscription(JointState, ifc.JOINT_STATES, self._on_state, ifc.DEPTH)]
        if not self.lockstep:  # lockstep answers each state with its own target: no horizon needed
            subs.append(self.create_subscription(JointTrajectory, ifc.JOINT_TRAJECTORY,
                                                 self._on_trajectory, 5))
        self.activity = ActivityStats()
        self.throttle = Throttle(1.0)
        self.hot = HotPath(self, subs)
        self.idle = self._check_wait
        self.get_logger().info(f"PID on {len(self.names)} joints, lockstep={self.lockstep}, "
                               f"wait_for_targets={self.wait_targets}")

    # ------------------------------------------------------------------------------ parameters
    def _build_law(self, changes: dict) -> PidLaw:
        """The law from the current parameters with ``changes`` (name -> value) applied."""
        names = (*self.gain_names, *LIMITS)
        cfg = {name: changes.get(name, self.get_parameter(name).value) for name in names}
        return PidLaw.from_config(config=cfg)

    def _on_set(self, params) -> SetParametersResult:
        changes = {}
        gain_names = {*self.gain_names, *LIMITS}
        try:
            for prm in params:
                if prm.name in gain_names:
                    changes[prm.name] = check_finite_scalar(prm.name, prm.value, 0.0)
                elif prm.name in ("target_timeout", "target_wait", "startup_wait"):
                    check_finite_scalar(prm.name, prm.value, 1e-3)
                elif prm.name in ("safe_blend", "resume_blend"):
                    check_finite_scalar(prm.name, prm.value, 0.0)
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
            elif prm.name == "safe_blend":
                self.bridge.safe_blend_s = float(prm.value)
            elif prm.name == "resume_blend":
                self.bridge.resume_blend_s = float(prm.value)
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------------------- callbacks
    def _on_target(self, msg: JointState) -> None:
        try:
            cmd = read_joint_command(msg, require="position")
        except ValueError as exc:
            self.throttle.warn(self, reason_key(exc),
                               f"rejected /joint_targets: {exc}")
            return
        t = stamp_ns(msg)
        self.targets_by_stamp.setdefault(t, []).append(cmd)  # applied by the state of its stamp (_answer)
        if len(self.targets_by_stamp) > TARGETS_KEEP:
            for key in sorted(self.targets_by_stamp)[:TARGETS_KEEP // 2]:
                del self.targets_by_stamp[key]
        if self.lockstep:
            if self.tripped and t >= self.latest_state_ns:
                self._untrip()
            if self.pending is not None and self.pending[0] in self.targets_by_stamp:
                t_ns, q, v, _ = self.pending
                self.pending = None
                self._answer(t_ns, q, v)
        else:
            self.last_target_ns = self.latest_state_ns
            if self.tripped:
                self._untrip()
            if self.pending is not None:
                t_ns, q, v, _ = self.pending
                self.pending = None
                self._answer(t_ns, q, v)

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            self.bridge.offer(read_joint_trajectory(msg))
        except ValueError as exc:
            self.throttle.warn(self, "trajectory " + reason_key(exc), f"rejected /joint_trajectory: {exc}")

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
            self.throttle.warn(self, "still stale", f"targets still stale ({why}): holding the last target "
                               "posture")

    def _on_state(self, msg: JointState) -> None:
        self.activity.tick()
        if msg.name == self.names and len(msg.position) == len(msg.velocity) == len(self.names):
            q, v = np.asarray(msg.position), np.asarray(msg.velocity)
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                self.throttle.warn(self, "state non-finite", "rejected /joint_states: non-finite value")
                return
        else:
            self.throttle.warn(self, "state layout", "rejected /joint_states: expected position and "
                               f"velocity of all {len(self.names)} joints in order")
            return
        t = stamp_ns(msg)
        if t == self.answered_ns:  # a re-sent state: answer again, identically
            self.pub.publish(self.b_tau.msg)
            return
        verdict = self.stamp_guard.judge(self.last_state_ns, t)
        if verdict == StampGuard.DROP:
            self.throttle.warn(self, "state jump", f"dropped /joint_states {t / 1e9:.9g} s: far from the "
                               f"last {self.last_state_ns / 1e9:.9g} s, unconfirmed (a restarted sim sends "
                               "the next or the same again)")
            return
        if verdict == StampGuard.RESET:
            self._clock_reset(t)
        if self.last_state_ns is not None and t < self.last_state_ns:
            return  # older than what was answered: stale duplicate
        self.latest_state_ns = max(self.latest_state_ns, t)
        if self._must_wait(t):
            if self.pending is None or self.pending[0] != t:  # a re-sent state keeps the wait's start
                self.pending = (t, q, v, time.monotonic())
            return
        self._answer(t, q, v)

    def _join_blend(self, t_ns: int, q_ref: np.ndarray, v_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A node started mid-run: from the posture measured at its first state to the reference, C1
        over resume_blend (the robot is wherever the servos' own hold left it, not at the targets)."""
        t0, q0 = self.join
        T = self.bridge.resume_blend_s
        u = 1.0 if T <= 0 else (t_ns - t0) / 1e9 / T
        if u >= 1.0:
            self.join = None
            return q_ref, v_ref
        w, dw = u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u) / T
        return q0 + w * (q_ref - q0), w * v_ref + dw * (q_ref - q0)

    def _clock_reset(self, t_ns: int) -> None:
        """A state stamped more than CLOCK_RESET_S before the last answered one, confirmed by the next (a
        single stray one is dropped): the sim has restarted.
        Start over as a fresh node: targets and horizon forgotten, the standing crouch, integral 0."""
        self.get_logger().warn(f"/joint_states went back from {self.last_state_ns / 1e9:.3f} s to "
                               f"{t_ns / 1e9:.3f} s (sim restarted): starting over")
        self.targets_by_stamp.clear()
        self.last_target_ns = self.live_ns = self.last_state_ns = self.answered_ns = None
        self.latest_state_ns = 0
        self.pending = None
        self.tripped = self.gap_warned = False
        self.q_target = np.array(default_standing_posture(), dtype=float)
        self.v_target = np.zeros(len(JOINT_NAMES))
        b = self.bridge
        self.bridge = GapBridge(default_standing_posture(), b.safe_blend_s, b.resume_blend_s)
        self.law.integral[:] = 0.0
        self.join = None
        self.clock_resets += 1

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
        else:  # every target stamped up to t, in stamp order (one sent ahead waits for its state)
            due = [k for k in self.targets_by_stamp if k <= t_ns]
            if not due and self.live_ns is None and self.targets_by_stamp:
                due = [min(self.targets_by_stamp)]  # start-up: the first target, whatever its stamp
            for key in sorted(due):
                for cmd in self.targets_by_stamp.pop(key):
                    self._apply(cmd)
                self.live_ns = key if self.live_ns is None else max(self.live_ns, key)
        q_ref, v_ref = self.q_target, self.v_target
        if not self.lockstep and self.bridge.active:
            q_ref, v_ref = self._bridge(t_ns)
        if self.last_state_ns is None and t_ns > 0:  # joined a running sim (restarted): blend in
            self.join = (t_ns, q.copy())
            self.joined_at_s = round(t_ns / 1e9, 6)
            self.get_logger().info(f"joined a running sim at {t_ns / 1e9:.3f} s: blending from the measured "
                                   f"posture to the targets over {self.bridge.resume_blend_s:g} s")
        if self.join is not None:
            q_ref, v_ref = self._join_blend(t_ns, q_ref, v_ref)
        elif (not self.tripped and self.last_target_ns is not None
                and t_ns - self.last_target_ns > self.timeout_ns):
            self._trip(f"last target {(t_ns - self.last_target_ns) / 1e9:.3f} sim s old")
        elif self.tripped:
            self._trip("no fresh target")
        # sim s since the last answered state; 0 for the first (nothing to integrate over yet)
        dt = 0.0 if self.last_state_ns is None else max(0.0, (t_ns - self.last_state_ns) / 1e9)
        tau = self.law.step(q_ref, v_ref, q, v, dt)
        self.last_state_ns = t_ns
        self.answered_ns = t_ns
        self.pub.publish(self.b_tau.fill(t_ns, effort=tau))

    def _bridge(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """The reference at t from the GapBridge (live targets, horizon or standing crouch); logs and
        counts the gaps (a gap shorter than target_timeout is not logged: the horizon rides it out)."""
        b = self.bridge
        q_ref, v_ref = b.reference(t_ns, self.q_target, self.v_target, self.live_ns)
        gap_s = 0.0 if self.live_ns is None else (t_ns - self.live_ns) / 1e9
        g = self.gap
        if b.switched is not None:
            came_from, mode = b.switched
            if mode == HORIZON and came_from != HORIZON:
                g["horizon_entries"] += 1
            elif mode == SAFE:
                g["safe_entries"] += 1
                self.gap_warned = True
                self.get_logger().warn(
                    f"no target for {gap_s:.3f} sim s and the horizon ended at "
                    f"{b.newest.end_ns / 1e9:.3f} s: blending to the standing posture over "
                    f"{b.safe_blend_s:g} s")
            elif mode == LIVE and self.gap_warned:
                self.gap_warned = False
                self.get_logger().info(f"targets resumed (from {came_from}): blending back over "
                                       f"{b.resume_blend_s:g} s")
        if b.mode != LIVE:
            g[f"{b.mode}_states"] += 1
            g["longest_gap_s"] = max(g["longest_gap_s"], round(gap_s, 6))
            if b.mode == HORIZON and not self.gap_warned and gap_s * 1e9 > self.timeout_ns:
                self.gap_warned = True
                self.get_logger().warn(f"targets late ({gap_s:.3f} sim s): following the "
                                       f"/joint_trajectory horizon (to {b.trajectory.end_ns / 1e9:.3f} s)")
        return q_ref, v_ref

    def on_exit(self) -> None:
        exit_stats(self, {**self.activity.summary(), "gaps": self.gap, "clock_resets": self.clock_resets,
                          "joined_at_s": self.joined_at_s, "gc": gc_summary(self)})



def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("pid_node", "HOAP-2 joint PID servos: /joint_targets + /joint_states -> /joint_torques.",
                     specs.node_help(ifc.PID_NODE), argv)
    return run_main(argv, PidNode)


if __name__ == "__main__":
    raise SystemExit(main())
