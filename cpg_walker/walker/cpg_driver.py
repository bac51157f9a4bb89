"""The learned humanoid CPG driven by sim-time ticks, free of ROS: what cpg_node wires to its topics.

``CPGDriver`` takes /clock ticks (``clock``), sensor samples (``imu``, ``load``), ζ/α commands
(``command``), /cmd_vel twists (``twist``) and the sim's servo hold (``servo_hold``), and answers through
a ``DriverOutput``: the targets of a tick stamped with it (and, with ``lookahead``, those of the next
tick), the horizon (the next ``horizon_s`` of targets, then ``horizon_stop_s`` in which the stepping dies
out: `gait_source.stop_fade`), the monitored state and log lines. Per tick, in this order: the /cmd_vel
follower's output, the sensor samples to the feedback pathways (`FeedbackGaitSource.observe`, weighted by
`FeedbackFade`), the targets, the horizon, the monitor.

Time: a first tick later than REJOIN_AFTER_S (a node joining a running sim), the servos' release
(``servo_hold(False)``) and a clock that went back (a restarted sim: the learned network again) re-enter
the gait from the standing crouch (`CPGGaitSource.reenter`). With ``lockstep`` a tick waits for the
sensor samples stamped like it (up to ``sensor_wait_s`` wall s), so the target stamped t + period depends
on the state stamped t only (bit-reproducible); otherwise it takes the newest samples.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from typing import Protocol

import numpy as np

from cpg_walker.timing import CLOCK_JUMP_NS, ActivityStats, StampGuard, TickStats
from cpg_walker.walker import storage
from cpg_walker.walker.cmd_vel import CmdVelFollower, CmdVelLimits, CmdVelOutput, SpeedMap, apply_output
from cpg_walker.walker.controller import HumanoidCPG
from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController
from cpg_walker.walker.gait_source import FeedbackGaitSource, smootherstep, stop_fade
from cpg_walker.walker.governor import GovernorConfig
from cpg_walker.walker.live_teaching import CONVERGED, IDLE, REFUSED, LiveTeacher

#: Sensor samples kept per topic, by stamp (lockstep takes the one stamped like its tick).
SENSOR_KEEP = 32
#: The start-up warm-up commands this fraction of the current ζ/α (0.9 of 0 is 0: then this value itself),
#: so the modulation filters move too while the compiled kernels load.
WARM_UP_COMMAND = 0.9
#: A first tick later than this (sim s) means the node joined a running sim (restarted, or started late):
#: it re-enters the gait from the standing crouch instead of playing the recording's opening steps.
REJOIN_AFTER_S = 0.1
#: Targets kept by stamp, to re-send a re-sent tick's targets identically.
RECENT_KEEP = 4
#: A take-over switches networks once the applied α is below this (the robot stands).
TAKE_OVER_ALPHA = 0.01
#: The driver's stages, as reported on /diagnostics ``state``.
STAGES = ("learning", "converged", "starting", "walking")


class DriverOutput(Protocol):
    """Where a CPGDriver's answers go (cpg_node: its publishers and logger)."""

    def targets(self, t_ns: int, q: np.ndarray, qd: np.ndarray) -> None:
        """The 25 joints' target (q, q̇) for sim time ``t_ns``."""

    def horizon(self, t_ns: int, offsets_ns: np.ndarray, q: np.ndarray, qd: np.ndarray) -> None:
        """The forecast targets at ``t_ns + offsets_ns`` ((K, 25) each)."""

    def monitor(self, t_ns: int, state: np.ndarray, values: dict[str, str]) -> None:
        """The CPG state of ``t_ns`` (`state_vector`) and the status values of that moment."""

    def log(self, level: str, text: str, key: str | None = None) -> None:
        """A line to the log at ``level`` (info | warn); with ``key``: throttled per key."""


class FeedbackFade:
    """The weight w in [0, 1] of the feedback pathways. A ramp u moves at 1/``fade_s`` per sim s towards 1
    while feedback is on and the newest sensor sample is at most ``timeout_s`` sim s old, towards 0
    otherwise (``fade_s`` 0: at once); w = smootherstep(u) (w, dw/dt continuous, flat at both ends).
    Starts at 0: feedback fades in once the first samples are there."""

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
        self.weight = smootherstep(self.u)[0]
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


def state_vector(ctrl: HumanoidCPG) -> np.ndarray:
    """/cpg/state's data: per DOF, each oscillator's [phase rad, frequency Hz, amplitude rad] and then the
    DOF's output [target q, target q̇, offset]: (B, N + 1, 3) flattened."""
    net = ctrl.net
    q, qd = ctrl.joint_targets()
    osc = np.stack([net.phases(), net.frequencies() / (2 * math.pi), np.abs(net.amplitudes())], axis=-1)
    out = np.stack([q, qd, net.offset], axis=-1)[:, None, :]
    return np.concatenate([osc, out], axis=1).ravel()


def turn_unavailable(enabled: bool, weight: float, pathways: tuple[str, ...]) -> str:
    """Why angular.z cannot turn the robot ('' if it can): turning is the heading feedback pathway."""
    if "heading" not in pathways:
        return "the heading feedback pathway is not in feedback_pathways"
    if not enabled:
        return "feedback is off"
    if weight <= 0.0:
        return "feedback has faded out (stale sensors)"
    return ""


def side_step_unavailable(turn_reason: str, ankle_allowed: bool, pathways: tuple[str, ...],
                          ankle_for_side_step: bool = False) -> str:
    """Why linear.y cannot side-step the robot ('' if it can): the side step walks only with the heading
    pathway's oscillator phase and the ankle pathway's balance (without it every side step measured
    in-process fell within 12 s, docs/steering.md); ``ankle_for_side_step``: the ankle pathway, off
    here, is closed for the side step."""
    if turn_reason:
        return turn_reason
    if "ankle" not in pathways:
        return "the ankle feedback pathway is not in feedback_pathways"
    if not ankle_allowed and not ankle_for_side_step:
        return ("the ankle pathway is off in realtime (cpg_node ankle_in_realtime and ankle_for_side_step "
                "false)")
    return ""


