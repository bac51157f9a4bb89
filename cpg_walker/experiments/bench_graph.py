"""Benchmark section ``graph``: the ROS graph's speed (registered in experiments/bench_sections.py).

Measures, each in its own isolated DDS domain with real node processes:
  * real-time factor of sim_node + pid_node (standing, config/sim.yaml's control period) in each pacing;
  * the walk through the three-process graph (with target_player_node) in lockstep and real time;
  * the CPG walk (with cpg_node) in real time and lockstep, and cpg_node's loop timing at its rate: wall
    period between consecutive /clock ticks, its jitter against the nominal control period (meaningful in
    real time), work per tick, overruns (from the node's stats at exit, timing.TickStats);
  * the stretch goal: lockstep at a 1 ms control period (1 kHz);
  * latency from publishing a /joint_states sample to the sim taking the torque that answers it (p50/p99,
    measured inside the sim process on one monotonic clock);
  * CPU per node over its active period (fraction of one core);
  * the real-time graph's topics as a third process receives them: messages per wall second and the share
    of states whose answering torque arrived too (the tests check rates in sim time only).
Baselines measured in the same run: the same sim + PID law in one process without ROS (real-time factor,
CPU per sim second), the round trip of a /joint_states-sized message to an echo process and back (the
latency's transport floor, `pingpong_latency`, with rclpy's executor and with the nodes' HotPath poll),
and the per-period costs inside the sim process (state publishing, physics step, an idle rclpy
executor ``spin_once`` versus the direct wait-set poll the nodes use).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.interface import PACINGS


def graph_run(pacing: str, duration: float, target: str | None = None, control_period: float | None = None,
              work: Path | None = None) -> dict:
    """One run of the graph (sim + PID, with ``target`` node if given); the sim exits after ``duration``
    sim seconds; ``control_period`` None: config/sim.yaml's. With cpg_node, ``cpg_tick`` is its loop
    timing (wall period between consecutive /clock ticks vs the nominal control period, work per tick,
    overruns) from its stats at exit."""
    from cpg_walker.experiments.replay_graph import run_graph

    work = Path(tempfile.mkdtemp(prefix="bench_graph_")) if work is None else work
    tag = f"{pacing}_{target or 'stand'}_{round(control_period * 1e6) if control_period else 'nominal'}"
    run = run_graph(work, target, duration=duration, pacing=pacing, control_period=control_period,
                    timeout=60 + 20 * duration, tag=tag)
    rec, s = run.record, run.record.stats
    cpu = {"sim_node": round(s["cpu_s"] / s["wall_s"], 3) if s["wall_s"] else None}
    node_stats = {name: stats for name, stats in run.stats.items() if name != "sim_node"}
    for name, stats in node_stats.items():
        cpu[name] = stats.get("cpu_fraction")
    out = {
        "real_time_factor": s["real_time_factor"], "sim_s": s["sim_s"], "wall_s": s["wall_s"],
        "control_hz": round(1.0 / run.control_period), "latency_ms": s["latency"],
        "late_commands": s["late_commands"], "torque_age_mean_ms": round(s["torque_age_s"]["mean"] * 1e3, 3),
        "cpu_core_fraction": cpu, "fell": rec.fell,
        "distance_m": round(float(rec.base_xy[-1][0] - rec.base_xy[0][0]), 4) if rec.base_xy else None,
    }
    if target == "cpg_node":
        out["cpg_tick"] = node_stats["cpg_node"].get("tick", {})
    out.update(check_graph_run(out, node_stats, rec.fall_time_s, walking=target is not None))
    return out


def controller_ticks(node_stats: dict) -> dict[str, int | None]:
    """The ticks each controller node handled, from its exit stats (None: it logged none): cpg_node's
    loop ticks (timing.TickStats), the other nodes' handled messages (timing.ActivityStats)."""
    ticks: dict[str, int | None] = {}
    for name, stats in node_stats.items():
        if name == "cpg_node":
            ticks[name] = stats.get("tick", {}).get("ticks") if stats else None
        else:
            ticks[name] = stats.get("messages") if stats else None
    return ticks


