"""The controller lost and back, in-process, at phases over a whole stride (``cpg-walker faults
--in-process``): what the graph's pid_node fault does, without DDS or wall-clock noise.

The walking robot (the learned CPG with feedback and the governor, as cpg_node, zeta 1, the in-process
loop of walker/loop.py) loses its PID at ``t_kill``: after ``hold_after`` s the servos hold the posture
measured then (sim_node's ``ServoHold``: the PID law towards that posture, velocity 0) while the CPG goes
on stepping; ``away`` s later a new PID takes over and blends from the measured posture to the gait's
targets over ``resume_blend`` (pid_node's join blend). Two ways back are compared:

* ``live``: track the gait where the CPG has got to (what pid_node alone does);
* ``reenter``: the gait re-enters from the standing crouch at that moment (``CPGGaitSource.reenter``:
  CPG from phase 0, alpha ramping up), what cpg_node does on the release of /sim/servo_hold.

Per kill time: fell or not (and when), and the speed over the last ``window`` s.
"""

from __future__ import annotations

import numpy as np

from cpg_walker.robot.joints import JOINT_NAMES

#: Kill times: 52, every 0.05 s over two strides (1.26 s at zeta 1) once the CPG walks alone (from 6.6 s);
#: the falls of a re-entry are scattered over phases 0.05 s apart (the 11 of a 0.25 s grid missed them).
KILL_TIMES = tuple(round(8.0 + 0.05 * k, 2) for k in range(52))
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
    from cpg_walker.walker.governor import GovernorConfig
    from cpg_walker.walker.loop import run_replay

    hold_after = float(ros_parameters("sim.yaml", "sim")["servo_hold_after"])
    resume_blend = float(ros_parameters("pid.yaml", "pid")["resume_blend"])
    source = FeedbackGaitSource(_controller(), FeedbackController(FeedbackConfig.load()),
                                governor=GovernorConfig.load())  # as cpg_node
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


#: cpg_node-loss times (``run_cpg_loss``): every 0.1 s over 6.4 strides once the CPG walks alone.
CPG_LOSS_TIMES = tuple(round(7.05 + 0.1 * k, 2) for k in range(80))


class CpgLoss:
    """A target source as pid_node sees cpg_node's death at ``t_kill``: the gait and its /joint_trajectory
    horizon (every horizon_step, with ``horizon_stop`` s of foreseen stop) until then, afterwards only the
    last horizon and, past its end, the standing crouch (robot/trajectory.py's GapBridge, pid_node's)."""

    def __init__(self, source, t_kill: float, bridge, horizon: float, horizon_stop: float,
                 step: float) -> None:
        from cpg_walker.walker.gait_source import stop_fade

        self.source, self.t_kill, self.bridge, self.step = source, t_kill, bridge, step
        self.names = source.names
        self.offsets = np.round(np.arange(0.0, horizon + horizon_stop + 1e-9, step), 9)
        self.fade = stop_fade(self.offsets, horizon, horizon_stop) if horizon_stop > 0 else None
        self.next_horizon = 0.0
        self.live: tuple | None = None

    def observe(self, *sample) -> None:
        if sample[0] < self.t_kill:  # the node's feedback dies with it
            self.source.observe(*sample)

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        from cpg_walker.nodes.validation import validate_joint_trajectory

        t_ns = round(t * 1e9)
        if t < self.t_kill:
            q, v = self.source.targets(t)
            self.live = (q, v, t_ns)
            if t >= self.next_horizon - 1e-9:
                qh, vh = self.source.forecast(t + self.offsets, self.fade)
                offs = np.round(self.offsets * 1e9).astype(np.int64)
                self.bridge.offer(validate_joint_trajectory(JOINT_NAMES, t_ns, offs, qh, vh))
                self.next_horizon = t + self.step
        q, v, live_ns = self.live
        return self.bridge.reference(t_ns, q, v, live_ns)


def run_cpg_loss_one(t_kill: float, horizon_stop: float | None = None, tail: float = 5.0) -> dict:
    """One walk (the CPG with feedback, zeta 1, cpg_node's horizon settings) whose cpg_node dies at
    ``t_kill``; ``tail`` s past the crouch blend's end. ``horizon_stop``: None = config/cpg.yaml's."""
    from cpg_walker.experiments.walk_runs import _controller
    from cpg_walker.paths import ros_parameters
    from cpg_walker.robot.hoap2 import Hoap2Sim, default_standing_posture
    from cpg_walker.robot.pid import PidLaw, load_pid_config
    from cpg_walker.robot.trajectory import GapBridge
    from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController
    from cpg_walker.walker.gait_source import FeedbackGaitSource
    from cpg_walker.walker.loop import run_replay

    cpg, cfg = ros_parameters("cpg.yaml", "cpg"), load_pid_config()
    stop = float(cpg["horizon_stop"] if horizon_stop is None else horizon_stop)
    bridge = GapBridge(default_standing_posture(), cfg["safe_blend"], cfg["resume_blend"])
    source = FeedbackGaitSource(_controller(), FeedbackController(FeedbackConfig.load()))
    loss = CpgLoss(source, t_kill, bridge, float(cpg["horizon"]), stop, float(cpg["horizon_step"]))
    sim = Hoap2Sim()
    sim.reset()
    end = t_kill + float(cpg["horizon"]) + stop + float(cfg["safe_blend"]) + tail
    r = run_replay(sim, loss, PidLaw.from_config(config=cfg), end)
    return {"t_kill": t_kill, "horizon_stop_s": stop, "fell": bool(r.fell),
            "fall_time_s": None if r.fall_time_s is None else round(float(r.fall_time_s), 2)}


def run_cpg_loss(kill_times=CPG_LOSS_TIMES, stops: tuple[float | None, ...] = (0.0, None), say=print) -> dict:
    """cpg_node lost at each kill time, with the horizon's foreseen stop (config/cpg.yaml's) and without
    it (0: the crouch straight from the horizon's mid-stride end); falls per setting."""
    runs = []
    for stop in stops:
        for k, t_kill in enumerate(kill_times):
            runs.append(run_cpg_loss_one(t_kill, stop))
            say(f"[stop {runs[-1]['horizon_stop_s']:g} s {k + 1}/{len(kill_times)}] {runs[-1]}")
    summary = {}
    for stop in sorted({r["horizon_stop_s"] for r in runs}):
        mine = [r for r in runs if r["horizon_stop_s"] == stop]
        summary[f"horizon_stop_{stop:g}s"] = {"fell": sum(r["fell"] for r in mine), "of": len(mine),
                                              "fell_at_kill_s": [r["t_kill"] for r in mine if r["fell"]]}
    return {"kill_times_s": list(kill_times), "summary": summary, "runs": runs}