class CPGDriver:
    """The learned CPG (``ctrl``, started over from its dict on a sim reset) as a target source on sim
    time, with the feedback pathways, the /cmd_vel follower and the horizon (module docstring). ``zeta``
    and ``alpha``: the commands to walk at (``command`` changes them: the one entry point for the
    parameters; /cmd_vel's output goes through the same gait source). ``horizon_s`` 0: no horizon.
    ``wall``: the monotonic wall clock of the lockstep sensor wait. The ankle pathway acts only in
    ``lockstep`` or with ``ankle_in_realtime`` (its rate gains need a loop that waits for its samples);
    otherwise, with ``ankle_for_side_step``, while a /cmd_vel side step is commanded or still winding down
    (side steps need it), and with ``ankle_for_speed`` while the governor wants it (steps longer than the
    plain envelope's, the speed map's fast nodes: ``FeedbackGaitSource.needs_ankle``)."""

    def __init__(self, ctrl: HumanoidCPG, out: DriverOutput, *, feedback: FeedbackController,
                 feedback_on: bool, fade: FeedbackFade, zeta: float, alpha: float, speed_map: SpeedMap,
                 cmd_vel_limits: CmdVelLimits, follow_cmd_vel: bool = True, lookahead: bool = True,
                 monitor_period_ns: int = 100_000_000, horizon_s: float = 0.0, horizon_stop_s: float = 0.0,
                 horizon_step_ns: int = 40_000_000, horizon_period_ns: int = 0, rejoin_settle_ns: int = 0,
                 lockstep: bool = False,
                 ankle_in_realtime: bool = False, ankle_for_side_step: bool = True,
                 ankle_for_speed: bool = True,
                 sensor_wait_s: float = 0.4,
                 governor: GovernorConfig | None = None, wall: Callable[[], float] = time.monotonic,
                 teacher: LiveTeacher | None = None, teach_steps: int = 2,
                 teach_blend_s: float = 2.0) -> None:
        self.out, self.wall, self.governor_config = out, wall, governor
        self.teacher = teacher  # live teaching (/cpg/teach), None: off
        self.teach_steps, self.teach_blend_s = int(teach_steps), float(teach_blend_s)
        self.teach_counts = {"received": 0, "took_over": 0, "saved": 0}
        self.pending: HumanoidCPG | None = None  # a taught network waiting for the robot to stand
        self.teach_work: deque[float] = deque(maxlen=10_000)  # wall s of learning per call (flat memory)
        self.took_over_at_s: float | None = None
        self._teach_logged: tuple[str, str] | None = None
        self.ctrl = ctrl
        self.learned_network = storage.to_dict(ctrl)  # the loaded network, to start over from (a sim reset)
        self.zeta, self.alpha = float(zeta), float(alpha)  # the commanded values (the parameters')
        self.lookahead, self.lockstep, self.sensor_wait_s = bool(lookahead), bool(lockstep), sensor_wait_s
        self.monitor_period_ns, self.rejoin_settle_ns = int(monitor_period_ns), int(rejoin_settle_ns)
        self.horizon_s, self.horizon_stop_s, self.horizon_step_ns = horizon_s, horizon_stop_s, horizon_step_ns
        self.horizon_period_ns = int(horizon_period_ns) or horizon_step_ns  # between messages
        if horizon_s > 0 and self.horizon_period_ns > horizon_s * 1e9 / 2:
            raise ValueError(f"horizon_period ({self.horizon_period_ns / 1e9:g} s) must be at most half the "
                             f"horizon ({horizon_s:g} s)")
        if horizon_s > 0 and round(horizon_s * 1e9 / horizon_step_ns) < 1:
            raise ValueError(f"horizon ({horizon_s} s) must be 0 or at least horizon_step")
        n_points = round((horizon_s + horizon_stop_s) * 1e9 / horizon_step_ns)
        # the coarse points (every step up to horizon + horizon_stop); the tick-spaced head is added once
        # the control period is known
        self.horizon_points_ns = np.arange(1, n_points + 1, dtype=np.int64) * horizon_step_ns \
            if horizon_s > 0 else None
        self.feedback_on, self.fade = bool(feedback_on), fade
        self.speed_map, self.follow_cmd_vel = speed_map, bool(follow_cmd_vel)
        self.cmd = CmdVelFollower(speed_map, cmd_vel_limits, zeta)
        self.stage = "converged"
        self.timing, self.activity = TickStats(), ActivityStats()
        self.counters = {"sensors_dropped": 0, "sensor_wait_timeouts": 0, "clock_dropped": 0,
                         "targets_withheld": 0}
        self.cmd_vel_counts = {"received": 0, "dropped": 0, "ignored": 0}
        self.horizon_work: deque[float] = deque(maxlen=10_000)  # wall s per horizon (flat memory)
        self.clock_guard = StampGuard()
        self.clock_resets = self.reentries = 0
        self.reentry_cause = "none"  # why the gait last re-entered from the crouch (status)
        # kept across a sim reset: the control period and the horizon's points, the last states reported
        self.control_period_ns: int | None = None  # the smallest step seen between ticks
        self.traj_offsets_ns: np.ndarray | None = None
        self.traj_fade: np.ndarray | None = None
        self.traj_period_ns: int | None = None
        self.monitor_due: tuple[int, np.ndarray, dict[str, str]] | None = None
        self.feedback_state = self.fade.state(self.feedback_on)
        self.sensor_age_s: float | None = None
        self.sample_ages = {"ticks": 0, "max_s": 0.0, "older_than_ankle_max": 0}
        self._cmd_logged: tuple | None = None
        self.cmd_turn = "ok"  # ok | why angular.z cannot turn the robot
        self.cmd_side = "ok"  # ok | why linear.y cannot side-step it
        self.ankle_allowed = self.lockstep or bool(ankle_in_realtime)
        self.ankle_for_side_step = bool(ankle_for_side_step)
        self.ankle_for_speed = bool(ankle_for_speed)
        self._start(feedback)

    def _start(self, fb: FeedbackController) -> None:
        """The state of a fresh run: the source from t = 0, no tick yet, empty buffers."""
        fb.weight = self.fade.weight
        fb.ankle_allowed = self.ankle_allowed
        # started at α 0 the robot stands from the first tick, without the recording's opening steps: in the
        # realtime graph walking those steps and stopping at once fell in 10 of 18 starts, 8-9 s in (from
        # standing: 0 of 4); a later α > 0 steps off through the governor
        start = "standing" if self.alpha == 0.0 else "recording"
        self.source = FeedbackGaitSource(self.ctrl, fb, transition=start, zeta=self.zeta, alpha=self.alpha,
                                         governor=self.governor_config)
        self.source.keep_traces = False  # plots' traces: a node's memory stays flat
        self.rejoined_at_s: float | None = None
        self.join_seen_ns: int | None = None  # the first tick of a running sim, while standing by
        self.last_tick_ns: int | None = None
        self.sent_ns: int | None = None
        self.recent: dict[int, tuple] = {}  # the last targets by stamp (re-sent ticks)
        self.next_monitor_ns = self.next_horizon_ns = 0
        self.waiting: deque[tuple[int, float]] = deque()  # lockstep: ticks waiting for their samples
        self.sensors_gave_up = False  # a lockstep wait timed out: no waiting until the samples catch up
        self.imu = SensorBuffer()
        self.loads = (SensorBuffer(), SensorBuffer())
        self.buffers = (self.imu, *self.loads)
        self.cmd_out: CmdVelOutput | None = None  # the follower's last output
        self.cmd_override = False  # a ζ/α command while following /cmd_vel: holds until the next Twist
        self.servos_held = self.reenter_pending = False

    @property
    def walk_from_s(self) -> float:
        """Sim s from which the CPG alone drives (the end of the start-up or re-entry cross-fade)."""
        return self.source.takeover_s

    # ---------------------------------------------------------------- start-up
    def warm_up(self) -> float:
        """Step a copy of the CPG (the modulation filters moving) a few times, and its forecast: compiled
        kernels are compiled or loaded on first use (about 1 s with numba), which must not happen at the
        hand-over tick mid-walk (in real time the robot would go without targets and fall). Wall s."""
        t0 = time.perf_counter()
        spare = storage.from_dict(storage.to_dict(self.ctrl))
        spare.set_zeta(WARM_UP_COMMAND * spare.zeta_command or WARM_UP_COMMAND)
        spare.set_alpha(WARM_UP_COMMAND * spare.alpha_command or WARM_UP_COMMAND)
        for _ in range(3):
            spare.step(self.source.h)
            spare.joint_targets()
        if self.horizon_points_ns is not None:  # the forecast with the filters moving, then settled
            offsets = np.concatenate(([0.0, self.source.h], self.horizon_points_ns / 1e9))
            fade = stop_fade(offsets, self.horizon_s, self.horizon_stop_s)
            spare.forecast(offsets, fade)
            spare.set_modulation_state(spare.zeta_command, spare.alpha_command)
            spare.forecast(offsets)
            spare.forecast(offsets, fade)
        state_vector(spare)
        if self.teacher is not None:
            self.teacher.warm_up()
        return time.perf_counter() - t0

    # ---------------------------------------------------------------- commands
    def command(self, zeta: float, alpha: float) -> float:
        """Command ζ and α (the parameters' path); returns the sim time from which they apply. While
        following /cmd_vel they hold until the next Twist."""
        self.zeta, self.alpha = float(zeta), float(alpha)
        if self.pending is not None:  # a take-over stands the robot first: these follow it
            self.out.log("info", f"zeta={zeta:g}, alpha={alpha:g} apply once the taught network has "
                         "taken over")
            return (self.last_tick_ns or 0) / 1e9
        deferred = self.source.command(self.zeta, self.alpha)
        after = self.walk_from_s if deferred else (self.last_tick_ns or 0) / 1e9
        self.out.log("info", f"commanded zeta={zeta:g}, alpha={alpha:g} after sim {after:.3f} s")
        if self.cmd.last is not None and self.follow_cmd_vel:
            self.cmd_override = True
            self.cmd.zeta = self.zeta if self.zeta else self.cmd.zeta
            self._turn(0.0)
            self.out.log("info", "zeta/alpha set while following /cmd_vel: they hold until the next "
                         "/cmd_vel message")
        return after

    def set_feedback(self, on: bool) -> None:
        self.feedback_on = bool(on)
        self.out.log("info", f"feedback {'on' if on else 'off'} (fading {'in' if on else 'out'} over "
                     f"{self.fade.fade_s:g} s)")

    def configure_feedback(self, cfg: FeedbackConfig, pathways: tuple[str, ...], changes: dict) -> None:
        """New pathway constants and pathways, between ticks."""
        fb = self.source.fb
        fb.set_config(cfg)
        fb.set_pathways(pathways)
        self.out.log("info", f"feedback pathways {list(fb.pathways)}" + (f"; {changes}" if changes else ""))

    def set_cmd_vel(self, follow: bool | None, limits: CmdVelLimits, speed_map: SpeedMap | None) -> None:
        """New /cmd_vel settings (validated by the caller)."""
        if speed_map is not None:
            self.cmd.map = self.speed_map = speed_map
        self.cmd.set_limits(limits)
        if follow is not None and follow != self.follow_cmd_vel:
            self.follow_cmd_vel = follow
            if not follow and self.cmd.last is not None:
                self._stop_following("cmd_vel.follow set false")
            self.out.log("info", f"cmd_vel.follow {str(follow).lower()}")

    def _stop_following(self, why: str) -> None:
        """Back to the commanded ζ/α; the follower waits for a first message again."""
        self.cmd = CmdVelFollower(self.speed_map, self.cmd.limits, self.zeta)
        self.cmd_out, self.cmd_override = None, False
        self._turn(0.0)
        self.command(self.zeta, self.alpha)
        self.out.log("info", f"{why}: not following /cmd_vel; zeta/alpha parameters again")

    def _turn(self, rate: float) -> None:
        fb = self.source.fb
        if rate == 0.0 and fb.turn_rate != 0.0:
            fb.hold_heading()
        fb.set_turn_rate(rate)

    def twist(self, linear_x: float, angular_z: float, linear_y: float = 0.0) -> None:
        """A validated /cmd_vel message, timed by the newest tick (a Twist has no stamp)."""
        if not self.follow_cmd_vel:
            self.cmd_vel_counts["ignored"] += 1
            return
        self.cmd_vel_counts["received"] += 1
        t = (self.last_tick_ns or 0) / 1e9
        if self.cmd.last is None:
            self.out.log("info", f"following /cmd_vel from sim {t:.3f} s (timeout "
                         f"{self.cmd.limits.timeout:g} sim s)")
        self.cmd_override = False
        self.cmd.command(t, float(linear_x), float(angular_z), float(linear_y))

    def _cmd_vel_tick(self, t_ns: int) -> None:
        """The follower's output for tick t_ns, and the ankle pathway for a side step or longer steps (class
        docstring)."""
        self._follow_cmd_vel(t_ns)
        src = self.source
        side = not self.cmd_override and self.cmd.side_step_commanded
        src.fb.ankle_allowed = self.ankle_allowed or (self.ankle_for_side_step and (
            side or src.side_stepping)) or (self.ankle_for_speed and src.needs_ankle)

    def fast_available(self) -> bool:
        """Whether the governor's ankle envelope (the speed map's fast nodes) can be reached: the ankle
        pathway chosen and allowed here (lockstep, ankle_in_realtime) or closed for it (ankle_for_speed)."""
        cfg = self.governor_config
        return (cfg is not None and cfg.ankle is not None and self.feedback_on
                and "ankle" in self.source.fb.pathways and (self.ankle_allowed or self.ankle_for_speed))

    def _follow_cmd_vel(self, t_ns: int) -> None:
        """Apply the follower's output for tick t_ns (once the CPG has taken over)."""
        if self.cmd.last is None or self.cmd_override or t_ns < self.walk_from_s * 1e9 \
                or self.pending is not None:  # a take-over stands the robot first
            return
        fb = self.source.fb
        reason = turn_unavailable(self.feedback_on, self.fade.weight, fb.pathways)
        side = side_step_unavailable(reason, self.ankle_allowed, fb.pathways, self.ankle_for_side_step)
        self.cmd.allow_side_step(not side)
        self.cmd.allow_fast(self.fast_available())
        out = self.cmd.update(t_ns / 1e9, self.ctrl.zeta, self.ctrl.alpha)
        if out is None:
            return
        prev = self.cmd_out
        want = self.cmd.limits.clamp_angular(self.cmd.last[2])
        self.cmd_turn = reason if reason and want != 0.0 else "ok"
        want_y = self.cmd.limits.clamp_lateral(self.cmd.linear_y)
        self.cmd_side = side if side and want_y != 0.0 else "ok"
        if (reason and out.turn_rate != 0.0) or (side and out.linear_y != 0.0):
            out = CmdVelOutput(out.zeta, out.alpha, 0.0 if reason else out.turn_rate, out.state,
                               0.0 if side else out.linear_y)
        if side and want_y != 0.0:
            self.out.log("warn", f"/cmd_vel linear.y {want_y:g} m/s cannot side-step the robot: {side}",
                         "/cmd_vel side step")
        if reason and want != 0.0:
            self.out.log("warn", f"/cmd_vel angular.z {want:g} rad/s cannot turn the robot: {reason}",
                         "/cmd_vel turn")
        apply_output(self.source, out)
        key = (out.state, self.cmd.target)  # not each tick of an alpha ramp: a new state or command
        if prev is None or key != self._cmd_logged:
            self.out.log("info", f"/cmd_vel {out.state}: zeta {out.zeta:.3g}, alpha {out.alpha:.3g}, turn "
                         f"{out.turn_rate:.3g} rad/s at sim {t_ns / 1e9:.3f} s")
            self._cmd_logged = key
        self.cmd_out = out

    def servo_hold(self, held: bool) -> None:
        """The sim's servos hold the robot by themselves (no torques: pid_node lost) while the CPG goes on
        stepping, so the gait's phase no longer matches the frozen robot (tracking it again from
        mid-stride fell in 39 of 52 in-process runs, re-entering in 6): on release the gait re-enters from
        the crouch."""
        if held and not self.servos_held:
            self.servos_held = True
            self.out.log("warn", "the sim's servos hold the robot (no torques): the gait re-enters from "
                         "the standing crouch when they are released")
        elif not held and self.servos_held:
            self.servos_held, self.reenter_pending = False, True

    # ---------------------------------------------------------------- sensors
    def sample(self, sensor: int, t_ns: int, value: object) -> None:
        """A validated sensor sample: 0 /imu (quat wxyz, gyro), 1 and 2 the left and right sole load."""
        self.buffers[sensor].add(t_ns, value)
        if self.sensors_gave_up and self.last_tick_ns is not None and all(
                b.newest_ns is not None and b.newest_ns >= self.last_tick_ns for b in self.buffers):
            self.sensors_gave_up = False  # caught up: wait again
        if self.waiting:
            self._run_waiting()

    def dropped(self, counter: str) -> None:
        """Count a message dropped by the caller's validation (sensors_dropped, clock_dropped)."""
        self.counters[counter] += 1

    def _sample(self, t_ns: int) -> tuple[int, np.ndarray, np.ndarray, tuple[float, float]] | None:
        """(stamp ns, quat, gyro, loads) for tick t_ns: the samples stamped t_ns when all are there, else
        the newest of each (stamp: the oldest of them); None before every topic has one."""
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
        self.sensor_age_s = None if sample is None else max(0, t_ns - sample[0]) / 1e9
        if self.sensor_age_s is not None:  # how old the samples the pathways acted on were (exit stats)
            ages = self.sample_ages
            ages["ticks"] += 1
            ages["max_s"] = max(ages["max_s"], self.sensor_age_s)
            ages["older_than_ankle_max"] += self.sensor_age_s > self.source.fb.cfg.ankle_max_sample_age_s
        weight = self.fade.update(dt, self.feedback_on, self.sensor_age_s)
        self.source.fb.weight = weight
        if sample is not None and (weight > 0 or self.feedback_on):
            self.source.observe(t_ns / 1e9, sample[1], sample[2], sample[3], self.sensor_age_s)
        else:
            self.source.feedback_g = None  # faded out and off: the open-loop CPG
        state = self.fade.state(self.feedback_on)
        if state != self.feedback_state:
            age_s = self.sensor_age_s
            age = "no sample yet" if age_s is None else f"newest sample {age_s:.3f} s old"
            text = f"feedback {self.feedback_state} -> {state} at sim {t_ns / 1e9:.3f} s ({age})"
            self.out.log("warn" if state in ("fading", "stale") and self.feedback_on else "info", text)
            self.feedback_state = state

    # ---------------------------------------------------------------- clock
    def clock(self, t_ns: int) -> None:
        """A /clock tick at sim time ``t_ns`` (ns; negative ones are dropped)."""
        if t_ns < 0:  # sim time starts at 0: malformed, not a restarted sim
            self.counters["clock_dropped"] += 1
            self.out.log("warn", f"dropped /clock {t_ns / 1e9:.9g} s: before 0", "/clock negative")
            return
        last = self.last_tick_ns
        verdict = self.clock_guard.judge(last, t_ns)
        if verdict == StampGuard.DROP:  # a stray far-future tick would end the walk, an old one restart it
            self.counters["clock_dropped"] += 1
            self.out.log("warn", f"dropped /clock {t_ns / 1e9:.9g} s: far from the last tick "
                         f"{last / 1e9:.9g} s, unconfirmed", "/clock jump")
            return
        if verdict == StampGuard.RESET:
            self._clock_reset(t_ns)
        if self.last_tick_ns is None and not self.waiting and t_ns > REJOIN_AFTER_S * 1e9 \
                and self.rejoined_at_s is None:
            if self._standing_by(t_ns):
                return
            self._reenter(t_ns)
        if self.reenter_pending and self.last_tick_ns is not None:
            self.reenter_pending = False
            self._reenter(t_ns, "the servos were released")
        if self.last_tick_ns is not None and t_ns <= self.last_tick_ns:
            self._tick(t_ns)  # a re-sent (or old) tick: its targets again, from the cache
            return
        if any(t == t_ns for t, _ in self.waiting):
            return
        self.waiting.append((t_ns, self.wall()))
        self._run_waiting()

    def _clock_reset(self, t_ns: int) -> None:
        """The clock went back (a restarted sim): start over from the loaded network, as a fresh node
        would (its first tick at t_ns)."""
        self.out.log("warn", f"/clock went back from {self.last_tick_ns / 1e9:.3f} s to {t_ns / 1e9:.3f} s "
                     "(sim restarted): starting the CPG over")
        self.ctrl = storage.from_dict(self.learned_network)
        fb = self.source.fb
        self.fade.u = self.fade.weight = 0.0
        limits = self.cmd.limits
        self._start(FeedbackController(fb.cfg, fb.pathways))
        self.cmd = CmdVelFollower(self.speed_map, limits, self.zeta)
        self.clock_resets += 1

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
                self.out.log("info", f"first /clock tick at {t_ns / 1e9:.3f} s, of a running sim: standing "
                             f"by {self.rejoin_settle_ns / 1e9:g} s before re-entering the gait")
            self.join_seen_ns = seen = t_ns
        return t_ns - seen < self.rejoin_settle_ns

    def _reenter(self, t_ns: int, why: str = "joined a running sim") -> None:
        """Re-enter the gait at t_ns from the standing crouch, α ramping up from 0 to the commanded α
        (`CPGGaitSource.reenter`)."""
        self.source.reenter(t_ns / 1e9, self.zeta, self.alpha)
        self.next_horizon_ns = 0  # a horizon of the re-entered gait at once: pid_node must not fall back
        # on the last one, the gait before the re-entry, when a target is late (seen: 128 switches
        # between the two in 1.3 s after a servo release, and a fall)
        self.recent.clear()
        self.rejoined_at_s = t_ns / 1e9
        self.reentries += 1
        self.reentry_cause = why
        self.out.log("info", f"{why} at {t_ns / 1e9:.3f} s: re-entering the gait from the standing crouch "
                     f"(CPG from phase 0, alpha ramping up from 0 to {self.alpha:g}, cross-fade over "
                     f"{self.source.blend:g} s; walking from {self.walk_from_s:.3f} s)")

    def _run_waiting(self) -> None:
        """Run the queued ticks, in order, whose sensor samples are there (or need not be waited for)."""
        while self.waiting:
            t_ns, since = self.waiting[0]
            if not self._sensors_ready(t_ns, since):
                return
            self.waiting.popleft()
            self._tick(t_ns)

    def _sensors_ready(self, t_ns: int, since: float) -> bool:
        """Lockstep with feedback on (or fading): the samples stamped t_ns of every sensor, waited for up to
        sensor_wait_s wall s; after a wait timed out, no waiting until the samples catch up with the
        ticks (a dead sensor must not slow every tick down by sensor_wait_s)."""
        if not self.lockstep or self.sensors_gave_up or not (self.feedback_on or self.fade.weight > 0):
            return True
        if all(t_ns in b.samples for b in self.buffers):
            return True
        waited = self.wall() - since
        if waited <= self.sensor_wait_s:
            return False
        self.sensors_gave_up = True
        self.counters["sensor_wait_timeouts"] += 1
        self.out.log("warn", f"no /imu and /foot_load samples stamped {t_ns / 1e9:.3f} s after {waited:.2f} "
                     "wall s: going on with the newest (not reproducible)", "sensor wait")
        return True

    def idle(self) -> None:
        """Between messages (cpg_node: every executor period): a lockstep tick whose samples are late may
        have waited long enough; the pending monitor output."""
        if self.waiting:
            self._run_waiting()
        self._flush_monitor()
        self._teach_step()

    # ---------------------------------------------------------------- ticks
    def _tick(self, t_ns: int) -> None:
        """One tick (its samples there, in lockstep): /cmd_vel, feedback, targets, horizon, monitor."""
        w0 = time.perf_counter()
        self.activity.tick()
        new = self.last_tick_ns is None or t_ns > self.last_tick_ns
        if new:
            self._take_over_tick(t_ns)
            self._cmd_vel_tick(t_ns)
            self._feedback_tick(t_ns)
        if not new or t_ns != self.sent_ns:  # a re-sent tick: its target again (it may have been lost;
            self._targets(t_ns)               # the first tick has no lookahead to cover it)
        period = None
        if self.last_tick_ns is not None and t_ns > self.last_tick_ns:
            period = t_ns - self.last_tick_ns
            if self.lookahead:
                self._targets(t_ns + period)
        if new:
            self.last_tick_ns = t_ns
        if period is not None and (self.control_period_ns is None or period < self.control_period_ns):
            self.control_period_ns = period  # the sim's control period (a skipped tick only gives a multiple)
        if self.horizon_points_ns is not None and self.control_period_ns is not None \
                and t_ns >= self.next_horizon_ns:
            self._horizon(self.sent_ns, self.control_period_ns)
            self.next_horizon_ns = t_ns + self.horizon_period_ns
        if t_ns >= self.next_monitor_ns:
            self.stage = "walking" if t_ns >= self.walk_from_s * 1e9 else "starting"
            self._flush_monitor()  # a pending one first (no idle step since)
            self.monitor_due = (t_ns, state_vector(self.ctrl), self.status(t_ns))
            self.next_monitor_ns = t_ns + self.monitor_period_ns
        self.timing.tick(w0, t_ns, time.perf_counter() - w0)  # overrun: work longer than the period
        self._teach_step()  # after the tick's targets are out: learning never delays them

    def _targets(self, t_ns: int) -> None:
        cached = self.recent.get(t_ns)
        if cached is None:
            cached = self.source.targets(t_ns / 1e9)
            self.recent[t_ns] = cached
            if len(self.recent) > RECENT_KEEP:
                del self.recent[min(self.recent)]
        q, qd = cached
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):  # never to the servos: pid_node rides
            self.counters["targets_withheld"] += 1               # the gap on the horizon, then the crouch
            self.out.log("warn", f"withheld non-finite /joint_targets at sim {t_ns / 1e9:.3f} s "
                         f"({self.counters['targets_withheld']} so far)", "non-finite targets")
            return
        self.out.targets(t_ns, q, qd)
        self.sent_ns = t_ns

    def _horizon(self, t_ns: int, period_ns: int) -> None:
        """The horizon from t_ns (the newest target sent): points every control period up to
        horizon_step, then every horizon_step to horizon + horizon_stop; past the horizon the forecast's
        stepping dies out (`stop_fade`), so a pid_node that follows it to its end (this node gone) has
        stopped the robot in the gait's standing posture before it blends to the crouch."""
        w0 = time.perf_counter()
        if period_ns != self.traj_period_ns:  # the first message (or a shorter period seen since)
            head = np.arange(0, self.horizon_step_ns, period_ns, dtype=np.int64)
            self.traj_offsets_ns = np.concatenate((head, self.horizon_points_ns))
            self.traj_fade = stop_fade(self.traj_offsets_ns / 1e9, self.horizon_s, self.horizon_stop_s) \
                if self.horizon_stop_s > 0 else None
            self.traj_period_ns = period_ns
        q, qd = self.source.forecast((t_ns + self.traj_offsets_ns) / 1e9, self.traj_fade)
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            self.counters["targets_withheld"] += 1
            self.out.log("warn", f"withheld a non-finite /joint_trajectory at sim {t_ns / 1e9:.3f} s",
                         "non-finite horizon")
            return
        self.out.horizon(t_ns, self.traj_offsets_ns, q, qd)
        if len(self.horizon_work) < 100_000:
            self.horizon_work.append(time.perf_counter() - w0)

    def _flush_monitor(self) -> None:
        due, self.monitor_due = self.monitor_due, None
        if due is not None:
            self.out.monitor(*due)

    # ---------------------------------------------------------------- live teaching
    def teach(self, t_s: float, names, positions) -> None:
        """A teaching sample (/cpg/teach: teacher time ``t_s``, joint names and positions)."""
        if self.teacher is None:
            return
        self.teach_counts["received"] += 1
        self.teacher.add(t_s, names, positions, now=self.wall())
        self._teach_report()

    def _teach_step(self) -> None:
        """At most ``teach_steps`` learning steps (after a tick's output, and between messages)."""
        teacher = self.teacher
        if teacher is None or teacher.state in (IDLE, CONVERGED, REFUSED):
            return
        w0 = time.perf_counter()
        teacher.stalled(self.wall())
        if teacher.advance(self.teach_steps):
            self.teach_work.append(time.perf_counter() - w0)
        self._teach_report()

    def _teach_report(self) -> None:
        teacher = self.teacher
        now = (teacher.state, teacher.reason)
        if now == self._teach_logged:
            return
        self._teach_logged = now
        if teacher.state == REFUSED:
            self.out.log("warn", f"live teaching refused: {teacher.reason}; the walking network is untouched")
        elif teacher.state == CONVERGED:
            info = teacher.result_info
            self.out.log("info", f"live teaching converged after {info['converged_after_s']:.1f} teacher s "
                         f"({info['strides']} strides): {info['learned_frequency_hz']:.4f} Hz learned, "
                         f"the stream's {info['teacher_frequency_hz']:.4f} Hz")
        elif teacher.state != IDLE:
            self.out.log("info", f"live teaching: {teacher.state}")

    def taught(self) -> HumanoidCPG:
        """A copy of the last converged live-taught network, ready to walk and to be saved: its posture
        recording (the joints the CPG does not drive, the standing crouch) the walking network's, its
        phase 0 the stream's (``phase: stream``: it starts from standing, not from the recording's steps).
        ValueError with the reason when there is none."""
        teacher = self.teacher
        if teacher is None:
            raise ValueError("live teaching is off (cpg_node's teach parameter)")
        if teacher.result is None:
            why = f" ({teacher.reason})" if teacher.reason else ""
            raise ValueError(f"no taught network has converged yet: teaching is {teacher.state}{why}")
        ctrl = storage.from_dict(storage.to_dict(teacher.result))
        walking = self.ctrl.meta["teaching"]
        ctrl.meta["teaching"].update(stream_cycle_start_s=ctrl.meta["teaching"]["cycle_start_s"],
                                     gait=walking["gait"], cycle_start_s=walking["cycle_start_s"],
                                     phase="stream")
        return ctrl

    def take_over(self) -> str:
        """The last converged taught network walks from now on, through standing: the robot stops (α → 0
        through the governor; commands and /cmd_vel wait), the taught network cross-fades in standing
        (``FeedbackGaitSource.switch``: phase matched, ζ carried over, over ``teach_blend_s``), then the
        requested ζ/α (or /cmd_vel) step off on it. Handing over mid-stride from the walk to the taught slow
        walk fell in 1 of 3 graph runs, 2.6 s after. A sim reset starts over from the taught network.
        Returns what will happen; ValueError with the reason when it cannot."""
        ctrl = self.taught()
        if self.last_tick_ns is None or self.source.t_net < self.walk_from_s:
            raise ValueError("the CPG has not taken over from the start-up yet: try again once it walks or "
                             "stands on the CPG")
        if self.pending is not None:
            raise ValueError("a take-over is already under way (the robot is stopping)")
        self.pending = ctrl
        self.source.command(self.ctrl.zeta_command, 0.0)
        return (f"taking over with the taught network ({ctrl.gait_frequency_hz():.4f} Hz): stopping at sim "
                f"{self.last_tick_ns / 1e9:.3f} s, then cross-fading over {self.teach_blend_s:g} s standing, "
                f"then zeta {self.zeta:g}, alpha {self.alpha:g}")

    def _take_over_tick(self, t_ns: int) -> None:
        """A pending take-over switches networks once the robot stands (applied α below TAKE_OVER_ALPHA)."""
        ctrl = self.pending
        if ctrl is None or self.ctrl.alpha > TAKE_OVER_ALPHA or self.ctrl.alpha_command > 0.0:
            return
        phase = self.source.switch(ctrl, self.teach_blend_s)
        self.ctrl, self.pending = ctrl, None
        self.learned_network = storage.to_dict(ctrl)
        self.teach_counts["took_over"] += 1
        self.took_over_at_s = t_ns / 1e9
        self.source.command(self.zeta, self.alpha)
        self.out.log("info", f"the taught network took over standing at sim {t_ns / 1e9:.3f} s, "
                     f"{phase:.3f} s into its cycle; zeta {self.zeta:g}, alpha {self.alpha:g} from now on")

    def save_taught(self, path) -> str:
        """Write the last converged taught network as a CPG YAML that ``cpg_file`` loads; returns the path."""
        written = storage.save(self.taught(), path)
        self.teach_counts["saved"] += 1
        return str(written)

    def teach_status(self) -> dict[str, str]:
        """/diagnostics values of the live teaching (per DOF: frequency, amplitude, error)."""
        teacher = self.teacher
        if teacher is None:
            return {"teaching": "off"}
        p = teacher.progress()
        v = {"teaching": p["state"], "teaching_reason": p["reason"],
             "teaching_received": str(self.teach_counts["received"]),
             "teaching_streams": str(p["teachings"]),
             "teaching_took_over": str(self.teach_counts["took_over"]),
             "teaching_take_over_pending": str(self.pending is not None).lower(),
             "teaching_took_over_at_s": "none" if self.took_over_at_s is None
             else f"{self.took_over_at_s:.3f}",
             "teaching_converged_result": str(p["converged_result"]).lower()}
        for key in ("teacher_s", "strides", "teacher_frequency_hz", "correlation"):
            if key in p:
                v[f"teaching_{key}"] = f"{p[key]:.6g}"
        for key in ("learned_frequency_hz", "amplitude_rad", "error_deg"):
            for name, x in zip(teacher.names, p.get(key, ()), strict=False):
                v[f"teaching_{key}.{name}"] = f"{x:.6g}"
        for key, x in teacher.result_info.items():
            v[f"taught_{key}"] = f"{x:.6g}" if isinstance(x, float) else str(x)
        if self.teach_work:
            work = np.asarray(self.teach_work)
            v["teaching_work_ms_max"] = f"{1e3 * work.max():.3f}"
        return v

    # ---------------------------------------------------------------- status
    def status(self, t_ns: int) -> dict[str, str]:
        """The status values of /diagnostics as of now: modulation, feedback, /cmd_vel."""
        ctrl, fb, c = self.ctrl, self.source.fb, self.counters
        gov = self.source.governor
        v = {"zeta_requested": f"{self.zeta:g}", "alpha_requested": f"{self.alpha:g}",
             "zeta_command": f"{ctrl.zeta_command:g}", "zeta": f"{ctrl.zeta:.6g}",
             "alpha_command": f"{ctrl.alpha_command:g}", "alpha": f"{ctrl.alpha:.6g}",
             "governor": "off" if self.governor_config is None else gov.state if gov else "waiting",
             "governor_reason": gov.reason if gov else "",
             "feedback": self.feedback_state, "feedback_enabled": str(self.feedback_on).lower(),
             "feedback_weight": f"{self.fade.weight:.6g}",
             "sensor_age_s": "none" if self.sensor_age_s is None else f"{self.sensor_age_s:.3f}",
             "feedback_pathways": ",".join(fb.pathways), "phase_resets": str(len(fb.resets)),
             "ankle_allowed": str(self.ankle_allowed).lower(), "ankle_closed": str(fb.ankle_allowed).lower(),
             **{k: str(n) for k, n in c.items()},
             "reentries": str(self.reentries), "reentry_cause": self.reentry_cause,
             "rejoined_at_s": "none" if self.rejoined_at_s is None else f"{self.rejoined_at_s:.3f}",
             "clock_resets": str(self.clock_resets), "servos_held": str(self.servos_held).lower()}
        cmd = self.cmd
        state = ("off" if not self.follow_cmd_vel else "waiting" if cmd.last is None
                 else "parameters" if self.cmd_override else cmd.state)
        v.update({"cmd_vel": state, "cmd_vel_received": str(self.cmd_vel_counts["received"]),
                  "cmd_vel_dropped": str(self.cmd_vel_counts["dropped"]), "cmd_vel_turn": self.cmd_turn,
                  "cmd_vel_side_step": self.cmd_side})
        if cmd.last is not None:
            v.update({"cmd_vel_linear_x": f"{cmd.last[1]:g}", "cmd_vel_linear_y": f"{cmd.linear_y:g}",
                      "cmd_vel_angular_z": f"{cmd.last[2]:g}",
                      "cmd_vel_age_s": f"{max(0.0, t_ns / 1e9 - cmd.last[0]):.3f}"})
        if self.cmd_out is not None:
            o = self.cmd_out
            v.update({"cmd_vel_zeta": f"{o.zeta:.6g}", "cmd_vel_alpha": f"{o.alpha:.6g}",
                      "cmd_vel_turn_rate": f"{o.turn_rate:.6g}",
                      "cmd_vel_side_step_mps": f"{o.linear_y:.6g}"})
        return v

    def summary(self) -> dict:
        """The run's statistics (cpg_node writes them at exit)."""
        timing, fb, c = self.timing.summary(), self.source.fb, self.counters
        feedback = {"enabled": self.feedback_on, "state": self.feedback_state, "weight": self.fade.weight,
                    "pathways": list(fb.pathways), "phase_resets": len(fb.resets),
                    "phase_reset_times_s": [round(t, 3) for t, _ in fb.resets[:100]],
                    "dropped": c["sensors_dropped"], "wait_timeouts": c["sensor_wait_timeouts"],
                    "clock_dropped": c["clock_dropped"], "targets_withheld": c["targets_withheld"],
                    "sample_age": {**self.sample_ages, "max_s": round(self.sample_ages["max_s"], 4)},
                    "ankle_allowed": self.ankle_allowed, "ankle_for_side_step": self.ankle_for_side_step,
                    "ankle_for_speed": self.ankle_for_speed,
                    "ankle_fresh": fb.ankle_fresh}
        return {**self.activity.summary(), "overruns": timing["overruns"], "tick": timing,
                "feedback": feedback, "cmd_vel": self.cmd_vel_counts, "rejoined_at_s": self.rejoined_at_s,
                "reentries": self.reentries, "clock_resets": self.clock_resets,
                "teaching": self._teach_summary()}

    def _teach_summary(self) -> dict:
        """The run's live teaching: counts, the last state, and the wall time learning took per call."""
        teacher = self.teacher
        if teacher is None:
            return {"enabled": False}
        work = np.asarray(self.teach_work) * 1e3
        stats = None if not len(work) else {
            "max": round(float(work.max()), 4), "p99": round(float(np.percentile(work, 99)), 4),
            "mean": round(float(work.mean()), 4)}
        return {"enabled": True, **self.teach_counts, "state": teacher.state, "reason": teacher.reason,
                "result": teacher.result_info, "took_over_at_s": self.took_over_at_s, "calls": len(work),
                "work_ms": stats}