def check_graph_run(run: dict, node_stats: dict, fall_time_s: float | None, walking: bool) -> dict:
    """bench_validity.check_run of one graph run (``walking``: it has a target node, so it must move)."""
    from cpg_walker.experiments.bench_validity import check_run

    return check_run(fell=run["fell"], fall_time_s=fall_time_s, ticks=controller_ticks(node_stats),
                     distance_m=run["distance_m"], walking=walking)


def inprocess_baseline(duration: float) -> dict:
    """The same physics + PID law at the control period in one process, no ROS: the graph's ceiling."""
    from cpg_walker.robot.hoap2 import Hoap2Sim, default_standing_posture
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.loop import control_period

    sim, pid = Hoap2Sim(), PidLaw.from_config()
    target, zero = default_standing_posture(), np.zeros(25)
    period = control_period()
    steps = round(period / sim.dt)
    n = round(duration / period)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        tau = pid.step(target, zero, sim.joint_positions(), sim.joint_velocities(), period)
        sim.step(tau, steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"real_time_factor": round(duration / wall, 2), "per_period_us": round(wall / n * 1e6, 1),
            "cpu_s_per_sim_s": round(cpu / duration, 4)}


def per_period_costs(n: int = 1000) -> dict:
    """Median microseconds of the sim node's per-period work, in this process (isolated domain)."""
    import os

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from cpg_walker.graph.processes import random_domain_id
    from cpg_walker.nodes.params import params_file
    from cpg_walker.nodes.sim_node import SimNode

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rclpy.init(domain_id=random_domain_id(), signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = SimNode(cli_args=["--ros-args", "--params-file", str(params_file("sim"))])

    def timed(fn) -> float:
        samples = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            samples.append(time.perf_counter() - t)
        return round(float(np.median(samples)) * 1e6, 1)

    ex = SingleThreadedExecutor()
    other = rclpy.create_node("bench_idle")
    ex.add_node(other)
    def publish():  # advancing the period count, so odometry and diagnostics come at their cadence
        node.publish_state(node.k * node.period_ns)
        node.k += 1

    out = {
        "publish_state_us": timed(publish),
        "physics_period_us": timed(lambda: node.sim.step(node.tau, node.steps_per_period)),
        "executor_spin_once_idle_us": timed(lambda: ex.spin_once(timeout_sec=0.0)),
        "hotpath_poll_idle_us": timed(lambda: node.hot.poll(0.0)),
    }
    ex.shutdown()
    other.destroy_node()
    node.destroy_node()
    rclpy.try_shutdown()
    return out


#: How `pingpong_latency`'s two processes take messages: rclpy's executor, or nodes.runtime.HotPath (the
#: direct wait-set poll sim_node and pid_node use).
PING_MODES = ("executor", "hotpath")


def pingpong_latency(mode: str = "hotpath", n: int = 500, period: float = 0.002,
                     start_timeout: float = 60.0) -> dict:
    """Baseline of the state->torque latency: the round trip of a /joint_states-sized JointState (25
    joints) from this process to a minimal echo process (``python -m cpg_walker.experiments.bench_graph
    echo MODE``) and back, in its own domain, ``n`` samples one every ``period`` s: the transport alone
    (no physics, no PID), both sides taking messages the ``mode`` way (PING_MODES)."""
    import os
    import subprocess
    import sys

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import JointState

    from cpg_walker.experiments.replay_graph import stop_process
    from cpg_walker.graph.processes import isolated_env, quiet_domain_id
    from cpg_walker.nodes.messages import stamp, stamp_ns
    from cpg_walker.robot.joints import JOINT_NAMES

    domain = quiet_domain_id()
    from cpg_walker.nodes.runtime import HotPath

    if mode not in PING_MODES:
        raise ValueError(f"mode must be one of {PING_MODES}, got {mode!r}")
    echo = subprocess.Popen([sys.executable, "-m", "cpg_walker.experiments.bench_graph", "echo", mode],
                            env=isolated_env(domain), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("bench_ping", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    back: dict[int, int] = {}
    try:
        pub = node.create_publisher(JointState, "/ping", 10)
        def answered(m: JointState) -> None:
            back.setdefault(stamp_ns(m), time.monotonic_ns())

        sub = node.create_subscription(JointState, "/pong", answered, 10)
        hot = HotPath(node, [sub])

        def wait(timeout: float) -> None:
            if mode == "hotpath":
                hot.poll(timeout)
            else:
                ex.spin_once(timeout_sec=timeout)
        msg = JointState(name=list(JOINT_NAMES), position=[0.1] * 25, velocity=[0.2] * 25, effort=[0.3] * 25)
        end = time.monotonic() + start_timeout
        while not back:  # until the echo answers (discovery done both ways)
            if time.monotonic() > end or echo.poll() is not None:
                raise RuntimeError("the echo process did not answer")
            msg.header.stamp = stamp(time.monotonic_ns())
            pub.publish(msg)
            wait(0.05)
        rtt, lost = [], 0
        for _ in range(n):
            sent = time.monotonic_ns()
            msg.header.stamp = stamp(sent)
            pub.publish(msg)
            deadline = time.monotonic() + 0.1
            while sent not in back and time.monotonic() < deadline:
                wait(0.001)
            if sent in back:
                rtt.append((back[sent] - sent) * 1e-6)
            else:
                lost += 1
            time.sleep(max(0.0, period - (time.monotonic_ns() - sent) * 1e-9))
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        stop_process(echo)
    return {"samples": len(rtt), "lost": lost, "p50_ms": round(float(np.percentile(rtt, 50)), 3),
            "p99_ms": round(float(np.percentile(rtt, 99)), 3), "max_ms": round(float(np.max(rtt)), 3)}


def _echo(mode: str) -> int:
    """The echo process of `pingpong_latency`: /ping back out on /pong, taken the ``mode`` way."""
    import rclpy
    from sensor_msgs.msg import JointState

    from cpg_walker.nodes.runtime import HotPath, spin_hot

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pub = node.create_publisher(JointState, "/pong", 10)
    sub = node.create_subscription(JointState, "/ping", pub.publish, 10)
    try:
        if mode == "hotpath":
            spin_hot(node, HotPath(node, [sub]))
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    return 0


def third_process_rates(window: float = 2.0, start_timeout: float = 120.0) -> dict:
    """sim_node + pid_node standing in real time, received by a node in this process: messages per wall
    second of /joint_states, /joint_torques (500 Hz nominal) and /odom/ground_truth (100 Hz) over
    ``window`` wall s once every topic has arrived, and the share of the states received whose answer (a
    torque with the same stamp) was received too."""
    import os

    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState

    from cpg_walker.graph.probe import Probe
    from cpg_walker.graph.processes import Graph
    from cpg_walker.nodes.messages import stamp_ns

    topics = {ifc.JOINT_STATES: JointState, ifc.JOINT_TORQUES: JointState, ifc.ODOM_GROUND_TRUTH: Odometry}
    got: dict[str, list[int]] = {t: [] for t in topics}
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    with Graph(Path(tempfile.mkdtemp(prefix="bench_rates_"))) as g:
        probe = Probe(g.domain_id, "bench_rates")
        ex = probe.executor
        try:
            for topic, cls in topics.items():
                probe.subscribe(topic, cls, lambda m, t=topic: got[t].append(stamp_ns(m)), 2000)
            g.start("pid_node")
            g.start("sim_node", pacing="realtime")
            end = time.monotonic() + start_timeout
            while not all(got.values()):
                if time.monotonic() > end:
                    raise RuntimeError(f"the graph's topics did not all arrive within {start_timeout:g} s")
                ex.spin_once(timeout_sec=0.05)
            for stamps in got.values():
                stamps.clear()
            t0 = time.monotonic()
            while time.monotonic() - t0 < window:
                ex.spin_once(timeout_sec=0.01)
            wall = time.monotonic() - t0
        finally:
            probe.close()
    states, torques = set(got[ifc.JOINT_STATES]), set(got[ifc.JOINT_TORQUES])
    return {"window_wall_s": round(wall, 3),
            **{f"{t.strip('/').replace('/', '_')}_hz": round(len(v) / wall, 1) for t, v in got.items()},
            "states_answered_fraction": round(len(states & torques) / len(states), 4) if states else None}


def checked(entry: dict) -> dict:
    """A measurement entry with its validity (bench_validity: every figure present and finite)."""
    from cpg_walker.experiments.bench_validity import check_run, numbers

    return {**check_run(figures=numbers(entry)), **entry}


def run(quick: bool = False) -> dict:
    d = 3.0 if quick else 10.0
    d_cpg = 10.0 if quick else 20.0
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.walker.loop import control_period

    work = Path(tempfile.mkdtemp(prefix="bench_graph_"))
    result: dict = {
        "setup": {"physics_dt_s": Hoap2Sim().dt, "control_period_s": control_period(), "sim_s_per_run": d,
                  "sim_s_per_cpg_run": d_cpg,
                  "note": "sim_node + pid_node standing unless stated; each run in its own DDS domain"},
        "baseline_inprocess": checked(inprocess_baseline(d)),
        "per_period_costs": checked(per_period_costs(300 if quick else 1000)),
        "pingpong_baseline": {mode: checked(pingpong_latency(mode, 300 if quick else 1000))
                              for mode in PING_MODES},
    }
    for pacing in PACINGS:
        result[pacing] = graph_run(pacing, d, work=work)
    result["lockstep_walk_3_nodes"] = graph_run("lockstep", d, "target_player_node", work=work)
    result["realtime_walk_3_nodes"] = graph_run("realtime", d, "target_player_node", work=work)
    result["lockstep_1khz"] = graph_run("lockstep", d, control_period=0.001, work=work)
    # cpg_node's loop at its rate: the CPG takes over at 6.6 s (recorded opening steps before)
    result["realtime_cpg_walk"] = graph_run("realtime", d_cpg, "cpg_node", work=work)
    result["lockstep_cpg_walk"] = graph_run("lockstep", d_cpg, "cpg_node", work=work)
    result["realtime_rates_at_third_process"] = checked(third_process_rates())
    rates = result["realtime_rates_at_third_process"]

    def valid(key: str) -> dict:  # an invalid run gives no summary figure (None)
        return result[key] if result[key]["valid"] else {}

    lockstep_tick, realtime_tick = (valid(k).get("cpg_tick", {}) for k in ("lockstep_cpg_walk",
                                                                         "realtime_cpg_walk"))
    result["summary"] = {
        "real_time_factor": {k: valid(k).get("real_time_factor") for k in
                             ("realtime", "fast", "lockstep", "lockstep_walk_3_nodes", "lockstep_1khz")},
        "latency_p50_ms": valid("lockstep").get("latency_ms", {}).get("p50_ms"),
        "latency_p99_ms": valid("lockstep").get("latency_ms", {}).get("p99_ms"),
        "cpg_node_realtime_jitter_ms": realtime_tick.get("jitter_ms"),
        "cpg_node_realtime_work_ms": realtime_tick.get("work_ms"),
        # the longest tick (numba compiling at the CPG hand-over once took ~1 s; the node warms up now)
        "cpg_node_lockstep_work_ms_max": lockstep_tick.get("work_ms", {}).get("max"),
        "joint_states_hz_at_third_process": rates["joint_states_hz"],
        "states_answered_fraction": rates["states_answered_fraction"],
    }
    return result


if __name__ == "__main__":
    import sys

    if sys.argv[1:2] == ["echo"]:
        sys.exit(_echo(sys.argv[2]))
    print(json.dumps(run(quick="--quick" in sys.argv), indent=2))
