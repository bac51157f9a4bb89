"""Riding out a gap in the live joint targets on a horizon of future ones (pid_node's logic; no ROS).

A target source that knows its future (cpg_node) publishes, beside the live targets, a short horizon of
them: a joint trajectory (``trajectory_msgs/JointTrajectory``: points at times after a start stamp, with
positions and velocities). When the live targets stop coming (the source is starved of CPU, a discovery
burst, a GC pause), the servo follows the horizon at the state's sim time; past the horizon's end it
goes to a safe posture (the standing crouch); when the live targets come back it returns to them.

Every change of what is followed is C¹: at the switch, the reference as it was (position and velocity)
minus the new source's is an offset that decays to zero along a cubic Hermite curve over a set time
(`OffsetBlend`). The reference never jumps, whatever the order of the switches (a new switch starts from
the blended reference). All times are integer nanoseconds of sim time (the stamps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: What the servo follows (`GapBridge.mode`).
LIVE, HORIZON, SAFE = "live", "horizon", "safe"


@dataclass(frozen=True)
class Trajectory:
    """Future targets of the joints ``index`` (into JOINT_NAMES): ``q``/``qd`` (P, J) at ``start_ns`` +
    ``offsets_ns`` (P,), strictly increasing, >= 0. Between points: cubic Hermite (C¹, exact for
    cubics: with points 40 ms apart, a 2 Hz harmonic is interpolated within ~1e-5 of its amplitude)."""

    start_ns: int
    offsets_ns: np.ndarray
    index: np.ndarray
    q: np.ndarray
    qd: np.ndarray

    @property
    def first_ns(self) -> int:
        return self.start_ns + int(self.offsets_ns[0])

    @property
    def end_ns(self) -> int:
        return self.start_ns + int(self.offsets_ns[-1])

    def covers(self, t_ns: int) -> bool:
        return self.first_ns <= t_ns <= self.end_ns

    def sample(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) of the trajectory's joints at t: Hermite between points; before the first point that
        point; after the last, its linear continuation (used only for the instant of a switch)."""
        rel = t_ns - self.start_ns
        offs = self.offsets_ns
        if rel <= offs[0]:
            return self.q[0].copy(), self.qd[0].copy()
        if rel >= offs[-1]:
            dt = (rel - int(offs[-1])) * 1e-9
            return self.q[-1] + self.qd[-1] * dt, self.qd[-1].copy()
        i = int(np.searchsorted(offs, rel, side="right")) - 1
        return hermite((rel - int(offs[i])) * 1e-9, (int(offs[i + 1]) - int(offs[i])) * 1e-9,
                       self.q[i], self.qd[i], self.q[i + 1], self.qd[i + 1])


