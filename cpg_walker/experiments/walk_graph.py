"""``cpg-walker walk``: the CPG walk through the ROS graph, three processes.

cpg_node streams the learned CPG as /joint_targets on every /clock tick (the recording's opening steps,
then the CPG), pid_node closes the loop over /joint_states -> /joint_torques, sim_node steps the HOAP-2
and records the run. Run and summarised by the graph replay's code (experiments/replay_graph.py), so
walk.json has replay.json's keys (``heading_change_deg`` among them) plus ``zeta``, ``alpha``,
``feedback``, ``real_time_factor``, the CPG facts and the ``schedule`` as it landed. Every node gets its
parameters file (config/<node>.yaml); ``zeta``/``alpha``/``feedback``/``cpg_file`` None leave cpg_node's
values from config/cpg.yaml.

A ``schedule`` of (t, zeta, alpha) changes goes through cpg_node's SetParameters service (the one
``ros2 param set`` / ``cpg-walker param set`` call), sent from this process once /clock reaches t: one
request with both values, so they land on the same tick. The sim runs on during the service's round
trip, so a change lands a little after t (the sim time it took effect is in walk.json, from cpg_node's
log); in lockstep the landing tick depends on the machine's timing (the rest of the run does not).
"""

from __future__ import annotations

import json
import math
import re
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

from cpg_walker.errors import InputError
from cpg_walker.graph.processes import Placement
from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.recording import BAG_NAME
from cpg_walker.walker.learning import cpg_defaults


class Watcher(Protocol):
    """Something that follows a running graph from this process (``run_graph_walk``'s ``watchers``)."""

    def start(self, domain_id: int) -> None: ...

    def stop(self) -> None: ...


#: Wall s to allow cpg_node for learning at start-up (cpg_file ''): pid_node's startup_wait then.
LEARN_WAIT_S = 600.0


def check_modulation(zeta: float, alpha: float, governed: bool = True) -> None:
    """The cpg_node's ranges (with or without its governor), checked before any process starts."""
    from cpg_walker.walker.governor import GovernorConfig, command_error

    gcfg = GovernorConfig.load() if governed else None
    for name, value in (("zeta", zeta), ("alpha", alpha)):
        reason = command_error(name, value, gcfg)
        if reason:
            raise InputError(f"--{name}: {reason}")


def parse_schedule(text: str) -> list[tuple[float, float, float]]:
    """``"T,Z,A;T,Z,A"`` -> [(t sim s, zeta, alpha), ...] sorted by t; ValueError naming a bad item."""
    out = []
    for item in text.split(";"):
        if not item.strip():
            continue
        parts = item.split(",")
        try:
            t, z, a = (float(x) for x in parts)
        except ValueError:
            raise InputError(f"--schedule item {item!r}: expected 'time,zeta,alpha' (three numbers)") \
                from None
        if not (t >= 0 and math.isfinite(t)):
            raise InputError(f"--schedule item {item!r}: the time must be >= 0 sim s")
        if not (math.isfinite(z) and math.isfinite(a)):
            raise InputError(f"--schedule item {item!r}: zeta and alpha must be finite numbers")
        out.append((t, z, a))  # a value the node refuses is sent, refused and recorded: the walk goes on
    return sorted(out)


