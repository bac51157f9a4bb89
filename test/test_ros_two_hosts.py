"""Two hosts (issue 14, part 5): sim_node in one network namespace, pid_node + cpg_node in another, joined
by a veth pair the test creates and removes (graph/netns.py; root and ``ip netns`` needed, else skipped).
Each namespace has only lo and its veth end, so every message between the robot and its controllers
crosses the link; discovery: the SUBNET range plus the other side's address as ROS_STATIC_PEERS
(experiments/two_hosts.py). The walk is lockstep: other load on the machine slows it, never changes it.

The local-vs-link latency comparison is ``cpg-walker two-hosts``
(docs/results/two_hosts/two_hosts.json, checked here)."""

from __future__ import annotations

import json
import math
import os
import subprocess
from pathlib import Path

import pytest

from cpg_walker.graph import netns
from cpg_walker.paths import ros_parameters

WHY_NOT = netns.unavailable()
needs_netns = pytest.mark.skipif(WHY_NOT is not None, reason=f"two hosts need network namespaces: {WHY_NOT}")

#: sim s of the walk across the link.
DURATION_S = 30.0
CONTROL_PERIOD_S = float(ros_parameters("sim.yaml", "sim")["control_period"])
#: Bytes a period's /joint_torques at least takes on the wire (RTPS + a JointState with every joint's
#: name and effort: several hundred in fact); the bytes to the sim must cover one per period.
TORQUE_BYTES_MIN = 100
RESULT = Path(__file__).resolve().parent.parent / "docs" / "results" / "two_hosts" / "two_hosts.json"


def _namespaces() -> set[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True).stdout
    return {line.split()[0] for line in out.splitlines() if line.strip()}


@pytest.mark.ros
@pytest.mark.slow
@needs_netns
def test_walk_across_two_hosts(tmp_path, ros_domain):
    from ros_helpers import sim_deadline

    from cpg_walker.experiments.two_hosts import run_two_hosts

    report = run_two_hosts(tmp_path, duration=DURATION_S, timeout=sim_deadline(DURATION_S),
                           domain_id=ros_domain)
    link = report["link"]
    assert not report["fell"], f"the robot fell at {report['fall_time_s']} s across the link"
    assert report["duration_s"] == pytest.approx(DURATION_S)
    periods = round(DURATION_S / CONTROL_PERIOD_S)
    latency = report["graph"]["latency_state_to_torque"]
    # lockstep: the sim steps a period only once that period's torque has come back across the link
    assert latency["count"] >= periods - 2, latency
    assert all(math.isfinite(latency[k]) and latency[k] > 0 for k in ("p50_ms", "p99_ms")), latency
    assert link["bytes_to_sim"] >= periods * TORQUE_BYTES_MIN, link
    assert link["bytes_from_sim"] >= periods * TORQUE_BYTES_MIN, link
    left = {link[side]["netns"] for side in ("sim_side", "controller_side")} & _namespaces()
    assert not left, f"namespaces left behind: {left}"


@needs_netns
def test_veth_pair_is_always_removed():
    """A pair is handed out with both ends up (carrier and address); it is removed when its block raises;
    a pair left by a process that is gone (a crashed run) is
    removed by the next pair's creation; a live process's pair is not."""
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = f"{netns.PREFIX}-{dead.pid}-0-a"
    mine = f"{netns.PREFIX}-{os.getpid()}-999-a"  # this process is alive: not stale
    for name in (stale, mine):
        subprocess.run(["ip", "netns", "add", name], check=True)
    try:
        with pytest.raises(RuntimeError, match="inside"), netns.VethPair() as (a, b):
            names = _namespaces()
            assert {a.netns, b.netns} <= names and stale not in names and mine in names
            for h in (a, b):
                shown = subprocess.run(["ip", "-n", h.netns, "addr", "show", "dev", h.device],
                                       capture_output=True, text=True, check=True).stdout
                assert f"inet {h.address}/30" in shown and ",UP," in shown, shown
                # up with carrier before the pair is handed out: a DDS participant started on a link
                # still coming up announces 127.0.0.1 and is never reached from the other side
                assert ",LOWER_UP" in shown and netns.is_up(h), shown
            raise RuntimeError("inside")
        assert not {a.netns, b.netns} & _namespaces()
    finally:
        for name in (stale, mine):
            subprocess.run(["ip", "netns", "delete", name], capture_output=True)


def test_committed_comparison():
    """docs/results/two_hosts/two_hosts.json (written by ``cpg-walker two-hosts``) holds the round trip of
    both walks, finite, and neither fell."""
    result = json.loads(RESULT.read_text())
    assert set(result["state_to_torque_ms"]) == {"local", "two_hosts"}
    for name, run in result["runs"].items():
        assert not run["fell"], name
        assert all(math.isfinite(v) for v in result["state_to_torque_ms"][name].values()), name
