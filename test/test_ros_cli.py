"""`cpg-walker graph | param | topic`: the pip-only stand-ins for `ros2 launch/param/topic`, run as real
subprocesses against a real graph on the test's own random DDS domain (the `graph` fixture)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """The real `cpg-walker` in a subprocess, on the domain in ROS_DOMAIN_ID (set by the fixture)."""
    return subprocess.run([sys.executable, "-m", "cpg_walker.cli.main", *args], capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def test_param_and_topic_tools_against_a_running_graph(graph):
    graph.start("pid_node", lockstep=True, wait_for_targets=True)
    graph.start("cpg_node")
    graph.start("sim_node", pacing="lockstep", duration=300.0)

    listed = cli("param", "list", "/cpg")
    assert listed.returncode == 0, listed.stderr
    assert {"zeta", "alpha"} <= set(listed.stdout.split())

    ok = cli("param", "set", "/cpg", "zeta", "0.8")
    assert ok.returncode == 0 and "Set parameter successful" in ok.stdout, ok.stderr
    got = cli("param", "get", "/cpg", "zeta")
    assert got.returncode == 0 and got.stdout.strip() == "Double value is: 0.8", got
    one = cli("param", "set", "/cpg", "alpha", "1")  # an integer for a double parameter: sent as 1.0
    assert one.returncode == 0, one.stderr
    for bad, reason in (("nan", "zeta out of range"), ("5", "zeta out of range"),
                        ("fast", "Wrong parameter type")):  # the node's (rclpy's) reasons
        r = cli("param", "set", "/cpg", "zeta", bad)
        assert r.returncode == 1, (bad, r)
        assert r.stderr.startswith("Setting parameter failed: ") and reason in r.stderr, (bad, r.stderr)
    assert cli("param", "get", "/cpg", "zeta").stdout.strip() == "Double value is: 0.8"

    missing = cli("param", "get", "/nonexistent", "x", "--timeout", "2")
    assert missing.returncode == 1
    assert f"node /nonexistent not found in domain {graph.domain_id}" in missing.stderr, missing.stderr

    topics = cli("topic", "list")
    assert topics.returncode == 0, topics.stderr
    assert "/joint_targets [sensor_msgs/msg/JointState]" in topics.stdout.splitlines(), topics.stdout
    assert "/clock [rosgraph_msgs/msg/Clock]" in topics.stdout.splitlines()

    echo = cli("topic", "echo", "/joint_targets", "--once", "--timeout", "30")
    assert echo.returncode == 0, echo.stderr
    assert "- lleg_joint_3" in echo.stdout and "\nposition:\n- " in echo.stdout, echo.stdout[:500]
    assert echo.stdout.rstrip().endswith("---") and echo.stdout.count("---") == 1
    stamp = cli("topic", "echo", "/joint_targets", "--count", "2", "--field", "header.stamp")
    assert stamp.returncode == 0 and stamp.stdout.count("nanosec:") == 2, stamp

    hz = cli("topic", "hz", "/clock", "--duration", "2")
    assert hz.returncode == 0, hz.stderr
    rates = [float(x) for x in re.findall(r"average rate: ([0-9.]+)", hz.stdout)]
    assert rates and rates[-1] > 10.0, hz.stdout
    assert graph.procs["sim_node"].popen.poll() is None, "the graph ended before the tools were done"


def _node_pids(domain: int) -> list[int]:
    """Node processes (python -m cpg_walker.nodes.*) running on ``domain``, read from /proc."""
    pids = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes()
            env = (proc / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"cpg_walker.nodes." in cmd and f"ROS_DOMAIN_ID={domain}".encode() in env:
            pids.append(int(proc.name))
    return pids


def test_graph_command_ends_by_itself_and_leaves_nothing_behind(tmp_path):
    from cpg_walker.nodes.graph import isolated_env, quiet_domain_id

    domain = quiet_domain_id()
    env = isolated_env(domain)
    started = time.monotonic()
    p = subprocess.Popen([sys.executable, "-m", "cpg_walker.cli.main", "graph", "--duration", "3",
                          "--pacing", "lockstep", "--log-dir", str(tmp_path / "logs")], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        out, _ = p.communicate(timeout=90)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        for pid in _node_pids(domain):  # never leave a node behind, even when the test fails
            os.kill(pid, signal.SIGKILL)
    assert p.returncode == 0, out[-3000:]
    assert f"ROS_DOMAIN_ID={domain} (ROS_DOMAIN_ID)" in out
    assert f"ROS_DOMAIN_ID={domain} cpg-walker param set /cpg zeta 0.8" in out
    assert "[cpg] " in out and "[sim] " in out and "sim_node finished; stopping the graph" in out, out[-3000:]
    assert "stopped: pid_node 0, cpg_node 0, sim_node 0" in out, out[-3000:]
    assert not _node_pids(domain)
    assert subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True).returncode == 1
    assert time.monotonic() - started < 90
