"""The controller lost and back, in-process, at phases over a whole stride (``cpg-walker faults
--in-process``): what the graph's pid_node fault does, without DDS or wall-clock noise.

The walking robot (the learned CPG with feedback, zeta 1, the in-process loop of walker/loop.py) loses
its PID at ``t_kill``: after ``hold_after`` s the servos hold the posture measured then (sim_node's
``ServoHold``: the PID law towards that posture, velocity 0) while the CPG goes on stepping; ``away`` s
later a new PID takes over and blends from the measured posture to the gait's targets over
``resume_blend`` (pid_node's join blend). Two ways back are compared:

* ``live``: track the gait where the CPG has got to (what pid_node alone does);
* ``reenter``: the gait re-enters from the standing crouch at that moment (``CPGGaitSource.reenter``:
  CPG from phase 0, alpha ramping up), what cpg_node does on the release of /sim/servo_hold.

Per kill time: fell or not (and when), and the speed over the last ``window`` s.
"""

from __future__ import annotations

import numpy as np

from cpg_walker.robot.joints import JOINT_NAMES

#: Kill times: 11 over a stride (1.26 s at zeta 1) once the CPG walks alone (from 6.6 s).
KILL_TIMES = tuple(round(8.0 + 0.25 * k, 2) for k in range(11))
MODES = ("live", "reenter")


def smoothstep(u: float) -> tuple[float, float]:
    """C1 cubic from 0 to 1 over u in [0, 1] and its derivative (pid_node's blend)."""
    u = min(max(u, 0.0), 1.0)
    return u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u)


class ControllerLoss:
    """A target source: the gait, then the servos' hold of the posture at the loss, then a new PID's
    blend from the measured posture back to the gait (``mode``: live or re-entered)."""

    def __init__(self, sim, source, t_kill: float, away: float, mode: str, hold_after: float,
                 resume_blend: float, zeta: float = 1.0, alpha: float = 1.0) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.sim, self.source, self.mode = sim, source, mode
        self.t_hold, self.t_back = t_kill + hold_after, t_kill + away
        self.blend, self.zeta, self.alpha = resume_blend, zeta, alpha
        self.names = source.names
        self.observe = source.observe
        self._adr = sim._qadr[np.array([JOINT_NAMES.index(n) for n in source.names])]
        self.q_hold: np.ndarray | None = None
        self.offset: np.ndarray | None = None
        self.t0 = 0.0

    def _measured(self) -> np.ndarray:
        return self.sim.data.qpos[self._adr].copy()

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t < self.t_hold:  # the PID still answers (the held torque until servo_hold_after: ~ the same)
            return self.source.targets(t)
        if t < self.t_back:
            if self.q_hold is None:
                self.q_hold = self._measured()
            self.source.targets(t)  # the CPG goes on stepping meanwhile
            return self.q_hold, np.zeros_like(self.q_hold)
        if self.offset is None:
            if self.mode == "reenter":
                self.source.reenter(t, self.zeta, self.alpha)
            self.offset = self._measured() - self.source.targets(t)[0]
            self.t0 = t
        q, qd = self.source.targets(t)
        w, dw = smoothstep((t - self.t0) / self.blend)
        return q + (1.0 - w) * self.offset, qd - dw / self.blend * self.offset


def run_one(t_kill: float, away: float, mode: str, tail: float = 10.0, window: float = 4.0) -> dict:
    """One walk with the controller lost at ``t_kill`` for ``away`` sim s; ``tail`` s after its return."""
    from cpg_walker.experiments.walk_runs import _controller
    from cpg_walker.paths import ros_parameters
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController
    from cpg_walker.walker.gait_source import FeedbackGaitSource
    from cpg_walker.walker.loop import run_replay

    hold_after = float(ros_parameters("sim.yaml", "sim")["servo_hold_after"])
    resume_blend = float(ros_parameters("pid.yaml", "pid")["resume_blend"])
    source = FeedbackGaitSource(_controller(), FeedbackController(FeedbackConfig.load()))
    sim = Hoap2Sim()
    sim.reset()
    loss = ControllerLoss(sim, source, t_kill, away, mode, hold_after, resume_blend)
    end = t_kill + away + tail
    r = run_replay(sim, loss, PidLaw.from_config(), end)
    out = {"t_kill": t_kill, "mode": mode, "fell": bool(r.fell),
           "fall_time_s": None if r.fall_time_s is None else round(float(r.fall_time_s), 2)}
    if not r.fell:
        t, xy = np.asarray(r.t), np.asarray(r.base_xy)
        k = t >= end - window
        out["speed_mps"] = round(float(np.linalg.norm(xy[k][-1] - xy[k][0]) / (t[k][-1] - t[k][0])), 4)
    return out


def run_phases(away: float = 3.0, kill_times=KILL_TIMES, modes=MODES, say=print) -> dict:
    """Every mode at every kill time; a summary per mode (falls of n, median final speed)."""
    runs = []
    for mode in modes:
        for k, t_kill in enumerate(kill_times):
            runs.append(run_one(t_kill, away, mode))
            say(f"[{mode} {k + 1}/{len(kill_times)}] {runs[-1]}")
    summary = {}
    for mode in modes:
        mine = [r for r in runs if r["mode"] == mode]
        speeds = [r["speed_mps"] for r in mine if "speed_mps" in r]
        summary[mode] = {"fell": sum(r["fell"] for r in mine), "of": len(mine),
                         "median_speed_mps": round(float(np.median(speeds)), 4) if speeds else None}
    return {"away_s": away, "kill_times_s": list(kill_times), "summary": summary, "runs": runs}
