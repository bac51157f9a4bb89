"""Benchmark section ``realtime``: does watching the real-time graph hurt it? (experiments/bench_sections.py)

The CPG walk (sim_node + pid_node + cpg_node, realtime pacing, each run in its own DDS domain) with
  * 0, 1 or 3 attached subscribers: 1 = ``cpg-walker topic echo /joint_states`` (500 Hz, YAML to a pipe);
    3 = that, ``cpg-walker topic echo /odom/ground_truth`` and an rclpy process subscribing to every
    topic of the graph (``python -m cpg_walker.experiments.bench_realtime subscribe-all``). They attach
    once cpg_node is ready, i.e. while the graph runs (their discovery burst included);
  * with and without a second CPU-bound process (a Python busy loop at normal priority).
Per scenario, from the nodes' exit stats (runtime: sim ``late_commands`` / ``latency``, cpg ``tick``):
cpg_node overruns (work per tick longer than the control period) and work per tick p50/p99/max,
pid_node stale-target events (its "targets stale" warnings), sim late torques (periods whose torque had
not arrived at the period's wall deadline), state->torque latency p50/p99 (inside the sim, one clock),
whether the robot fell, and each node's CPU per control period. ``per_period_cpu`` is the sim's and the
cpg node's per-period work measured in-process in CPU time (the machine may be shared: CPU time is what
the work costs, wall time what the scheduler gave it).
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from cpg_walker.experiments.bench_graph import check_graph_run, checked
from cpg_walker.nodes import interface as ifc

#: (name, attached subscribers, CPU-bound process) of the full run; ``--quick`` runs QUICK_SCENARIOS.
SCENARIOS = [("alone", 0, False), ("subscribers_1", 1, False), ("subscribers_3", 3, False),
             ("cpu_load", 0, True), ("subscribers_1_cpu_load", 1, True), ("subscribers_3_cpu_load", 3, True)]
QUICK_SCENARIOS = ("alone", "subscribers_3", "subscribers_3_cpu_load")
#: Wall s after cpg_node is ready before the subscribers attach (the walk is under way by then).
ATTACH_AFTER_S = 1.0
#: The scheduling parameters off (each control node): the "no OS help" comparison runs.
NO_OS_HELP = {"realtime_priority": 0, "nice": 0, "cpu_affinity": 0}


def _tools(n: int) -> list[list[str]]:
    py = sys.executable
    cmds = [[py, "-m", "cpg_walker.cli.main", "topic", "echo", ifc.JOINT_STATES],
            [py, "-m", "cpg_walker.cli.main", "topic", "echo", ifc.ODOM_GROUND_TRUTH],
            [py, "-m", "cpg_walker.experiments.bench_realtime", "subscribe-all"]]
    return cmds[:n]


def _wait_cpg_loaded(g, timeout: float) -> bool:
    """Wait until cpg_node has loaded its CPG (then it subscribes to /sim/servo_hold, its last topic) or
    has exited; whether it did."""
    from cpg_walker.graph.probe import Probe

    cpg, proc = ifc.NODE_NAMES[ifc.CPG_NODE], g.procs["cpg_node"]
    with Probe(g.domain_id, "bench_realtime_wait", parameter_services=False) as probe:
        return probe.spin_for(timeout, until=lambda: probe.subscribed(cpg, ifc.SIM_SERVO_HOLD)
                              or proc.popen.poll() is not None) and proc.popen.poll() is None


def _cpu_s(pid: int) -> float | None:
    import os

    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def scenario_run(subscribers: int, cpu_load: bool, duration: float, work: Path, tag: str,
                 os_help: bool = True) -> dict:
    """One realtime CPG walk of ``duration`` sim s with the given watchers; the figures of one run."""
    from cpg_walker.experiments.replay_graph import run_graph

    started: list[tuple[str, subprocess.Popen, Path]] = []

    def attach(g) -> list[subprocess.Popen]:
        procs = []
        if cpu_load:  # the load runs for the whole walk, start-up included
            p = subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True,
                                 stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)  # its KeyboardInterrupt at the stop
            started.append(("cpu_load", p, Path("/dev/null")))
            procs.append(p)
        if subscribers:
            _wait_cpg_loaded(g, 120.0)
            time.sleep(ATTACH_AFTER_S)
            for i, cmd in enumerate(_tools(subscribers)):
                out = g.log_dir / f"watcher_{i}.log"
                with open(out, "wb") as fh:
                    p = subprocess.Popen(cmd, env=g.env, stdout=fh if i == 2 else subprocess.DEVNULL,
                                         stderr=fh if i != 2 else subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, start_new_session=True)
                started.append((" ".join(cmd[2:]), p, out))
                procs.append(p)
        return procs

    params = None if os_help else {n: dict(NO_OS_HELP) for n in ("sim_node", "pid_node", "cpg_node")}
    t0 = time.monotonic()
    watcher_cpu: dict[str, float | None] = {}
    sampling = threading.Event()

    def sample() -> None:  # the watchers' CPU seconds, last seen before they are stopped
        while not sampling.wait(0.5):
            for name, p, _ in started:
                if p.poll() is None:
                    watcher_cpu[name] = _cpu_s(p.pid)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        run = run_graph(work, "cpg_node", duration=duration, pacing="realtime", stop_on_fall=False,
                        timeout=180 + 5 * duration, tag=tag, node_params=params, attach=attach)
    finally:
        sampling.set()
        sampler.join()
    rec, s = run.record, run.record.stats
    cpg = run.stats.get("cpg_node", {})
    pid = run.stats.get("pid_node", {})
    periods = max(1, int(s["periods"]))
    tick = cpg.get("tick", {})
    received = {}
    for name, _, out in started:
        if name.endswith("subscribe-all") and out.exists():
            m = re.findall(r"received (\{.*\})", out.read_text(errors="replace"))
            received = json.loads(m[-1]) if m else {}
    sched = {n: _scheduling_line(run.logs[n]) for n in ("sim_node", "pid_node", "cpg_node")}
    distance = round(float(rec.base_xy[-1][0] - rec.base_xy[0][0]), 3) if rec.base_xy else None
    return {
        **check_graph_run({"fell": bool(rec.fell), "distance_m": distance},
                          {"pid_node": pid, "cpg_node": cpg}, rec.fall_time_s, walking=True),
        "fell": bool(rec.fell), "fall_time_s": rec.fall_time_s, "distance_m": distance,
        "sim_s": s["sim_s"], "real_time_factor": s["real_time_factor"],
        "cpg_overruns": cpg.get("overruns"),
        "cpg_work_ms": {k: tick.get("work_ms", {}).get(k) for k in ("p50", "p99", "max")},
        "pid_stale_events": run.logs["pid_node"].count("targets stale ("),
        "sim_late_torques": s["late_commands"],
        "latency_ms": {"p50": s["latency"].get("p50_ms"), "p99": s["latency"].get("p99_ms"),
                       "max": s["latency"].get("max_ms")},
        "cpu_us_per_period": {
            "sim_node": round(s["cpu_s"] / periods * 1e6, 1),
            "pid_node": _per_message_us(pid), "cpg_node": _per_message_us(cpg)},
        "gc": {"sim_node": s.get("gc"), "pid_node": pid.get("gc"), "cpg_node": cpg.get("gc")},
        "watchers_cpu_s": watcher_cpu, "subscribe_all_received": received,
        "scheduling": sched, "wall_s": round(time.monotonic() - t0, 1),
    }


def _per_message_us(stats: dict) -> float | None:
    if not stats.get("messages"):
        return None
    return round(stats["active_cpu_s"] / stats["messages"] * 1e6, 1)


def _scheduling_line(log: str) -> str | None:
    m = re.findall(r"scheduling: (.*)", log)
    return m[-1].strip() if m else None


def summarize_runs(all_runs: list[dict]) -> dict:
    """Over a scenario's runs: how many, how many valid (bench_validity: no fall, controller ticks, moved)
    and why the others are not, falls; over the valid runs only: counts summed, latency/work percentiles
    as the worst run's (None without a valid run)."""
    runs = [r for r in all_runs if r["valid"]]

    def worst(path: tuple[str, str]):
        vals = [r[path[0]][path[1]] for r in runs if r[path[0]].get(path[1]) is not None]
        return max(vals) if vals else None

    def total(key: str):
        vals = [r[key] for r in runs if r[key] is not None]
        return sum(vals) if vals else None

    return {
        "runs": len(all_runs), "valid_runs": len(runs),
        "invalid_reasons": [r["invalid_reason"] for r in all_runs if not r["valid"]],
        "falls": sum(r["fell"] for r in all_runs),
        "sim_s_total": round(sum(r["sim_s"] for r in runs), 3),
        "cpg_overruns": total("cpg_overruns"), "pid_stale_events": total("pid_stale_events"),
        "sim_late_torques": total("sim_late_torques"),
        "latency_p50_ms_worst": worst(("latency_ms", "p50")),
        "latency_p99_ms_worst": worst(("latency_ms", "p99")),
        "cpg_work_p99_ms_worst": worst(("cpg_work_ms", "p99")),
        "cpg_work_max_ms_worst": worst(("cpg_work_ms", "max")),
    }


