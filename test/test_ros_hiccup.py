"""The real-time graph keeps walking through a hiccup and with tools attached (issue "Watching must not
hurt"): sim_node (realtime pacing) + pid_node + cpg_node as processes. A node frozen for 0.2 s of wall
time (SIGSTOP/SIGCONT) mid-stride, first the cpg node (pid_node rides the gap on /joint_trajectory), then
the pid node (the sim waits for its torques rather than running open loop), then the sim (the others
wait on /clock); and a `cpg-walker topic echo /joint_states` plus a subscriber to every topic attached
while walking. The tests judge walking (the sim's record: no fall, and the stalls happened mid-stride),
never wall-clock speed: every wait is for a sim-time condition, with a generous deadline, so a busy
machine only makes them slower."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from cpg_walker.nodes import interface as ifc

pytestmark = [pytest.mark.ros, pytest.mark.slow]

HANDOVER_S = 6.616  # the CPG drives alone from here (cpg_node: recording's opening steps + 1 s cross-fade)
STALL_WALL_S = 0.2  # how long a node is frozen
AFTER_S = 6.0  # sim s the robot must walk on after a stall (more than two strides)


def _sim_time(probe) -> float:
    """The newest sim time seen: the stamps of /diagnostics (sim_node every 1 s, cpg_node every 0.1 s)."""
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in probe.received[ifc.DIAGNOSTICS]]
    return max(stamps, default=0.0)


def _wait_sim(probe, graph, t: float, timeout: float = 300.0) -> float:
    """Spin until the sim time reaches t (or the sim exits); the sim time then."""
    sim = graph.procs["sim_node"].popen
    probe.spin_for(timeout, until=lambda: _sim_time(probe) >= t or sim.poll() is not None)
    now = _sim_time(probe)
    tail = graph.procs["sim_node"].log()[-2000:]
    assert now >= t, f"sim time {now:.2f} s, waited for {t} s; sim log:\n{tail}"
    return now


def _stall(proc) -> None:
    """Freeze the node's process for STALL_WALL_S (every thread, DDS's too), then let it go on."""
    os.kill(proc.pid, signal.SIGSTOP)
    try:
        time.sleep(STALL_WALL_S)
    finally:
        os.kill(proc.pid, signal.SIGCONT)


def _start_walk(graph, probe, duration: float, record) -> None:
    """pid_node and cpg_node (their parameters files: realtime answering, the horizon on), then the sim in
    realtime pacing once cpg_node is up."""
    from diagnostic_msgs.msg import DiagnosticArray

    probe.listen(ifc.DIAGNOSTICS, DiagnosticArray, 200)
    graph.start("pid_node", wait_for_targets=True)
    cpg = graph.start("cpg_node")
    up = lambda: probe.node.count_publishers(ifc.JOINT_TRAJECTORY) > 0  # noqa: E731
    assert probe.spin_for(120.0, until=up), cpg.log()
    graph.start("sim_node", pacing="realtime", duration=duration, record_path=str(record))


def _finish(graph, record, duration: float):
    """Wait for the sim to end its run; stop the others; the run (ReplayResult) and the nodes' exit stats."""
    from cpg_walker.experiments.replay_graph import record_to_result
    from cpg_walker.robot.run_record import RunRecord

    assert graph.wait("sim_node", timeout=120.0 + 20.0 * duration) == 0, graph.procs["sim_node"].log()[-2000:]
    graph.stop_all()
    for proc in graph.procs.values():
        log = proc.log()
        assert "Traceback" not in log, log[-3000:]
    stats = {name: graph.stats(name) for name in graph.procs}  # each node's stats file
    rec = RunRecord.load(record)
    return record_to_result(rec), rec.stats, stats


def test_the_robot_walks_through_a_stall_of_each_node(graph, probe, tmp_path):
    """Mid-stride after the CPG hand-over: 0.2 s SIGSTOP of the cpg node at 9 s, of the pid node 4 s
    later, of the sim 4 s after that; no fall over the whole run, which goes on >= 8 s after each."""
    record = tmp_path / "record.json"
    t_cpg = 9.0
    duration = t_cpg + 2 * 4.0 + AFTER_S + 0.5
    _start_walk(graph, probe, duration, record)
    stalls = {}
    for name, at in (("cpg_node", t_cpg), ("pid_node", t_cpg + 4.0), ("sim_node", t_cpg + 8.0)):
        stalls[name] = _wait_sim(probe, graph, at)
        _stall(graph.procs[name])
    run, sim_stats, stats = _finish(graph, record, duration)
    assert not run.fell, (run.fall_time_s, stalls, sim_stats)
    assert stalls["cpg_node"] > HANDOVER_S  # the CPG was driving
    assert run.duration_s >= max(stalls.values()) + AFTER_S - 0.5, (run.duration_s, stalls)
    after = run.base_xy[run.t > stalls["cpg_node"]]
    assert np.linalg.norm(after[-1] - after[0]) > 0.5, after[[0, -1]]  # walking on (~0.075 m/s)
    gaps = stats["pid_node"]["gaps"]
    assert gaps["horizon_states"] > 0, gaps  # the cpg stall was ridden out on /joint_trajectory
    assert sim_stats["late_waited"] > 0, sim_stats  # the pid stall: the sim waited for its torques


