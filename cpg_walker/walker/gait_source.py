"""Target sources of the in-process loop and of cpg_node: the learned CPG from standing to walking.

``CPGGaitSource`` plays the recording's opening steps, hands over to the CPG (start-up transition) and
then steps the frozen network once per control tick; ``FeedbackGaitSource`` also closes the sensory
feedback pathways of walker/feedback.py. Both have ``names`` and ``targets(t) -> (q, qd)`` (walker/loop.py's
TargetSource); the feedback one also ``observe(t, quat_wxyz, gyro, loads)``.
"""

from __future__ import annotations

import math

import numpy as np

from cpg_walker.cpg.hopf import phase
from cpg_walker.robot.gait_data import GaitPlayback, find_steady_cycle, load_gait
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.walker.controller import DOFS, HumanoidCPG
from cpg_walker.walker.feedback import (
    ANKLE2,
    ANKLE_PITCH_JOINTS,
    ANKLE_ROLL_JOINTS,
    HIP_ROLL_JOINTS,
    HIP_YAW,
    KNEE,
    RIGHT_HIP2,
    FeedbackController,
    hip_yaw_offsets,
    phase_reset,
    touchdown_phase,
)
from cpg_walker.walker.governor import Governor, GovernorConfig

#: Indices (of all joints) the ankle and free_leg pathways offset; sim s over which a forecast's offset
#: dies out.
ANKLE_PITCH = np.array([JOINT_NAMES.index(j) for j in ANKLE_PITCH_JOINTS])
ANKLE_ROLL = np.array([JOINT_NAMES.index(j) for j in ANKLE_ROLL_JOINTS])
HIP_ROLL = np.array([JOINT_NAMES.index(j) for j in HIP_ROLL_JOINTS])
ANKLE_HOLD_S = 0.1
#: |ζ| below which the turn's feedforward takes the stride period as at this ζ (no stepping rhythm there)
MIN_STRIDE_ZETA = 0.3