def per_period_cpu(n: int = 500) -> dict:
    """CPU microseconds (best of 5 batches of ``n``) of the sim's state publishing (publish_state: all
    topics, odometry and diagnostics at their cadence) and of its parts, of one physics period, and of the
    cpg node's work for one new target (CPGGaitSource.targets + serialization), on a standing robot
    (8 sole contacts) in this process."""
    import os

    import rclpy

    from cpg_walker.graph.processes import random_domain_id
    from cpg_walker.nodes.params import params_file
    from cpg_walker.nodes.sim_node import SimNode
    from cpg_walker.robot.contact import sole_wrenches

    def cpu(fn, reps: int = n) -> float:
        best = float("inf")
        for _ in range(5):
            t = time.process_time()
            for _ in range(reps):
                fn()
            best = min(best, (time.process_time() - t) / reps)
        return round(best * 1e6, 1)

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rclpy.init(domain_id=random_domain_id(), signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        node = SimNode(cli_args=["--ros-args", "--params-file", str(params_file("sim"))])
        sim = node.sim
        for _ in range(50):
            sim.step(node.tau, node.steps_per_period)

        def publish() -> None:
            node.publish_state(node.k * node.period_ns)
            node.k += 1

        imu = sim.imu()
        out = {
            "sim_contacts": int(sim.data.ncon),
            "sim_publish_state_us": cpu(publish),
            "sim_sole_wrenches_us": cpu(lambda: sole_wrenches(sim)),
            "sim_joint_states_us": cpu(lambda: node.pub_js.publish(node.b_js.fill(
                0, sim.data.qpos[sim._qadr], sim.data.qvel[sim._dadr], sim.data.actuator_force[sim._act]))),
            "sim_imu_us": cpu(lambda: node.pub_imu.publish(
                node.b_imu.fill(0, imu.gyro, imu.accel, imu.quat))),
            "sim_physics_period_us": cpu(lambda: sim.step(node.tau, node.steps_per_period), max(50, n // 5)),
        }
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
    out["cpg_target_us"] = _cpg_target_cpu(cpu)
    return out


def _cpg_target_cpu(cpu) -> float:
    from cpg_walker.nodes.messages import JointStateBuilder
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import load_controller

    ctrl, _, _ = load_controller("cpg_humanoid.yaml", None)
    src = CPGGaitSource(ctrl)
    b = JointStateBuilder(src.names, fields=("position", "velocity"))
    t = [src.handover + src.blend + 0.1]

    def tick() -> None:
        q, qd = src.targets(t[0])
        b.fill(0, position=q, velocity=qd)
        t[0] += src.h

    tick()
    return cpu(tick)


def run(quick: bool = False) -> dict:
    duration = 10.0 if quick else 30.0
    repeats = 1  # full: one 30 s run per scenario (two made the benchmark run ~10 min longer)
    names = QUICK_SCENARIOS if quick else tuple(n for n, _, _ in SCENARIOS)
    work = Path(tempfile.mkdtemp(prefix="bench_realtime_"))
    result: dict = {
        "setup": {"pacing": "realtime", "sim_s_per_run": duration, "runs_per_scenario": repeats,
                  "walk": "cpg_node (CPG takes over at 6.6 s)", "attach_after_cpg_ready_s": ATTACH_AFTER_S,
                  "scenarios": {n: {"subscribers": k, "cpu_load": c} for n, k, c in SCENARIOS if n in names}},
        "per_period_cpu": checked(per_period_cpu(200 if quick else 500)),
    }
    for name, subs, load in SCENARIOS:
        if name not in names:
            continue
        runs = [scenario_run(subs, load, duration, work, f"{name}_{i}") for i in range(repeats)]
        result[name] = {"summary": summarize_runs(runs), "runs": runs}
    result["table"] = {name: result[name]["summary"] for name in names}
    return result


def subscribe_all(settle: float = 3.0) -> int:
    """Subscribe to every topic of the graph (the environment's domain) with a QoS matching its publishers,
    count the messages, print ``received {json}`` on SIGINT/SIGTERM. Topics appearing later are added."""
    from cpg_walker.graph import ros2cli as rt

    counts: dict[str, int] = {}
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    with rt.Session("bench_subscribe_all") as s:
        next_scan = 0.0
        while not stop:
            now = time.monotonic()
            if now >= next_scan:
                for topic, types in s.node.get_topic_names_and_types():
                    if topic in counts or not s.node.count_publishers(topic):
                        continue
                    try:
                        cls = rt.message_class(types[0])
                    except rt.ToolError:
                        continue
                    counts[topic] = 0

                    def cb(_msg, topic=topic) -> None:
                        counts[topic] += 1
                    s.node.create_subscription(cls, topic, cb, rt.matching_qos(s, topic))
                next_scan = now + settle
            s.executor.spin_once(timeout_sec=0.1)
    print("received " + json.dumps(counts), flush=True)
    return 0


if __name__ == "__main__":
    if sys.argv[1:] == ["subscribe-all"]:
        raise SystemExit(subscribe_all())
    print(json.dumps(run(quick="--quick" in sys.argv), indent=2))
