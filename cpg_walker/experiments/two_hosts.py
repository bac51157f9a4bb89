"""``cpg-walker two-hosts``: the CPG walk with the robot on one "host" and its controllers on another.

sim_node runs in network namespace a, pid_node and cpg_node in namespace b, joined by a veth pair
(graph/netns.py, created and removed here; root needed). Each namespace has only lo and its veth end, so
every DDS packet between the two sides crosses the link (sim_node is UDP-only: the namespaces share
/dev/shm, two hosts would not), and discovery can reach nothing but the other address. Discovery: the
SUBNET range plus the other side as ROS_STATIC_PEERS, which connected every time on this Fast DDS 2.14
PyPI build (LOCALHOST plus static peers did not, at first; OFF ignores static peers: docs/DEPLOYMENT.md).

The walk is lockstep (sim_node waits for each period's torque, so other load on the machine slows it
down but does not change it). ``compare`` runs the same walk on one host first, and reports the sim's
state->torque round trip (wall time from publishing /joint_states to the matching /joint_torques
arriving, sim_node's ``latency`` stats) for both.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cpg_walker.experiments.walk_graph import run_graph_walk
from cpg_walker.graph.netns import Host, VethPair
from cpg_walker.graph.processes import Placement

#: Discovery environment of a node on one side: automatic discovery on its subnet (inside the namespace:
#: the veth's /30 and lo) and the other side's address as a static peer.
DISCOVERY_RANGE = "SUBNET"
#: Transports of sim_node: UDP only. Two real hosts share no memory; the namespaces here share /dev/shm,
#: and Fast DDS's shared-memory transport must not carry what is meant to cross the link. The controllers
#: keep the default (shared memory between the two of them, UDP to the sim, which offers nothing else).
SIM_TRANSPORTS = "UDPv4"
#: Hang guard of a walk (wall s): start-up, then this many wall s per sim s (lockstep ran at 0.1-0.4x
#: real time with other jobs on the 2-core machine).
START_S, WALL_PER_SIM_S = 180.0, 20.0
#: The node executables on the controller side (namespace b); sim_node is on side a.
CONTROLLERS = ("pid_node", "cpg_node")
#: Lockstep's wall-clock waits, made patient for a machine shared with other jobs' real-time processes
#: (both walks get them): pid_node waits for cpg_node's first target (cpg_node's start-up took over the
#: default 30 s there, and the sim then ran on held targets and the robot fell) and for each tick's
#: target, cpg_node for each tick's sensor samples, before going on without them.
PATIENT = {"pid_node": {"startup_wait": START_S, "target_wait": 10.0}, "cpg_node": {"sensor_wait": 10.0}}
#: The keys of a walk report kept in the comparison.
KEPT = ("fell", "fall_time_s", "duration_s", "distance_m", "real_time_factor")


def side_env(peer: Host) -> dict[str, str]:
    """A node's discovery settings with ``peer`` on the other end of the link."""
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": DISCOVERY_RANGE, "ROS_STATIC_PEERS": peer.address}


def placement(a: Host, b: Host) -> dict[str, Placement]:
    """sim_node on ``a`` (UDP only), the controllers on ``b``, each with the other as its discovery
    peer."""
    place = {"sim_node": Placement(tuple(a.prefix()),
                                   side_env(b) | {"FASTDDS_BUILTIN_TRANSPORTS": SIM_TRANSPORTS})}
    for node in CONTROLLERS:
        place[node] = Placement(tuple(b.prefix()), side_env(a))
    return place


def hang_guard(duration: float) -> float:
    """Wall s after which a walk of ``duration`` sim s is called hung."""
    return START_S + WALL_PER_SIM_S * duration


def run_two_hosts(out_dir: str | Path, duration: float = 30.0, timeout: float | None = None,
                  domain_id: int | None = None) -> dict:
    """The lockstep walk across a fresh veth pair; walk.json's report plus ``link``: the two sides and the
    bytes that crossed it (counted on a's veth end). ``timeout``: wall s (None: ``hang_guard``)."""
    out = Path(out_dir)
    timeout = hang_guard(duration) if timeout is None else timeout
    with VethPair() as (a, b):
        rx0, tx0 = a.link_bytes()
        report = run_graph_walk(out, duration=duration, pacing="lockstep", timeout=timeout,
                                domain_id=domain_id, placement=placement(a, b), node_params=PATIENT)
        rx1, tx1 = a.link_bytes()
    report["link"] = {
        "sim_side": {"netns": a.netns, "address": a.address, "nodes": ["sim_node"]},
        "controller_side": {"netns": b.netns, "address": b.address, "nodes": list(CONTROLLERS)},
        "discovery": side_env(b) | {"ROS_STATIC_PEERS": "the other side's address"},
        "sim_transports": SIM_TRANSPORTS,
        "bytes_to_sim": rx1 - rx0, "bytes_from_sim": tx1 - tx0,
    }
    (out / "walk.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def summary(report: dict) -> dict:
    """The comparison's view of one walk: outcome, real-time factor, round trip, late/resent periods."""
    g = report["graph"]
    kept = {k: report[k] for k in KEPT}
    kept |= {"latency_state_to_torque": g["latency_state_to_torque"], "resends": g["resends"],
             "torque_age_s": g["torque_age_s"], "wall_s_total": g["wall_s_total"]}
    if "link" in report:
        kept["link"] = {k: report["link"][k] for k in ("bytes_to_sim", "bytes_from_sim")}
    return kept


def compare(out_dir: str | Path, duration: float = 30.0, local: bool = True,
            timeout: float | None = None) -> dict:
    """The walk on one host (unless ``local`` is False) and across the link; writes and returns
    ``two_hosts.json``: both summaries and the round trip's p50/p99 side by side."""
    out = Path(out_dir)
    timeout = hang_guard(duration) if timeout is None else timeout
    runs = {}
    if local:
        runs["local"] = summary(run_graph_walk(out / "local", duration=duration, pacing="lockstep",
                                               timeout=timeout, node_params=PATIENT))
    runs["two_hosts"] = summary(run_two_hosts(out / "two_hosts", duration=duration, timeout=timeout))
    table = {name: {k: run["latency_state_to_torque"].get(k, math.nan) for k in ("p50_ms", "p99_ms")}
             for name, run in runs.items()}
    result = {"duration_s": duration, "pacing": "lockstep", "state_to_torque_ms": table, "runs": runs}
    out.mkdir(parents=True, exist_ok=True)
    (out / "two_hosts.json").write_text(json.dumps(result, indent=2) + "\n")
    return result