def _echoed_stamps(path, tail: int | None = None) -> list[float]:
    """The header stamps (sim s) of the messages a `topic echo` has printed so far (in its last ``tail``
    bytes only, if given: cheap enough to poll)."""
    if not path.exists():
        return []
    with open(path, "rb") as fh:
        if tail is not None:
            fh.seek(max(0, path.stat().st_size - tail))
        text = fh.read().decode(errors="replace")
    return [int(sec) + int(ns) * 1e-9
            for sec, ns in re.findall(r"stamp:\n\s+sec: (\d+)\n\s+nanosec: (\d+)", text)]


def test_the_robot_walks_with_an_echo_and_a_subscriber_to_every_topic(graph, probe, tmp_path):
    """`cpg-walker topic echo /joint_states` (500 Hz, printed as YAML) and a subscriber to every topic
    of the graph, attached from 1 s of sim time on: no fall. The walk goes on (up to a cap) until the
    echo has printed states from well after the hand-over and the walk is AFTER_S past it: how soon the
    echo starts printing depends on the CPU the nodes leave it (they run first), so the run's end is a
    condition on what the watchers got, not a fixed length."""
    from cpg_walker.nodes.messages import message_class

    record = tmp_path / "record.json"
    cap = 120.0  # sim s: the sim ends by itself here if the condition never comes
    _start_walk(graph, probe, cap, record)
    _wait_sim(probe, graph, 1.0)
    echo_out = tmp_path / "echo.txt"
    with open(echo_out, "wb") as out:
        echo = subprocess.Popen(
            [sys.executable, "-m", "cpg_walker.cli.main", "topic", "echo", ifc.JOINT_STATES], env=graph.env,
            stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
    watched = (ifc.CLOCK, ifc.JOINT_STATES, ifc.JOINT_TARGETS, ifc.JOINT_TORQUES, ifc.JOINT_TRAJECTORY,
               ifc.IMU, ifc.ODOM_GROUND_TRUTH)
    try:
        counts: dict[str, int] = {}
        topics = {}
        for _ in range(20):  # every topic of the graph, as discovery reveals them
            probe.spin_for(0.25)
            for topic, types in probe.node.get_topic_names_and_types():
                if topic not in topics and topic != ifc.DIAGNOSTICS:
                    counts[topic] = 0
                    topics[topic] = probe.node.create_subscription(
                        message_class(types[0]), topic,
                        lambda _m, t=topic: counts.__setitem__(t, counts[t] + 1), 10)
        sim = graph.procs["sim_node"].popen

        def enough() -> bool:
            stamps = _echoed_stamps(echo_out, tail=8192)
            return (_sim_time(probe) >= HANDOVER_S + AFTER_S and bool(stamps)
                    and max(stamps) > HANDOVER_S + 0.5 * AFTER_S and all(counts.get(t, 0) for t in watched))

        probe.spin_for(120.0 + 20.0 * cap, until=lambda: enough() or sim.poll() is not None)
        if sim.poll() is None:
            graph.stop("sim_node", timeout=30.0)  # SIGINT: the sim ends its run and writes its record
        run, sim_stats, stats = _finish(graph, record, cap)
    finally:
        if echo.poll() is None:
            os.killpg(echo.pid, signal.SIGINT)
            try:
                echo.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(echo.pid, signal.SIGKILL)
                echo.wait()
    assert not run.fell, (run.fall_time_s, json.dumps(sim_stats), json.dumps(stats))
    assert run.duration_s >= HANDOVER_S + AFTER_S, run.duration_s
    # the echo printed the walk's states until well after the hand-over
    stamps = _echoed_stamps(echo_out)
    assert stamps and max(stamps) > HANDOVER_S + 0.5 * AFTER_S, (
        len(stamps), stamps[-1:], echo_out.read_text(errors="replace")[-2000:])
    for topic in watched:
        assert counts.get(topic, 0) > 0, counts
