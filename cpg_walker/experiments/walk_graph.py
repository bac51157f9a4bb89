"""``cpg-walker walk``: the CPG walk through the ROS graph, three processes.

cpg_node streams the learned CPG as /joint_targets on every /clock tick (the recording's opening steps,
then the CPG), pid_node closes the loop over /joint_states -> /joint_torques, sim_node steps the HOAP-2
and records the run. Summarised by the graph replay's code (experiments/replay_graph.py), so walk.json
has replay.json's keys plus ``zeta``, ``alpha``, ``feedback``, ``real_time_factor`` and the CPG facts.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from cpg_walker.graph import Graph, param_arg

DEFAULT_CPG_FILE = "cpg_humanoid.yaml"


class WalkGraph(Graph):
    """The graph harness, also knowing cpg_node (graph.NODES lists the replay's nodes only)."""

    def command(self, node: str, params: dict) -> list[str]:
        if node != "cpg_node":
            return super().command(node, params)
        args = [sys.executable, "-m", "cpg_walker.nodes.cpg_node", "--ros-args"]
        for name, value in {"use_sim_time": self.use_sim_time, **params}.items():
            args += ["-p", param_arg(name.replace("__", "."), value)]
        return args


def check_modulation(zeta: float, alpha: float) -> None:
    """The cpg_node's ranges, checked before any process starts."""
    from cpg_walker.nodes.cpg_node import validate_modulation

    for name, value in (("zeta", zeta), ("alpha", alpha)):
        reason = validate_modulation(name, value)
        if reason:
            raise ValueError(reason)


def run_graph_walk(
    out_dir: str | Path,
    duration: float = 60.0,
    zeta: float = 1.0,
    alpha: float = 1.0,
    cpg_file: str = DEFAULT_CPG_FILE,
    pacing: str = "lockstep",
    control_period: float = 0.002,
    stop_on_fall: bool = True,
    timeout: float | None = None,
) -> dict:
    """Walk through sim_node + pid_node + cpg_node; write ``walk.json``; return its content."""
    from cpg_walker.cpg.humanoid import HumanoidCPG
    from cpg_walker.experiments.replay import summarize
    from cpg_walker.experiments.replay_graph import record_to_result
    from cpg_walker.nodes.sim_core import RunRecord
    from cpg_walker.paths import config_path
    from cpg_walker.robot.hoap2 import Hoap2Sim

    if pacing not in ("realtime", "fast", "lockstep"):
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"--duration must be a positive number of seconds, got {duration}")
    check_modulation(zeta, alpha)
    learn_now = not cpg_file
    ctrl = None
    if not learn_now:  # fail early, in this process, on a missing or corrupt file
        path = Path(cpg_file)
        if not path.is_file() and not path.is_absolute() and len(path.parts) == 1:
            path = config_path(cpg_file)
        ctrl = HumanoidCPG.load(path)
        cpg_file = str(path.resolve())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "graph_record.json"
    record_path.unlink(missing_ok=True)
    lockstep = pacing == "lockstep"
    started = time.monotonic()
    with WalkGraph(out / "graph_logs") as g:
        g.start("pid_node", lockstep=lockstep, wait_for_targets=True,
                startup_wait=600.0 if learn_now else 30.0)
        g.start("cpg_node", cpg_file=cpg_file, zeta=float(zeta), alpha=float(alpha))
        g.start("sim_node", pacing=pacing, control_period=float(control_period), duration=float(duration),
                stop_on_fall=stop_on_fall, record_path=str(record_path))
        limit = timeout if timeout is not None else 60.0 + duration * 5.0 + (600.0 if learn_now else 0.0)
        status = g.wait("sim_node", limit)
        cpu = {name: p.cpu_seconds() for name, p in g.procs.items() if name != "sim_node"}
        g.stop_all()
    wall = time.monotonic() - started
    if status != 0 or not record_path.exists():
        raise RuntimeError(f"sim_node exited with status {status}; logs in {out / 'graph_logs'}; tail:\n"
                           f"{(out / 'graph_logs' / 'sim_node.log').read_text()[-2000:]}")
    record = RunRecord.load(record_path)
    result = record_to_result(record)
    period = ctrl.period / abs(zeta) if ctrl is not None and zeta else None
    metrics = summarize(result, period_s=period)
    stats = record.stats
    cpu["sim_node"] = stats.get("cpu_s")
    sim = Hoap2Sim()
    report = {
        **metrics,
        "zeta": zeta, "alpha": alpha, "feedback": False,
        "real_time_factor": stats["real_time_factor"],
        "n_oscillators": int(ctrl.net.N) if ctrl is not None else None,
        "cpg_file": cpg_file or "learned at start-up",
        "touchdowns_s": {k: [round(x, 3) for x in v] for k, v in result.touchdowns.items()},
        "control": {"rate_hz": 1.0 / control_period, "delay_s": 0.0, "timestep_s": sim.dt,
                    "through": "ROS graph (sim_node, pid_node, cpg_node)"},
        "total_mass_kg": round(sim.total_mass, 4),
        "graph": {
            "pacing": pacing, "wall_s_total": round(wall, 2), "sim_wall_s": stats["wall_s"],
            "latency_state_to_torque": stats["latency"], "late_commands": stats["late_commands"],
            "resends": stats["resends"], "torque_age_s": stats["torque_age_s"],
            "cpu_s": {k: (None if v is None or v != v else round(v, 3)) for k, v in cpu.items()},
        },
    }
    (out / "walk.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