def hermite(s: float, h: float, q0: np.ndarray, v0: np.ndarray, q1: np.ndarray,
            v1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cubic through (q0, v0) at 0 and (q1, v1) at h, and its derivative, at s in [0, h]."""
    u = s / h
    u2, u3 = u * u, u * u * u
    h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
    d00, d10, d01, d11 = 6 * u2 - 6 * u, 3 * u2 - 4 * u + 1, -6 * u2 + 6 * u, 3 * u2 - 2 * u
    q = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
    v = (d00 * q0 + d01 * q1) / h + d10 * v0 + d11 * v1
    return q, v


class OffsetBlend:
    """An offset (d, ḋ) at ``t0_ns`` that decays to (0, 0) at t0 + ``duration_s`` along a cubic Hermite
    curve (C¹ at both ends; velocity peak 1.5·|d|/duration for ḋ = 0), then stays 0."""

    def __init__(self, t0_ns: int, d: np.ndarray, dv: np.ndarray, duration_s: float):
        self.t0_ns, self.d, self.dv, self.duration = t0_ns, d, dv, float(duration_s)
        self.end_ns = t0_ns + round(self.duration * 1e9)

    def at(self, t_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(offset, its rate) at t, or None once the blend is over."""
        if t_ns >= self.end_ns or self.duration <= 0:
            return None
        zero = np.zeros_like(self.d)
        return hermite(max(0, t_ns - self.t0_ns) * 1e-9, self.duration, self.d, self.dv, zero, zero)


class GapBridge:
    """The reference the servo follows at each state time ``t`` (sim ns):

    * LIVE: the live targets, while the newest one is stamped at or after t;
    * HORIZON: else the newest trajectory, sampled at t, while it covers t;
    * SAFE: else ``safe_q`` (velocity 0): the standing crouch.

    A switch blends from the reference at the switch to the new source (`OffsetBlend`): over
    ``safe_blend_s`` into SAFE, ``resume_blend_s`` otherwise (back to LIVE, or HORIZON -> a newer
    horizon). Without any trajectory the bridge is inactive (`active` False) and answers LIVE."""

    def __init__(self, safe_q: np.ndarray, safe_blend_s: float, resume_blend_s: float):
        self.safe_q = np.asarray(safe_q, dtype=float)
        self.safe_blend_s, self.resume_blend_s = float(safe_blend_s), float(resume_blend_s)
        self.trajectory: Trajectory | None = None
        self.newest: Trajectory | None = None
        self.mode = LIVE
        self.blend: OffsetBlend | None = None
        self.switched: tuple[str, str] | None = None  # (from, to) of the last `reference` call's switch

    @property
    def active(self) -> bool:
        return self.newest is not None

    def offer(self, traj: Trajectory) -> None:
        """A received trajectory; the newest (by start stamp) is followed from the next state on."""
        if self.newest is None or traj.start_ns >= self.newest.start_ns:
            self.newest = traj

    def reference(self, t_ns: int, live_q: np.ndarray, live_v: np.ndarray,
                  live_ns: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) to follow at t given the live targets (``live_ns``: the newest one's stamp, None before
        any). Returns the live arrays themselves while LIVE and not blending.

        A switch compares the sources at the same instant t: the live target, stamped ``live_ns``, is
        carried to t for that comparison (`_source`; a live target one period old is the same signal
        as the horizon at t, not an offset to blend away), so going onto and off the horizon blends only
        the forecast's error, and only a real difference (the standing posture) is blended over the set
        time."""
        self.switched = None
        if live_ns is not None and live_ns >= t_ns:
            want = LIVE
        elif self.newest is not None and self.newest.covers(t_ns):
            want = HORIZON
        elif self.newest is None:
            want = LIVE
        else:
            want = SAFE
        live = (live_q, live_v, t_ns if live_ns is None else live_ns)
        newer = want == HORIZON and self.newest is not self.trajectory
        if want != self.mode or (newer and self.mode == HORIZON):
            q_old, v_old = self._output(self.mode, t_ns, live, at_t=True)
            if newer:
                self.trajectory = self.newest
            q_new, v_new = self._source(want, t_ns, live, at_t=True)
            duration = self.safe_blend_s if want == SAFE else self.resume_blend_s
            self.blend = OffsetBlend(t_ns, q_old - q_new, v_old - v_new, duration)
            self.switched = (self.mode, want)
            self.mode = want
        elif newer:
            self.trajectory = self.newest
        return self._output(self.mode, t_ns, live, at_t=False)

    def _source(self, mode: str, t_ns: int, live: tuple, at_t: bool) -> tuple[np.ndarray, np.ndarray]:
        """The source's (q, q̇) at t; ``at_t``: the live targets carried from their stamp to t, along
        the newest horizon where it covers both instants (what the signal does in between), else along
        their velocity."""
        live_q, live_v, live_ns = live
        if at_t and live_ns != t_ns:
            live_q = live_q + live_v * ((t_ns - live_ns) * 1e-9)
            traj = self.newest
            if traj is not None and traj.covers(live_ns) and traj.covers(t_ns):
                (q1, v1), (q0, v0) = traj.sample(t_ns), traj.sample(live_ns)
                live_q, live_v = live_q.copy(), live_v.copy()
                live_q[traj.index] = live[0][traj.index] + (q1 - q0)
                live_v[traj.index] = live_v[traj.index] + (v1 - v0)
        if mode == SAFE:
            return self.safe_q, np.zeros_like(self.safe_q)
        if mode == HORIZON and self.trajectory is not None:
            q, v = live_q.copy(), live_v.copy()  # joints the trajectory does not name: the live targets
            tq, tv = self.trajectory.sample(t_ns)
            q[self.trajectory.index], v[self.trajectory.index] = tq, tv
            return q, v
        return live_q, live_v

    def _output(self, mode: str, t_ns: int, live: tuple, at_t: bool) -> tuple[np.ndarray, np.ndarray]:
        q, v = self._source(mode, t_ns, live, at_t)
        if self.blend is not None:
            off = self.blend.at(t_ns)
            if off is None:
                self.blend = None
            else:
                q, v = q + off[0], v + off[1]
        return q, v