class ParameterSchedule:
    """Sends each (t, zeta, alpha) to /cpg/set_parameters when /clock reaches t, from a thread with its own
    probe (graph/probe.py) on the graph's domain; ``sent`` records (t, the /clock time it was sent at,
    accepted, the node's reason)."""

    def __init__(self, domain_id: int, schedule: list[tuple[float, float, float]]):
        self.domain_id, self.todo = domain_id, list(schedule)
        self.sent: list[dict] = []
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpg-schedule", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=30.0)

    def _run(self) -> None:
        from rcl_interfaces.msg import Parameter
        from rcl_interfaces.srv import SetParameters
        from rosgraph_msgs.msg import Clock

        from cpg_walker.graph.probe import Probe
        from cpg_walker.graph.ros2cli import to_parameter_value

        probe = Probe(self.domain_id, "walk_schedule", parameter_services=False)
        executor = probe.executor
        clock = [-1.0]
        probe.subscribe(ifc.CLOCK, Clock, lambda m: clock.__setitem__(
            0, max(clock[0], m.clock.sec + m.clock.nanosec * 1e-9)), 100)
        client = probe.node.create_client(SetParameters, "/cpg/set_parameters")
        pending = None
        try:
            while not self._stop.is_set() and (self.todo or pending is not None):
                executor.spin_once(timeout_sec=0.005)
                if pending is not None:
                    if pending[1].done():
                        results = pending[1].result().results
                        ok = all(r.successful for r in results)
                        self.sent.append({**pending[0], "accepted": ok,
                                          "reason": "; ".join(r.reason for r in results if r.reason)})
                        pending = None
                    continue
                t, z, a = self.todo[0]
                if clock[0] >= t and client.service_is_ready():
                    self.todo.pop(0)
                    req = SetParameters.Request(parameters=[
                        Parameter(name="zeta", value=to_parameter_value(float(z))),
                        Parameter(name="alpha", value=to_parameter_value(float(a)))])
                    pending = ({"t_s": t, "zeta": z, "alpha": a, "sent_at_sim_s": round(clock[0], 4),
                                "sent_wall": time.time()}, client.call_async(req))
        except Exception as exc:  # reported in walk.json; the walk itself goes on
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            probe.close()


#: cpg_node's log line for a modulation command (nodes/cpg_node.py ``_command``).
COMMANDED = re.compile(r"commanded zeta=(\S+), alpha=(\S+) after sim ([\d.]+) s")


def landed(schedule: list[dict], cpg_log: str) -> list[dict]:
    """The schedule's entries with ``applied_after_sim_s``: the sim time of the tick after which cpg_node
    applied each (the first of its log lines, after the previous entry's, with both values: rclpy calls
    the node's parameter callback once per parameter of a request, so a request logs one line each)."""
    lines = [(float(z), float(a), float(t)) for z, a, t in COMMANDED.findall(cpg_log)]
    out, i = [], 0
    for entry in schedule:
        item = {k: v for k, v in entry.items() if k != "sent_wall"}
        if entry["accepted"]:
            j = next((j for j in range(i, len(lines))
                      if lines[j][:2] == (float(entry["zeta"]), float(entry["alpha"]))), None)
            if j is not None:
                item["applied_after_sim_s"] = lines[j][2]
                i = j + 1
        out.append(item)
    return out