class CPGGaitSource:
    """A run_replay target source (``names`` = all 25 joints, ``targets(t)`` -> (q, q̇)) driven by the CPG.

    Start-up transitions from the standing posture (the recording's first row):

    * ``"recording"`` (default): play the recording's opening steps up to ``handover_s`` (default: the
      teaching cycle's start, 5.616 s for the walk — the recorded steps from standing into the steady
      gait), with the CPG started at the matching phase of the teaching cycle, then cross-fade from the
      recording (continued in its steady cycle) to the CPG over ``blend_s`` (C² smootherstep weight).
    * ``"standing"``: CPG from t = 0 at phase 0, its oscillating part faded in from α = 0 (the α filter)
      and the offsets blended from the standing posture to the learned mean posture over ``blend_s``.

    Joints the CPG does not control follow the recording until the hand-over, then hold the teaching
    cycle's mean (hip yaw ≈ 0, arms at their mean, body, and head/hands at 0 as in the replay).
    ``schedule``: list of (time_s, zeta, alpha) commands applied when t reaches time_s. With the
    "recording" transition, `zeta`/`alpha` other than 1 are commanded when the cross-fade ends (the CPG
    takes over the recording at the recording's pace first). ``governor``: the config of a Governor
    (walker/governor.py) between the commands and the CPG once it has taken over; None: the commands go to
    the CPG as they are (the raw controller, for measuring its envelope)."""

    def __init__(self, ctrl: HumanoidCPG, transition: str = "recording", handover_s: float | None = None,
                 blend_s: float = 1.0, schedule: list[tuple[float, float, float]] | None = None,
                 zeta: float = 1.0, alpha: float = 1.0, governor: GovernorConfig | None = None):
        if transition not in ("recording", "standing"):
            raise ValueError(f"unknown transition {transition!r}; use 'recording' or 'standing'")
        if ctrl.meta["teaching"].get("phase") == "stream":  # taught live: its phase 0 is not the recording's
            transition = "standing"
        if not (blend_s >= 0 and math.isfinite(blend_s)):
            raise ValueError(f"blend_s must be >= 0, got {blend_s}")
        self.ctrl = ctrl
        self.names = JOINT_NAMES
        self.transition = transition
        gait = load_gait(ctrl.meta["teaching"]["gait"])
        self.playback = GaitPlayback(gait, cycle=find_steady_cycle(gait))
        self.standing = self.playback.standing_posture()
        cyc_start = float(ctrl.meta["teaching"]["cycle_start_s"])
        self.handover = cyc_start if handover_s is None else float(handover_s)
        if transition == "standing":
            self.handover = 0.0
        if self.handover < 0:
            raise ValueError(f"handover_s must be >= 0, got {handover_s}")
        self.blend = float(blend_s)
        self._idx = np.array([JOINT_NAMES.index(j) for j in DOFS])
        i0 = round(cyc_start / gait.dt)
        n = round(ctrl.period / gait.dt)
        hold = np.zeros(len(JOINT_NAMES))
        for j, name in enumerate(JOINT_NAMES):
            if name in gait.names:
                hold[j] = gait.column(name)[i0 : i0 + n].mean()
        self.hold = hold
        self.schedule = sorted(schedule or [])
        h = ctrl.settings.control_dt
        self.h = h
        # CPG phase at the hand-over: the recording time handover maps to this time within the cycle
        phase_s = (self.handover - cyc_start) % ctrl.period if transition == "recording" else 0.0
        ctrl.reset_phase(phase_s)
        self.governor_config = governor
        if transition == "standing":
            ctrl.set_modulation_state(zeta, 0.0)
            ctrl.set_alpha(self._start_alpha(zeta, alpha))
            if self._start_alpha(zeta, alpha) != alpha:  # the rest through the governor at the takeover
                self.schedule = sorted([*self.schedule, (self.handover + self.blend, zeta, alpha)])
        else:  # take over the recording at its own pace; the requested ζ, α are commanded after the blend
            ctrl.set_modulation_state(1.0, 1.0)
            if (zeta, alpha) != (1.0, 1.0):
                self.schedule = sorted([*self.schedule, (self.handover + self.blend, zeta, alpha)])
        self._t_net = self.handover  # sim time the network state corresponds to
        self.governor: Governor | None = None  # made at the takeover, from the commands then
        self._cache = None
        self.feedback_g: np.ndarray | None = None  # eqs 16–17 g_k applied while stepping (feedback.py)
        self.fading: tuple[HumanoidCPG, float, float] | None = None  # a hand-over's (old network, from, s)

    def reenter(self, t: float, zeta: float, alpha: float) -> None:
        """Re-enter the gait at sim time ``t`` > 0 (a cpg node (re)started while the sim runs, or after a
        sim reset past the hand-over): the ``"standing"`` transition started at ``t`` instead of 0 — the
        CPG from phase 0 with α ramping up from 0 (its command filter) and the offsets blended from the
        standing crouch (the posture pid_node's watchdog holds when targets stop) over ``blend``; no
        recording, pending commands dropped. ``zeta``, ``alpha``: the commands to walk at."""
        if not (t >= 0 and math.isfinite(t)):
            raise ValueError(f"re-entry time must be a finite sim time >= 0, got {t}")
        self.transition = "standing"
        self.handover = float(t)
        self.schedule = []
        self.fading = None
        self.ctrl.reset_phase(0.0)
        self.ctrl.set_modulation_state(zeta, 0.0)
        first = self._start_alpha(zeta, alpha)
        self.ctrl.set_alpha(first)
        self._t_net = self.handover
        self.feedback_g = None
        if self.governor is not None:
            self.governor.reset(zeta, first)
            self.governor.request(zeta, alpha)

    @property
    def t_net(self) -> float:
        """The sim time the network's state corresponds to."""
        return self._t_net

    @property
    def takeover_s(self) -> float:
        """The sim time from which the CPG alone drives: the end of the start-up (or re-entry) cross-fade."""
        return self.handover + self.blend

    def command(self, zeta: float, alpha: float) -> bool:
        """Command ζ and α: the one entry point of a running source (a node's parameters, /cmd_vel's
        output). Before the CPG has taken over (the network behind ``takeover_s``) the command waits for
        the end of the cross-fade, replacing any pending one; True when it was deferred so."""
        if self._t_net < self.takeover_s:
            self.schedule = [(self.takeover_s, zeta, alpha)]
            return True
        self._request(zeta, alpha)
        return False

    def _request(self, zeta: float, alpha: float, at: float | None = None) -> None:
        """To the governor once the CPG has taken over (at sim time ``at``, default the network's). The
        start-up command (due at the takeover, the network not there yet) goes to the CPG's filters at
        once with α capped to the envelope, as the envelope's "from standing" cells were measured; the
        governor starts from it."""
        cfg = self.governor_config
        if self.governor is None and cfg is not None and at is not None and self._t_net < self.takeover_s \
                and at >= self.takeover_s - 1e-9:
            first = self._start_alpha(zeta, alpha)
            self.ctrl.set_zeta(zeta)
            self.ctrl.set_alpha(first)
            self.governor = Governor(cfg, zeta, first)
            self.governor.request(zeta, alpha)
            return
        gov = self._governor(at)
        if gov is not None:
            gov.request(zeta, alpha)
        else:
            self.ctrl.set_zeta(zeta)
            self.ctrl.set_alpha(alpha)

    def _start_alpha(self, zeta: float, alpha: float) -> float:
        """The α a start-up (from standing, the recording's takeover, a re-entry) ramps to at once: capped
        to the envelope of the pathways that will be closed then (the governor's, none: as requested), so
        the ramp never overshoots what walks before the governor takes over."""
        cfg = self.governor_config
        if cfg is None:
            return alpha
        env = cfg.envelope if self._closes_loop() else (cfg.open_loop or cfg.envelope)
        return min(alpha, env.alpha_max(zeta))

    def _open_loop(self) -> bool:
        """No feedback pathways closed (the governor's open-loop envelope)."""
        return True

    def _closes_loop(self) -> bool:
        """Feedback pathways will close at the takeover (the envelope of the start-up command)."""
        return False

    def _ankle_state(self) -> tuple[bool, bool]:
        """(The ankle pathway is closed at full weight: the governor's ``ankle`` envelope, it fades in)."""
        return False, False

    @property
    def needs_ankle(self) -> bool:
        """The governor wants the ankle pathway for the request or the applied steps (``needs_ankle``)."""
        gov = self.governor
        return gov is not None and gov.needs_ankle(self.ctrl.zeta, self.ctrl.alpha)

    def _governor(self, at: float | None = None) -> Governor | None:
        """The governor once the CPG has taken over (made then, from the commands as they stand): from
        the network's time, or ``at`` (a command due at the takeover goes through it too)."""
        t = self._t_net if at is None else at
        if self.governor is None and self.governor_config is not None and t >= self.takeover_s - 1e-9:
            self.governor = Governor(self.governor_config, self.ctrl.zeta_command, self.ctrl.alpha_command)
        return self.governor

    def switch(self, ctrl: HumanoidCPG, blend_s: float) -> float:
        """Hand the gait over to another learned network (a live-taught one taking over): its oscillators at
        the phase whose pattern is nearest the walking one's (``HumanoidCPG.match_phase``), the applied and
        commanded ζ/α, the per-DOF amplitude factors and the governor carried over, and the CPG DOFs' targets
        cross-faded from the old network (stepped on meanwhile) to the new over ``blend_s`` sim s (C²
        smootherstep, as the start-up's cross-fade). Returns the phase chosen (s after its phase 0)."""
        if not (blend_s >= 0 and math.isfinite(blend_s)):
            raise ValueError(f"blend_s must be >= 0, got {blend_s}")
        old = self.ctrl
        phase_s = ctrl.match_phase(old.unit_pattern())
        ctrl.dof_scale = old.dof_scale.copy()
        ctrl.set_modulation_state(old.zeta, old.alpha)
        ctrl.set_zeta(old.zeta_command)
        ctrl.set_alpha(old.alpha_command)
        self.fading = (old, self._t_net, float(blend_s)) if blend_s > 0 else None
        self.ctrl = ctrl
        return phase_s

    def _advance(self, t: float) -> None:
        while self.schedule and self.schedule[0][0] <= t + 1e-12:
            t_cmd, z, a = self.schedule.pop(0)
            self._request(z, a, t_cmd)
        ctrl = self.ctrl
        while self._t_net + 0.5 * self.h <= t:
            gov = self._governor()
            if gov is not None:
                z, a = gov.update(self.h, ctrl.zeta, ctrl.alpha, self._open_loop(), *self._ankle_state())
                if z != ctrl.zeta_command:
                    ctrl.set_zeta(z)
                if a != ctrl.alpha_command:
                    ctrl.set_alpha(a)
            ctrl.step(self.h, self.feedback_g)
            if self.fading is not None:  # the old network of a hand-over, under the same commands
                old = self.fading[0]
                old.set_zeta(ctrl.zeta_command)
                old.set_alpha(ctrl.alpha_command)
                old.set_dof_amplitude_scale(ctrl.dof_scale)
                old.step(self.h, self.feedback_g)
            self._t_net += self.h

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t < self.handover:
            return self.playback.targets(t)
        self._advance(t)
        qc, qdc = self.ctrl.joint_targets()
        if self.fading is not None:
            qc, qdc = self._fade_from_old(qc, qdc)
        return self._compose(t, qc, qdc)

    def _fade_from_old(self, qc: np.ndarray, qdc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A hand-over's cross-fade (``switch``) of the CPG DOFs at the network's time; ends it when done."""
        old, since, blend = self.fading
        u = (self._t_net - since) / blend
        if u >= 1.0:
            self.fading = None
            return qc, qdc
        qo, qdo = old.joint_targets()
        w, dw = smootherstep(u)
        return (1 - w) * qo + w * qc, (1 - w) * qdo + w * qdc + dw / blend * (qc - qo)

    def forecast(self, times: np.ndarray, fade: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The targets ``targets(t)`` will give at ``times`` (sim s, non-decreasing), predicted without
        advancing the source: the recording where it plays (exact), the CPG's future from
        `HumanoidCPG.forecast` from the network's current time on, composed as `targets` does. Times
        before the network's time take the network's current output; pending ``schedule`` commands
        and feedback changes are not foreseen. ``fade``: (K,) factors on the CPG's α at ``times``
        (`stop_fade`: a stop foreseen; None = none). Two (K, 25) arrays."""
        times = np.asarray(times, dtype=float).reshape(-1)
        q = np.empty((times.size, len(JOINT_NAMES)))
        qd = np.empty_like(q)
        cpg = times >= self.handover
        for k in np.flatnonzero(~cpg):
            q[k], qd[k] = self.playback.targets(float(times[k]))
        if cpg.any():
            qc, qdc = self.ctrl.forecast(np.maximum(times[cpg] - self._t_net, 0.0),
                                         None if fade is None else np.asarray(fade, dtype=float)[cpg])
            rows = np.flatnonzero(cpg)
            u = (times[rows] - self.handover) / self.blend if self.blend > 0 else np.ones(rows.size)
            done = u >= 1.0  # past the cross-fade (what _compose gives, for all these points at once)
            q[rows[done]] = self.hold
            q[np.ix_(rows[done], self._idx)] = qc[done]
            qd[rows[done]] = 0.0
            qd[np.ix_(rows[done], self._idx)] = qdc[done]
            for j in np.flatnonzero(~done):
                q[rows[j]], qd[rows[j]] = self._compose(float(times[rows[j]]), qc[j], qdc[j])
        return q, qd

    def _compose(self, t: float, qc: np.ndarray, qdc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All joints' (q, q̇) at t >= handover from the CPG DOFs' (qc, qdc): the cross-fade, then the CPG
        with the other joints held."""
        q = self.hold.copy()
        qd = np.zeros(len(JOINT_NAMES))
        u = (t - self.handover) / self.blend if self.blend > 0 else 1.0
        if u >= 1.0:
            q[self._idx] = qc
            qd[self._idx] = qdc
            return q, qd
        w, dw = smootherstep(u)
        dw /= self.blend
        if self.transition == "recording":
            q0, qd0 = self.playback.targets(t)
        else:
            q0 = self.standing.copy()
            qd0 = np.zeros(len(JOINT_NAMES))
            q0[self._idx] = self.standing[self._idx] + (qc - self.ctrl.net.offset)  # sway about standing
            qd0[self._idx] = qdc
        q[self._idx] = qc
        qd[self._idx] = qdc
        q_out = (1 - w) * q0 + w * q
        qd_out = (1 - w) * qd0 + w * qd + dw * (q - q0)
        return q_out, qd_out


def smootherstep(u: float) -> tuple[float, float]:
    """w(u) = 6u⁵ − 15u⁴ + 10u³ on [0, 1] (C², zero slope and curvature at both ends) and dw/du."""
    u = min(max(u, 0.0), 1.0)
    return _smoother(u), 30 * u * u * (1 - u) ** 2


def _smoother(u):
    """6u⁵ − 15u⁴ + 10u³ of u (a float or an array, already in [0, 1])."""
    return u**3 * (10 - 15 * u + 6 * u * u)


def stop_fade(offsets_s: np.ndarray, start_s: float, stop_s: float) -> np.ndarray:
    """The α factor of a foreseen stop at each offset (s ahead): 1 up to ``start_s``, then down to 0 over
    ``stop_s`` along 1 − smootherstep (C², no jerk at either end), 0 after: the stepping dies out and
    the robot stands in the gait's mean posture (α = 0: the offsets). The tail of cpg_node's horizon."""
    if not (start_s >= 0 and stop_s >= 0 and math.isfinite(start_s + stop_s)):
        raise ValueError(f"stop_fade: start {start_s} and duration {stop_s} must be finite and >= 0")
    u = (np.asarray(offsets_s, dtype=float) - start_s) / stop_s if stop_s > 0 else \
        np.where(np.asarray(offsets_s, dtype=float) > start_s, 1.0, 0.0)
    u = np.clip(u, 0.0, 1.0)
    return 1.0 - _smoother(u)


class FeedbackGaitSource(CPGGaitSource):
    """CPGGaitSource with the feedback pathways (walker/feedback.py) closed after the hand-over cross-fade.

    The loop calls ``observe(t, quat_wxyz, gyro, loads)`` every control tick before ``targets(t)``. Once
    the CPG has taken over (t >= handover + blend; the heading reference is captured then, or at the first
    observation with ``heading_reference: start``) the g vector of
    eqs 14–18 (at the applied ζ) is held over the network steps, the per-DOF amplitude factors follow the
    applied ζ, touchdowns reset the phase ("reset": right foot, the paper's; "reset_both": either foot)
    and the hip yaws get the heading pathway's oscillation."""

    trace_dt = 0.01  # s of sim time between g_trace samples
    #: Keep g_trace and the touchdown logs (for plots of a run); a node that runs for hours sets it False
    #: (g_trace alone grows ~18 kB per sim s).
    keep_traces = True

    def __init__(self, ctrl: HumanoidCPG, feedback: FeedbackController, **kwargs):
        self.fb = feedback  # first: the start-up's α cap depends on the pathways it will close
        super().__init__(ctrl, **kwargs)
        self._next_trace = -math.inf
        self.active_from = self.handover + self.blend
        self.g_trace: list[tuple[float, float, float, float, float]] = []  # t, roll, pitch, g_Ankle2, g_Knee
        self.touchdown_phases: list[float] = []  # right Hip2 oscillator 0 phase at right touchdowns
        self.touchdown_log: list[tuple[float, float, float]] = []  # (t, applied ζ, that phase), right foot
        self._yaw_u = 0.0
        self._yaw_idx = np.array([JOINT_NAMES.index(j) for j in HIP_YAW])
        self._ankle = (0.0, 0.0)  # the ankle pathway's (pitch, roll) offsets
        self._free_leg = (0.0, 0.0)  # the free_leg pathway's (left, right) hip roll offsets
        self.side_step = 0.0  # m/s commanded sideways (/cmd_vel linear.y)
        self._side_v = 0.0  # rad, the side step's hip-roll amplitude (slewed)
        self._t_obs: float | None = None

    def observe(self, t: float, quat_wxyz: np.ndarray, gyro: np.ndarray, loads: tuple[float, float],
                age_s: float = 0.0) -> None:
        fb = self.fb
        fb.observe(t, quat_wxyz, gyro, loads, age_s)
        if fb.heading_ref is None and (t >= self.active_from or fb.cfg.heading_reference == "start"):
            fb.capture_heading()
        if t < self.active_from:
            return
        self._advance(t)  # the network at t before the reset / the new g
        z = self.ctrl.zeta
        g = fb.g(z)
        self.feedback_g = g if np.any(g) else None
        self.ctrl.set_dof_amplitude_scale(fb.amplitude(z))
        st = self.ctrl.net.state
        if fb.touchdowns[1] and self.keep_traces:
            ph = phase(st[0, RIGHT_HIP2, 0], st[1, RIGHT_HIP2, 0])
            self.touchdown_phases.append(ph)
            self.touchdown_log.append((t, z, ph))
        for target, strength in fb.reset_events(z, self.ctrl.alpha):
            d = phase_reset(st, self.ctrl.net.omega, target, strength=strength)
            fb.resets.append((t, d))
        stride_s = self.ctrl.period / max(abs(z), MIN_STRIDE_ZETA)
        self._yaw_u = fb.heading_amplitude(stride_s, self.ctrl.alpha)
        self._side_step_update(t, stride_s)
        self._ankle = fb.ankle_offsets()
        self._free_leg = fb.free_leg_offsets(self.ctrl.alpha)
        if self.keep_traces and t >= self._next_trace - 1e-9:  # one per trace_dt, whatever the tick rate
            self.g_trace.append((t, *fb.psi, float(g[ANKLE2[0]]), float(g[KNEE[0]])))
            self._next_trace = t + self.trace_dt

    @property
    def side_stepping(self) -> bool:
        """A side step is commanded or its amplitude has not yet wound down to 0."""
        return self.side_step != 0.0 or self._side_v != 0.0

    def _side_step_update(self, t: float, stride_s: float) -> None:
        """Move the side step's amplitude toward side_step_gain·linear.y·T (clipped), at side_step_rate."""
        cfg = self.fb.cfg
        lim = cfg.side_step_limit_rad
        want = min(max(cfg.side_step_gain * self.side_step * stride_s, -lim), lim) * self.fb.weight
        dt = 0.0 if self._t_obs is None else max(t - self._t_obs, 0.0)
        self._t_obs = t
        step = cfg.side_step_rate * dt
        self._side_v = min(max(want, self._side_v - step), self._side_v + step)

    def _closes_loop(self) -> bool:
        return bool(self.fb.pathways) and self.fb.weight > 0.0

    def _ankle_state(self) -> tuple[bool, bool]:
        fb = self.fb
        on = "ankle" in fb.pathways and fb.ankle_allowed and not self._open_loop()
        return on and fb.ankle_fresh >= 1.0, on and fb.ankle_fresh < 1.0

    def _open_loop(self) -> bool:
        """The pathways are not all closed at full weight (none chosen, fading, or not yet active)."""
        fb = self.fb
        return not fb.pathways or fb.weight < 1.0 or self._t_net < self.active_from

    def reenter(self, t: float, zeta: float, alpha: float) -> None:
        """`CPGGaitSource.reenter`; the feedback pathways close once its cross-fade ends."""
        super().reenter(t, zeta, alpha)
        self.active_from = self.handover + self.blend
        self._yaw_u = 0.0
        self._ankle = self._free_leg = (0.0, 0.0)
        self._side_v = 0.0

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        q, qd = super().targets(t)
        if self._offsets_act() and t >= self.active_from:
            q, qd = q.copy(), qd.copy()
            self._add_offsets(q, qd, 0.0, 1.0)
        return q, qd

    def forecast(self, times: np.ndarray, fade: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """`CPGGaitSource.forecast` plus the heading pathway's hip-yaw oscillation and the side step at
        the held amplitudes (their phase advanced at the current frequency; ``fade`` scales them with the
        steps), and the ankle and free-leg offsets dying out ahead. All points at once: cpg_node computes
        this horizon between two ticks (a per-point loop took 2 of its 3 ms, longer than a tick)."""
        q, qd = super().forecast(times, fade)
        if not self._offsets_act():
            return q, qd
        times = np.asarray(times, dtype=float).reshape(-1)
        rows = np.flatnonzero(times >= self.active_from)
        if rows.size == 0:
            return q, qd
        ahead = np.maximum(times[rows] - self._t_net, 0.0)
        scale = np.ones(rows.size) if fade is None else np.asarray(fade, dtype=float).reshape(-1)[rows]
        qs, qds = q[rows], qd[rows]
        self._add_offsets(qs, qds, ahead, scale)
        q[rows], qd[rows] = qs, qds
        return q, qd

    def _offsets_act(self) -> bool:
        """Any of the heading, ankle and free_leg pathways' joint offsets is non-zero now."""
        return (self._yaw_u != 0.0 or self._side_v != 0.0 or self._ankle != (0.0, 0.0)
                or self._free_leg != (0.0, 0.0))

    def _reference_phase(self, ahead_s: float) -> tuple[float, float]:
        """(θ, θ̇) of the right Hip2 main oscillator ``ahead_s`` from now (at the current frequency)."""
        net = self.ctrl.net
        st = net.state
        w = float(net.frequencies()[RIGHT_HIP2, 0])
        return phase(st[0, RIGHT_HIP2, 0], st[1, RIGHT_HIP2, 0]) + w * ahead_s, w

    def _add_offsets(self, q: np.ndarray, qd: np.ndarray, ahead_s, scale) -> None:
        """Add the pathways' joint offsets to targets (q, q̇) ``ahead_s`` from now, scaled by ``scale``: one
        row (25,) with scalars, or (K, 25) rows with (K,) arrays (a forecast at once).

        * heading: hip yaws q_R = −q_L = u·cos(θ − φ_TD) at the held u, θ advanced at the current rate;
        * side step: hip rolls q_R = −q_L = v·cos(θ − φ_TD + side_step_phase_rad), the ankle rolls
          −FeedbackController.side_step_ankle_ratio() times that (1: soles level; 0: they tilt with the legs);
        * ankle and free leg: the offsets of now, dying out ahead (a reaction to now)."""
        theta, w = self._reference_phase(ahead_s)
        cfg = self.fb.cfg
        phi_td = touchdown_phase(self.ctrl.zeta, cfg)
        if self._yaw_u != 0.0:
            dq, dqd = hip_yaw_offsets(scale * self._yaw_u, theta, phi_td, w)
            q[..., self._yaw_idx] += dq
            qd[..., self._yaw_idx] += dqd
        if self._side_v != 0.0:
            dq, dqd = hip_yaw_offsets(scale * self._side_v, theta + cfg.side_step_phase_rad, phi_td, w)
            ratio = self.fb.side_step_ankle_ratio(self.ctrl.alpha, self._side_v)
            for idx, sign in ((HIP_ROLL, 1.0), (ANKLE_ROLL, -ratio)):
                q[..., idx] += sign * dq
                qd[..., idx] += sign * dqd
        hold = np.asarray(scale * np.exp(-np.asarray(ahead_s) / ANKLE_HOLD_S))[..., None]
        q[..., ANKLE_PITCH] += hold * self._ankle[0]
        q[..., ANKLE_ROLL] += hold * self._ankle[1]
        q[..., HIP_ROLL] += hold * np.asarray(self._free_leg)
