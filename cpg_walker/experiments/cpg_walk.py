"""In-process CPG walk (no ROS): the learned humanoid CPG drives the PID servos of the simulated HOAP-2.

Same loop as the recorded replay (experiments/replay.py: PID torque law at 500 Hz on 2 ms old state);
the target source is `walker.gait_source.CPGGaitSource` (start-up transition, then the frozen CPG, optional
ζ/α schedule). `cpg-walker cpg-walk` writes DIR/walk.json (replay.json's keys + zeta, alpha, feedback,
n_oscillators, transition, the CPG file) and a side-camera filmstrip.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.walker.controller import HumanoidCPG
from cpg_walker.walker.feedback import FeedbackController
from cpg_walker.walker.gait_source import CPGGaitSource, FeedbackGaitSource
from cpg_walker.walker.governor import GovernorConfig, command_error
from cpg_walker.walker.learning import cpg_defaults, load_controller
from cpg_walker.walker.loop import run_replay, summarize


def walk(ctrl: HumanoidCPG, duration: float, zeta: float | None = None, alpha: float | None = None,
         transition: str = "recording", blend_s: float = 1.0, handover_s: float | None = None,
         schedule: list[tuple[float, float, float]] | None = None, on_log=None, progress=None,
         feedback: FeedbackController | None = None, governed: bool = True) -> dict:
    """One walk from standing; returns the replay metrics plus the run's settings. With `feedback`
    (cpg/feedback.py) the source observes the IMU tilt and sole loads and closes the chosen pathways
    after the hand-over cross-fade (an empty pathway tuple only observes: calibration). ``zeta``/``alpha``
    None: cpg_node's (config/cpg.yaml, ``cpg_defaults``). ``governed``: the governor (walker/governor.py)
    between the commands and the CPG, as in cpg_node. A scheduled value outside the ranges is refused
    (``refused``: time, values, reason), as cpg_node refuses it, and the walk goes on."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw

    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"--duration must be a positive number of seconds, got {duration}")
    defaults = cpg_defaults()
    zeta = float(defaults["zeta"]) if zeta is None else zeta
    alpha = float(defaults["alpha"]) if alpha is None else alpha
    gcfg = GovernorConfig.load() if governed else None
    for name, value in (("zeta", zeta), ("alpha", alpha)):
        if reason := command_error(name, value, gcfg):  # as cpg_node refuses to start
            raise InputError(f"--{name}: {reason}")
    refused, kept = [], []
    for t, z, a in schedule or []:
        reason = command_error("zeta", z, gcfg) or command_error("alpha", a, gcfg)
        if reason:
            refused.append({"t_s": t, "zeta": z, "alpha": a, "reason": reason})
        else:
            kept.append((t, z, a))
    schedule = kept
    kw = dict(transition=transition, handover_s=handover_s, blend_s=blend_s, schedule=schedule, zeta=zeta,
              alpha=alpha, governor=gcfg)
    source = CPGGaitSource(ctrl, **kw) if feedback is None else FeedbackGaitSource(ctrl, feedback, **kw)
    sim = Hoap2Sim()
    sim.reset()
    pid = PidLaw.from_config()
    result = run_replay(sim, source, pid, duration, progress=progress, on_log=on_log)
    z_end = sorted(schedule)[-1][1] if schedule else zeta  # the stride at the end of the walk
    m = summarize(result, period_s=ctrl.period / abs(z_end) if z_end else None)
    m.update({
        "zeta": zeta, "alpha": alpha, "feedback": bool(feedback is not None and feedback.pathways),
        "n_oscillators": int(ctrl.net.N),
        "transition": transition, "handover_s": round(source.handover, 3), "blend_s": blend_s,
        "schedule": [list(s) for s in (schedule or [])],
        "touchdowns_s": {k: [round(x, 3) for x in v] for k, v in result.touchdowns.items()},
    })
    gov = getattr(source, "governor", None)
    m["applied_at_end"] = {"zeta": round(float(source.ctrl.zeta), 4),
                           "alpha": round(float(source.ctrl.alpha), 4),
                           "governor": gov.state if gov is not None else "off",
                           "reason": gov.reason if gov is not None else ""}
    if refused:  # the scheduled values refused (walk.json's keys are otherwise those of before the governor)
        m["refused"] = refused
    if not governed:
        m["governed"] = False  # the raw controller (--governor off)
    if isinstance(source, FeedbackGaitSource):
        m["feedback_pathways"] = list(feedback.pathways)
        m["feedback_config"] = asdict(feedback.cfg)
        m["phase_resets"] = len(feedback.resets)
        if feedback.resets:
            m["phase_reset_abs_mean_rad"] = round(float(np.mean([abs(d) for _, d in feedback.resets])), 4)
        if source.g_trace:
            tr = np.array(source.g_trace)
            m["tilt_after_handover"] = {
                "roll_rms_rad": round(float(np.sqrt(np.mean(tr[:, 1] ** 2))), 4),
                "roll_abs_mean_rad": round(float(np.mean(np.abs(tr[:, 1]))), 4),
                "pitch_mean_rad": round(float(np.mean(tr[:, 2] + feedback.cfg.pitch_reference_rad)), 4),
                "pitch_rms_about_ref_rad": round(float(np.sqrt(np.mean(tr[:, 2] ** 2))), 4),
                "g_ankle2_max": round(float(np.max(np.abs(tr[:, 3]))), 3),
                "g_knee_max": round(float(np.max(np.abs(tr[:, 4]))), 3)}
        if source.touchdown_phases:
            ph = np.array(source.touchdown_phases)
            m["right_touchdown_phase_rad"] = {
                "circular_mean": round(float(np.angle(np.mean(np.exp(1j * ph)))), 4),
                "resultant_length": round(float(np.abs(np.mean(np.exp(1j * ph)))), 4), "n": len(ph)}
    if isinstance(source, FeedbackGaitSource) and source.touchdown_log:
        z_end = source.ctrl.zeta  # phases at the final applied ζ (a calibration of the touchdown phase)
        ph = np.array([p for _, z, p in source.touchdown_log if abs(z - z_end) < 1e-3])
        if ph.size:
            m["right_touchdown_phase_final_zeta_rad"] = {
                "zeta": round(z_end, 4), "circular_mean": round(float(np.angle(np.mean(np.exp(1j * ph)))), 4),
                "resultant_length": round(float(np.abs(np.mean(np.exp(1j * ph)))), 4), "n": int(ph.size)}
    after = [x for x in result.touchdowns["right"] if x > source.handover + blend_s]
    if len(after) > 2:
        m["right_touchdown_interval_after_handover_s"] = round(float(np.median(np.diff(after))), 3)
    # step length: forward distance per step, over the CPG-driven part only
    i0 = int(np.searchsorted(result.t, source.handover + blend_s))
    if i0 < len(result.t) - 1:
        h0 = float(result.heading[0])
        fwd = np.array([math.cos(h0), math.sin(h0)])
        d = float((result.base_xy[-1] - result.base_xy[i0]) @ fwd)
        n_steps = sum(1 for side in ("left", "right") for x in result.touchdowns[side]
                      if x > result.t[i0])
        span = float(result.t[-1] - result.t[i0])
        m["cpg_part"] = {"from_s": round(float(result.t[i0]), 3), "distance_m": round(d, 4),
                         "speed_mps": round(d / span, 4) if span > 0 else 0.0, "steps": n_steps,
                         "step_length_m": round(d / n_steps, 4) if n_steps else None}
    return m


