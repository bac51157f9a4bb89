"""`cpg-walker replay`: the recorded gait on the simulated HOAP-2 in-process (walker/loop.py), rendered."""

from __future__ import annotations

from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.pid import PidLaw
from cpg_walker.walker.loop import control_period, recording_setup, run_replay, summarize


def replay_recording(
    out_dir: str,
    gait: str = "walk",
    data: str | None = None,
    duration: float | None = None,
    render: bool = True,
    progress_enabled: bool = True,
) -> dict:
    """Replay a packaged gait (or a CSV in the same layout) with the configured PID; continue with the
    recording's steady cycle past its end. Writes ``replay.json`` (+ ``filmstrip.png``, ``replay.gif``)."""
    import json
    from pathlib import Path

    from cpg_walker.progress import Progress
    from cpg_walker.robot.gait_data import GaitPlayback

    recording, duration, cycle = recording_setup(gait, data, duration)
    source = GaitPlayback(recording, cycle=cycle)
    sim = Hoap2Sim()
    pid = PidLaw.from_config()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    grabber = None
    if render:
        from cpg_walker.experiments.render import FrameGrabber

        grabber = FrameGrabber(sim.model, every_s=0.2, width=400, height=300)
    progress = Progress(duration, f"replay {recording.name}", enabled=progress_enabled)
    rate, delay = 1.0 / control_period(), control_period()  # run_replay's defaults, for the report
    result = run_replay(sim, source, pid, duration, rate_hz=rate, delay_s=delay, progress=progress,
                        on_log=grabber)
    progress.close()
    metrics = summarize(result, period_s=cycle.period)
    report = {
        **metrics,
        "gait": recording.name,
        "data": recording.source,
        "recording_s": recording.duration,
        "cycle": {"start_s": round(cycle.start, 3), "period_s": round(cycle.period, 3),
                  "seam_mismatch_rad": round(cycle.mismatch_rad, 6)},
        "touchdowns_s": {k: [round(x, 3) for x in v] for k, v in result.touchdowns.items()},
        "control": {"rate_hz": rate, "delay_s": delay, "timestep_s": sim.dt},
        "total_mass_kg": round(sim.total_mass, 4),
    }
    if grabber is not None:
        from cpg_walker.experiments.render import write_filmstrip, write_gif

        status = f"fell at {metrics['fall_time_s']} s" if metrics["fell"] else "no fall"
        title = (f"HOAP-2 replay of '{recording.name}': {metrics['distance_m']:.2f} m in "
                 f"{metrics['duration_s']:.1f} s, {status}")
        report["filmstrip"] = str(write_filmstrip(grabber.frames, grabber.times, out / "filmstrip.png",
                                                  title=title))
        report["gif"] = str(write_gif(grabber.frames, grabber.times, out / "replay.gif"))
        grabber.close()
    (out / "replay.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
