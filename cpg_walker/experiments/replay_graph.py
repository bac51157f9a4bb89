"""``cpg-walker replay --graph``: the recorded walk through the ROS graph, three processes.

target_player_node streams the recording as /joint_targets on every /clock tick, pid_node closes the loop
over /joint_states -> /joint_torques, sim_node steps the HOAP-2 and records the run (base pose, heading,
sole loads every 10 ms of sim time). The record is summarised by the in-process replay's code
(experiments/replay.py), so replay.json has the same keys, plus ``real_time_factor`` and a ``graph``
section (pacing, latency, CPU per node).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np


def record_to_result(record, touchdown_from_loads: bool = True):
    """A sim_node RunRecord as the in-process ReplayResult (contact events from the logged loads)."""
    from cpg_walker.experiments.replay import CONTACT_ON_N, ReplayResult, _contact_events

    t = np.asarray(record.t)
    loads = np.asarray(record.loads)
    events: dict[str, list[float]] = {"left": [], "right": []}
    if len(t):
        contact = [(loads[0][0] > CONTACT_ON_N, None), (loads[0][1] > CONTACT_ON_N, None)]
        for ti, li in zip(t, loads, strict=True):
            _contact_events((float(li[0]), float(li[1])), contact, float(ti), events)
    return ReplayResult(
        t=t, base_xy=np.asarray(record.base_xy), base_z=np.asarray(record.base_z),
        heading=np.unwrap(np.asarray(record.heading)), loads=loads, touchdowns=events,
        fell=bool(record.fell), fall_time_s=record.fall_time_s,
        duration_s=float(t[-1]) if len(t) else 0.0,
    )


def run_graph_replay(
    out_dir: str | Path,
    gait: str = "walk",
    data: str | None = None,
    duration: float | None = None,
    pacing: str = "lockstep",
    control_period: float = 0.002,
    stop_on_fall: bool = True,
    timeout: float | None = None,
) -> dict:
    """Replay a recording through sim_node + pid_node + target_player_node; write ``replay.json``."""
    from cpg_walker.experiments.replay import summarize
    from cpg_walker.graph import Graph
    from cpg_walker.nodes.sim_core import RunRecord
    from cpg_walker.robot.gait_data import Cycle, find_steady_cycle, load_gait
    from cpg_walker.robot.hoap2 import Hoap2Sim

    if pacing not in ("realtime", "fast", "lockstep"):
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    recording = load_gait(data if data is not None else gait)
    if duration is None:
        duration = max(30.0, recording.duration)
    if not (duration > 0):
        raise ValueError(f"--duration must be positive, got {duration}")
    try:
        cycle = find_steady_cycle(recording)
    except ValueError:
        cycle = Cycle(start=0.0, period=recording.duration + 1.0, mismatch_rad=float("nan"))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "graph_record.json"
    record_path.unlink(missing_ok=True)
    lockstep = pacing == "lockstep"
    started = time.monotonic()
    with Graph(out / "graph_logs") as g:
        g.start("pid_node", lockstep=lockstep, wait_for_targets=True)
        g.start("target_player_node", **({"data": str(data)} if data else {"gait": gait}))
        g.start("sim_node", pacing=pacing, control_period=float(control_period), duration=float(duration),
                stop_on_fall=stop_on_fall, record_path=str(record_path))
        limit = timeout if timeout is not None else 60.0 + duration * 5.0
        status = g.wait("sim_node", limit)
        cpu = {name: p.cpu_seconds() for name, p in g.procs.items() if name != "sim_node"}
        g.stop_all()
    wall = time.monotonic() - started
    if status != 0 or not record_path.exists():
        raise RuntimeError(f"sim_node exited with status {status}; log:\n"
                           f"{(out / 'graph_logs' / 'sim_node.log').read_text()[-2000:]}")
    record = RunRecord.load(record_path)
    result = record_to_result(record)
    metrics = summarize(result, period_s=cycle.period)
    stats = record.stats
    cpu["sim_node"] = stats.get("cpu_s")
    sim = Hoap2Sim()
    report = {
        **metrics,
        "real_time_factor": stats["real_time_factor"],
        "gait": recording.name,
        "data": recording.source,
        "recording_s": recording.duration,
        "cycle": {"start_s": round(cycle.start, 3), "period_s": round(cycle.period, 3),
                  "seam_mismatch_rad": round(cycle.mismatch_rad, 6)},
        "touchdowns_s": {k: [round(x, 3) for x in v] for k, v in result.touchdowns.items()},
        "control": {"rate_hz": 1.0 / control_period, "delay_s": 0.0, "timestep_s": sim.dt,
                    "through": "ROS graph (sim_node, pid_node, target_player_node)"},
        "total_mass_kg": round(sim.total_mass, 4),
        "graph": {
            "pacing": pacing, "wall_s_total": round(wall, 2), "sim_wall_s": stats["wall_s"],
            "latency_state_to_torque": stats["latency"], "late_commands": stats["late_commands"],
            "resends": stats["resends"], "torque_age_s": stats["torque_age_s"],
            "cpu_s": {k: (None if v is None or v != v else round(v, 3)) for k, v in cpu.items()},
        },
    }
    (out / "replay.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