def run_cpg_walk(out_dir: str, duration: float = 60.0, zeta: float | None = None, alpha: float | None = None,
                 n_oscillators: int | None = None, cpg_file: str | None = None, transition: str = "recording",
                 blend_s: float = 1.0, schedule: list[tuple[float, float, float]] | None = None,
                 render: bool = True, progress_enabled: bool = True,
                 pathways: tuple[str, ...] | None = None, feedback_overrides: dict | None = None,
                 governed: bool = True) -> dict:
    """`cpg-walker cpg-walk`: walk, write DIR/walk.json and DIR/filmstrip.png. `pathways` (None = no
    feedback) closes those feedback pathways with config/feedback.yaml. ``zeta``/``alpha`` None: cpg_node's
    (config/cpg.yaml)."""
    from cpg_walker.progress import Progress

    defaults = cpg_defaults()
    zeta = float(defaults["zeta"]) if zeta is None else zeta
    alpha = float(defaults["alpha"]) if alpha is None else alpha
    load = load_controller(cpg_file, n_oscillators) if cpg_file else _default_controller(n_oscillators)
    ctrl, origin, _ = load
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    grabber = None
    if render:
        from cpg_walker.experiments.render import FrameGrabber
        from cpg_walker.robot.hoap2 import Hoap2Sim

        grabber = FrameGrabber(Hoap2Sim().model, every_s=max(0.2, duration / 40), width=400, height=300)
    progress = Progress(duration, f"cpg-walk N={ctrl.net.N}", enabled=progress_enabled)
    fb = None
    if pathways is not None:
        from cpg_walker.walker.feedback import FeedbackConfig

        fb = FeedbackController(FeedbackConfig.load(**(feedback_overrides or {})), pathways)
    m = walk(ctrl, duration, zeta, alpha, transition, blend_s, schedule=schedule, on_log=grabber,
             progress=progress, feedback=fb, governed=governed)
    progress.close()
    m["cpg_file"] = origin
    m["learned_gait_frequency_hz"] = ctrl.gait_frequency_hz()
    if grabber is not None:
        from cpg_walker.experiments.render import write_filmstrip

        status = f"fell at {m['fall_time_s']} s" if m["fell"] else "no fall"
        end = m["applied_at_end"]  # what the governor walked, when it differs from the command
        walked = (f" (walked at alpha {end['alpha']:.2g}: {end['reason']})"
                  if not schedule and abs(end["alpha"] - alpha) > 0.005 else "")
        title = (f"HOAP-2, CPG N={ctrl.net.N}, zeta={zeta}, alpha={alpha}{walked}: "
                 f"{m['distance_m']:.2f} m in {m['duration_s']:.1f} s, {status}")
        strip = write_filmstrip(grabber.frames, grabber.times, out / "filmstrip.png", title=title)
        m["filmstrip"] = str(strip)
        grabber.close()
    (out / "walk.json").write_text(json.dumps(m, indent=2) + "\n")
    return m


def _default_controller(n_oscillators: int | None) -> tuple[HumanoidCPG, str, bool]:
    """The default learned CPG (cpg_node's ``cpg_file``) if it has the requested N, else learn one with
    that N now."""
    ctrl, origin, converged = load_controller(cpg_defaults()["cpg_file"])
    if n_oscillators is None or ctrl.net.N == n_oscillators:
        return ctrl, origin, converged
    return load_controller(None, n_oscillators)
