"""`cpg-walker graph | param | topic`: the pip-only stand-ins for `ros2 launch/param/topic`, run as real
subprocesses against a real graph on the test's own DDS domain (the `ros_domain` and `graph` fixtures).
Each tool is run once the graph is up (waited for with a deadline), with discovery deadlines of its own."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest
from ros_helpers import ANSWER_S, START_S, node_pids, sim_deadline

from cpg_walker.nodes import interface as ifc

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DISCOVERY = ("--timeout", str(ANSWER_S))  # param/echo: wall s for the node or topic to be discovered


def cli(*args: str, timeout: float = START_S) -> subprocess.CompletedProcess:
    """The real `cpg-walker` in a subprocess, on the domain in ROS_DOMAIN_ID (set by the fixture);
    ``timeout``: a hang guard."""
    return subprocess.run([sys.executable, "-m", "cpg_walker.cli.main", *args], capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def test_param_and_topic_tools_against_a_running_graph(graph, probe):
    from rosgraph_msgs.msg import Clock

    graph.start("pid_node", lockstep=True, wait_for_targets=True)
    graph.start("cpg_node")
    probe.wait_endpoints(ifc.JOINT_TARGETS)  # cpg -> pid before the clock starts
    probe.wait_endpoints(ifc.CLOCK, 0, 1)
    # until stopped (no fall stop either): the tools must find the graph running however long they take
    graph.start("sim_node", pacing="lockstep", duration=0.0, stop_on_fall=False)
    probe.listen(ifc.CLOCK, Clock, 1)
    probe.wait(lambda: len(probe.received[ifc.CLOCK]) > 0, "/clock ticking", START_S)

    listed = cli("param", "list", "/cpg", *DISCOVERY)
    assert listed.returncode == 0, listed.stderr
    assert {"zeta", "alpha"} <= set(listed.stdout.split())

    ok = cli("param", "set", "/cpg", "zeta", "0.8", *DISCOVERY)
    assert ok.returncode == 0 and "Set parameter successful" in ok.stdout, ok.stderr
    got = cli("param", "get", "/cpg", "zeta", *DISCOVERY)
    assert got.returncode == 0 and got.stdout.strip() == "Double value is: 0.8", got
    one = cli("param", "set", "/cpg", "alpha", "1", *DISCOVERY)  # an integer for a double: sent as 1.0
    assert one.returncode == 0, one.stderr
    for bad, reason in (("nan", "zeta must be finite"), ("5", "zeta must be in [-2, 2], got 5.0"),
                        ("fast", "zeta must be a number (double), got str 'fast'")):  # the node's reasons
        r = cli("param", "set", "/cpg", "zeta", bad, *DISCOVERY)
        assert r.returncode == 1, (bad, r)
        assert r.stderr.startswith("Setting parameter failed: ") and reason in r.stderr, (bad, r.stderr)
    assert cli("param", "get", "/cpg", "zeta", *DISCOVERY).stdout.strip() == "Double value is: 0.8"

    missing = cli("param", "get", "/nonexistent", "x", "--timeout", "2")
    assert missing.returncode == 1
    assert f"node /nonexistent not found in domain {graph.domain_id}" in missing.stderr, missing.stderr

    # a new process discovers the graph's topics one endpoint at a time: list again until they are there
    wanted = {"/joint_targets [sensor_msgs/msg/JointState]", "/clock [rosgraph_msgs/msg/Clock]"}
    end = time.monotonic() + ANSWER_S
    while True:
        topics = cli("topic", "list")
        assert topics.returncode == 0, topics.stderr
        if wanted <= set(topics.stdout.splitlines()) or time.monotonic() > end:
            break
    assert wanted <= set(topics.stdout.splitlines()), topics.stdout

    echo = cli("topic", "echo", ifc.JOINT_TARGETS, "--once", *DISCOVERY)
    assert echo.returncode == 0, echo.stderr
    assert "- lleg_joint_3" in echo.stdout and "\nposition:\n- " in echo.stdout, echo.stdout[:500]
    assert echo.stdout.rstrip().endswith("---") and echo.stdout.count("---") == 1
    stamp = cli("topic", "echo", ifc.JOINT_TARGETS, "--count", "2", "--field", "header.stamp", *DISCOVERY)
    assert stamp.returncode == 0 and stamp.stdout.count("nanosec:") == 2, stamp

    # the statistics' form (a rate in wall time: its value is the benchmark's business, not a test's)
    hz = cli("topic", "hz", ifc.CLOCK, "--duration", "2")
    assert hz.returncode == 0, hz.stderr
    summary = re.findall(r"average rate: ([0-9.]+)\n\tmin: [0-9.]+s max: [0-9.]+s std dev: [0-9.]+s "
                         r"window: (\d+)", hz.stdout)
    assert summary and float(summary[-1][0]) > 0 and int(summary[-1][1]) >= 2, hz.stdout
    assert graph.procs["sim_node"].popen.poll() is None, "the graph ended before the tools were done"


def test_graph_command_ends_by_itself_and_leaves_nothing_behind(tmp_path, ros_domain):
    from cpg_walker.graph.processes import isolated_env

    env = isolated_env(ros_domain)
    p = subprocess.Popen([sys.executable, "-m", "cpg_walker.cli.main", "graph", "--duration", "3",
                          "--pacing", "lockstep", "--log-dir", str(tmp_path / "logs")], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        out, _ = p.communicate(timeout=sim_deadline(3.0))
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        left = node_pids(ros_domain)  # listed before the fixture kills them at teardown
    assert p.returncode == 0, out[-3000:]
    assert f"ROS_DOMAIN_ID={ros_domain} (ROS_DOMAIN_ID)" in out
    assert f"ROS_DOMAIN_ID={ros_domain} cpg-walker param set /cpg zeta 0.8" in out
    assert "[cpg] " in out and "[sim] " in out and "sim_node finished; stopping the graph" in out, out[-3000:]
    assert "stopped: odom_node 0, pid_node 0, cpg_node 0, sim_node 0" in out, out[-3000:]
    assert not left
    assert subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True).returncode == 1