def run_graph_walk(
    out_dir: str | Path,
    duration: float = 60.0,
    zeta: float | None = None,
    alpha: float | None = None,
    cpg_file: str | None = None,
    feedback: bool | None = None,
    schedule: list[tuple[float, float, float]] | None = None,
    pacing: str = "lockstep",
    control_period: float | None = None,
    stop_on_fall: bool = True,
    timeout: float | None = None,
    record: bool = False,
    domain_id: int | None = None,
    watchers: Sequence[Watcher] = (),
    foxglove: str | None = None,
    relay: dict | None = None,
    placement: dict[str, Placement] | None = None,
    node_params: dict[str, dict] | None = None,
) -> dict:
    """Walk through sim_node + pid_node + cpg_node; write ``walk.json``; return its content. ``record``:
    every topic also to ``out_dir/recording.mcap`` (recorder_node; walk.json's ``bag``). ``zeta``,
    ``alpha``, ``feedback``, ``cpg_file`` None: cpg_node's own (config/cpg.yaml), not passed on.
    ``schedule``: (t, zeta, alpha) changes sent through cpg_node's SetParameters service (module doc).
    ``domain_id``: the graph's DDS domain (None: a free one). ``watchers`` are started on the graph's domain
    once its nodes are (e.g. a live status) and stopped when it has finished, however it ends.
    ``foxglove``: ``[HOST:]PORT`` ('' = 127.0.0.1:8765) of a Foxglove live view (foxglove_node) on the
    graph; its URL is printed to stderr once it listens. ``relay``: a degraded link (relay_node with these
    overrides of config/relay.yaml) in front of the controllers (replay_graph.run_graph); walk.json's
    ``relay`` holds its counters. ``placement``: where nodes run, ``node_params``: more parameter
    overrides by node executable (both: run_graph)."""
    from cpg_walker.experiments.replay_graph import run_graph
    from cpg_walker.nodes.interface import PACINGS
    from cpg_walker.walker.learning import load_controller

    if pacing not in PACINGS:
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    view = None
    if foxglove is not None:
        from cpg_walker.nodes.foxglove_view import parse_address

        host, port = parse_address(foxglove)  # ValueError before anything starts
        view = {"host": host, "port": port}
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"--duration must be a positive number of seconds, got {duration}")
    defaults = cpg_defaults()
    overrides: dict[str, object] = {name: float(value) for name, value in (("zeta", zeta), ("alpha", alpha))
                                    if value is not None}
    if feedback is not None:
        overrides["feedback"] = bool(feedback)
    feedback = bool(defaults["feedback"]) if feedback is None else bool(feedback)
    schedule = sorted(schedule or [])
    for t, _, _ in schedule:
        if not 0 <= t < duration:
            raise InputError(f"schedule time {t:g} s is outside the walk (0 to {duration:g} sim s)")
    zeta, alpha = (float(defaults[name]) if value is None else value
                   for name, value in (("zeta", zeta), ("alpha", alpha)))
    governed = (node_params or {}).get("cpg_node", {}).get("governor", defaults["governor"])
    check_modulation(zeta, alpha, bool(governed))
    cpg_file = defaults["cpg_file"] if cpg_file is None else cpg_file
    learn_now = not cpg_file
    ctrl = None
    if not learn_now:  # fail early, in this process, on a missing or corrupt file
        ctrl, origin, _ = load_controller(cpg_file)
        cpg_file = str(Path(origin).resolve())
    out = Path(out_dir)
    limit = timeout if timeout is not None else 60.0 + duration * 5.0 + (LEARN_WAIT_S if learn_now else 0.0)
    changes: list[ParameterSchedule] = []

    started: list[Watcher] = []

    def attach(graph) -> list:
        if schedule:
            changes.append(ParameterSchedule(graph.domain_id, schedule))
            changes[0].start()
        for w in watchers:
            w.start(graph.domain_id)
            started.append(w)
        if view is not None:
            from cpg_walker.graph.runner import start_foxglove

            print(start_foxglove(graph, view), file=sys.stderr, flush=True)
        return []

    try:
        cpg_params = {"cpg_file": cpg_file, "lockstep": ifc.controllers_lockstep(pacing), **overrides}
        run = run_graph(out, "cpg_node", cpg_params, duration=duration, pacing=pacing,
                        control_period=control_period, stop_on_fall=stop_on_fall, timeout=limit,
                        pid_params={"startup_wait": LEARN_WAIT_S} if learn_now else None, attach=attach,
                        bag_dir=out if record else None, domain_id=domain_id, relay=relay,
                        placement=placement,
                        node_params=node_params)
    finally:
        for c in [*changes, *started]:
            c.stop()
    period = ctrl.period / abs(zeta) if ctrl is not None and zeta else None
    metrics, _ = run.report(period_s=period)
    report = {
        **metrics,
        "zeta": zeta, "alpha": alpha, "feedback": feedback,
        "n_oscillators": int(ctrl.net.N) if ctrl is not None else None,
        "cpg_file": cpg_file or "learned at start-up",
    }
    cpg_stats = run.stats.get("cpg_node")
    if cpg_stats:
        report["cpg_feedback"] = cpg_stats.get("feedback")
    if relay is not None:
        report["relay"] = run.stats.get("relay_node", {}).get("topics")
    if record:
        report["bag"] = str((out / f"{BAG_NAME}.mcap").resolve())
    if schedule:
        report["schedule"] = landed(changes[0].sent, run.logs.get("cpg_node", ""))
        report["schedule_unsent"] = [list(x) for x in changes[0].todo]
        report["refused"] = [{k: e[k] for k in ("t_s", "zeta", "alpha", "reason")}
                             for e in changes[0].sent if not e["accepted"]]
        if changes[0].error:
            report["schedule_error"] = changes[0].error
    (out / "walk.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
