"""``cpg-walker replay --graph``: the recorded walk through the ROS graph, three processes.

target_player_node streams the recording as /joint_targets on every /clock tick, pid_node closes the loop
over /joint_states -> /joint_torques, sim_node steps the HOAP-2 and records the run (base pose, heading,
sole loads every 10 ms of sim time). The record is summarised by the in-process replay's code
(walker/loop.py), so replay.json has the same keys, plus ``real_time_factor`` and a ``graph``
section (pacing, latency, CPU per node).

``run_graph`` / ``GraphRun.report`` are the shared part: start sim_node + pid_node + a target node with
its parameters, wait for the sim to finish, summarise its record. ``cpg-walker walk``
(experiments/walk_graph.py) and the benchmark use them too.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cpg_walker.graph.processes import Graph, Placement
from cpg_walker.nodes.interface import PACINGS, controllers_lockstep
from cpg_walker.nodes.recorder_node import NAME as RECORDER_NAME
from cpg_walker.nodes.relay_node import consumer_remaps


def record_to_result(record):
    """A sim_node RunRecord as the in-process ReplayResult (contact events from the logged loads)."""
    from cpg_walker.robot.contact import TouchdownDetector
    from cpg_walker.walker.loop import ReplayResult

    t = np.asarray(record.t)
    loads = np.asarray(record.loads)
    touch = TouchdownDetector()
    for ti, li in zip(t, loads, strict=True):
        touch.update(float(ti), (float(li[0]), float(li[1])))
    events = touch.events
    return ReplayResult(
        t=t, base_xy=np.asarray(record.base_xy), base_z=np.asarray(record.base_z),
        heading=np.unwrap(np.asarray(record.heading)), loads=loads, touchdowns=events,
        fell=bool(record.fell), fall_time_s=record.fall_time_s,
        duration_s=float(t[-1]) if len(t) else 0.0,
    )


@dataclass
class GraphRun:
    """One finished run of the graph: the sim's record, wall time, CPU seconds, the log and the run
    statistics (its stats file, graph/processes.py) of every node."""

    record: object  # robot.run_record.RunRecord
    target: str | None
    pacing: str
    control_period: float  # s, the sim's (from its record)
    wall_s: float
    cpu_s: dict[str, float | None]
    logs: dict[str, str]
    stats: dict[str, dict] = field(default_factory=dict)  # by node; {} for a node that wrote none

    def report(self, period_s: float | None) -> tuple[dict, object]:
        """replay.json's keys (``summarize`` of the record, stride ``period_s``), ``real_time_factor``,
        touchdowns, control, mass and the ``graph`` section; and the ReplayResult."""
        from cpg_walker.robot.hoap2 import Hoap2Sim
        from cpg_walker.walker.loop import summarize

        result = record_to_result(self.record)
        stats = self.record.stats
        sim = Hoap2Sim()
        cpu = {**self.cpu_s, "sim_node": stats.get("cpu_s")}
        report = {
            **summarize(result, period_s=period_s),
            "real_time_factor": stats["real_time_factor"],
            "touchdowns_s": {k: [round(x, 3) for x in v] for k, v in result.touchdowns.items()},
            "control": {"rate_hz": 1.0 / self.control_period, "delay_s": 0.0, "timestep_s": sim.dt,
                        "through": f"ROS graph (sim_node, pid_node, {self.target})"},
            "total_mass_kg": round(sim.total_mass, 4),
            "graph": {
                "pacing": self.pacing, "wall_s_total": round(self.wall_s, 2), "sim_wall_s": stats["wall_s"],
                "latency_state_to_torque": stats["latency"], "late_commands": stats["late_commands"],
                "resends": stats["resends"], "torque_age_s": stats["torque_age_s"],
                "cpu_s": {k: (None if v is None or v != v else round(v, 3)) for k, v in cpu.items()},
            },
        }
        return report, result


def run_graph(
    work_dir: str | Path,
    target: str | None,
    target_params: dict | None = None,
    *,
    duration: float,
    pacing: str = "lockstep",
    control_period: float | None = None,
    stop_on_fall: bool = True,
    timeout: float,
    pid_params: dict | None = None,
    tag: str = "graph",
    node_params: dict[str, dict] | None = None,
    attach: Callable[[Graph], list[subprocess.Popen]] | None = None,
    bag_dir: str | Path | None = None,
    domain_id: int | None = None,
    relay: dict | None = None,
    placement: dict[str, Placement] | None = None,
    odometry: bool = True,
) -> GraphRun:
    """Run sim_node + pid_node (+ ``target`` node with ``target_params``) for ``duration`` sim seconds.
    Each node gets its parameters file (config/<node>.yaml), then these arguments as overrides
    (``control_period`` None: the file's).

    The sim records the run to ``work_dir/<tag>_record.json``; node logs go to ``work_dir/<tag>_logs``.
    pid_node answers in lockstep when the sim does and waits for targets when there is a target node
    (``pid_params`` override). ``node_params``: more overrides by node executable (e.g. the scheduling
    parameters); ``attach(graph)``, called once the nodes are started, may start more processes on the
    graph's domain (subscribers, a CPU load) and returns them: they are stopped when the sim has finished.
    ``bag_dir``: record every topic to ``bag_dir/recording.mcap`` (recorder_node, started first and
    stopped last; the sim holds its first state until the recorder subscribes to it). ``domain_id``: the
    graph's DDS domain (None: a free one). ``relay``: start relay_node (these parameter overrides of
    config/relay.yaml) before the others and route the consumers of its topics through it (remaps:
    nodes/relay_node.py ``consumer_remaps``). ``placement``: where nodes run, by executable (Graph; e.g.
    in another network namespace). ``odometry``: odom_node too (the leg odometry on /odom; then it, not
    the sim, publishes odom -> base_link on /tf: sim_node's ``publish_tf`` false). Raises RuntimeError
    (with the sim's log tail) if the sim fails."""
    from cpg_walker.robot.run_record import RunRecord

    if pacing not in PACINGS:
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    record_path = work / f"{tag}_record.json"
    record_path.unlink(missing_ok=True)
    started = time.monotonic()
    more = node_params or {}
    with Graph(work / f"{tag}_logs", domain_id=domain_id, placement=placement) as g:
        if bag_dir is not None:
            start_recorder(g, bag_dir, timeout)
        remaps: dict[str, dict[str, str]] = {}
        if odometry:  # first: subscribed before the sim's first state (its odom origin: the start pose)
            g.start("odom_node", **more.get("odom_node", {}))
        if relay is not None:
            remaps = consumer_remaps(relay)
            g.start("relay_node", **relay, **more.get("relay_node", {}))
        g.start("pid_node", remaps=remaps.get("pid_node"),
                **{"lockstep": controllers_lockstep(pacing), "wait_for_targets": target is not None,
                   **(pid_params or {}), **more.get("pid_node", {})})
        if target is not None:
            g.start(target, remaps=remaps.get(target), **(target_params or {}), **more.get(target, {}))
        period = {} if control_period is None else {"control_period": float(control_period)}
        waits = {} if bag_dir is None else {"wait_for_subscriber": RECORDER_NAME}  # bag from t = 0
        tf = {"publish_tf": False} if odometry else {}  # REP-105: odom -> base_link from the estimator
        g.start("sim_node", pacing=pacing, duration=float(duration), stop_on_fall=stop_on_fall,
                record_path=str(record_path), **period, **waits, **tf, **more.get("sim_node", {}))
        extra = attach(g) if attach is not None else []
        try:
            status = g.wait("sim_node", timeout)
        finally:
            for proc in extra:
                stop_process(proc)
        cpu = {name: p.cpu_seconds() for name, p in g.procs.items() if name != "sim_node"}
        g.stop_all()
        logs = {name: p.log() for name, p in g.procs.items()}
        stats = {name: g.stats(name) for name in g.procs}
    wall = time.monotonic() - started
    if status != 0 or not record_path.exists():
        raise RuntimeError(f"sim_node exited with status {status}; logs in {work / f'{tag}_logs'}; tail:\n"
                           f"{logs['sim_node'][-2000:]}")
    record = RunRecord.load(record_path)
    return GraphRun(record=record, target=target, pacing=pacing,
                    control_period=float(record.stats["control_period_s"]), wall_s=wall, cpu_s=cpu, logs=logs,
                    stats=stats)


def start_recorder(g: Graph, bag_dir: str | Path, timeout: float) -> None:
    """recorder_node on the graph, writing to ``bag_dir``; returns once it is listening (its topic scans
    then catch each node's publishers as they appear)."""
    from cpg_walker.nodes.recorder_node import READY

    g.start("recorder_node", out_dir=str(Path(bag_dir).resolve()))
    g.wait_for_log("recorder_node", READY, timeout)


def stop_process(proc: subprocess.Popen, timeout: float = 5.0) -> None:
    """SIGINT a helper process started beside the graph (in its own session), then SIGKILL."""
    import os
    import signal

    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=timeout)
        except (ProcessLookupError, PermissionError):
            pass
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=timeout)


def run_graph_replay(
    out_dir: str | Path,
    gait: str = "walk",
    data: str | None = None,
    duration: float | None = None,
    pacing: str = "lockstep",
    control_period: float | None = None,
    stop_on_fall: bool = True,
    timeout: float | None = None,
) -> dict:
    """Replay a recording through sim_node + pid_node + target_player_node; write ``replay.json``."""
    from cpg_walker.walker.loop import recording_setup

    if pacing not in PACINGS:
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    recording, duration, cycle = recording_setup(gait, data, duration, need_cycle=False)
    out = Path(out_dir)
    run = run_graph(out, "target_player_node", {"data": str(data)} if data else {"gait": gait},
                    duration=duration, pacing=pacing, control_period=control_period,
                    stop_on_fall=stop_on_fall,
                    timeout=timeout if timeout is not None else 60.0 + duration * 5.0)
    metrics, _ = run.report(period_s=cycle.period)
    report = {
        **metrics,
        "gait": recording.name,
        "data": recording.source,
        "recording_s": recording.duration,
        "cycle": {"start_s": round(cycle.start, 3), "period_s": round(cycle.period, 3),
                  "seam_mismatch_rad": round(cycle.mismatch_rad, 6)},
    }
    (out / "replay.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
