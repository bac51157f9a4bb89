"""Node faults on the real graph (`cpg-walker faults --out DIR`): sim_node (realtime pacing) + pid_node +
cpg_node as processes, walking at ζ = 1; each node in turn is killed (SIGKILL, its whole process group)
mid-walk and started again, and the robot's response is measured from /odom/ground_truth and /sim/fallen:
whether it fell, and the time until it walks again (its forward speed over the last WINDOW_S sim s back
above WALKING_FRACTION of the speed before the first fault). Writes DIR/faults.json and DIR/faults.md.

What each node does about the others' faults (docs/ROS_INTERFACE.md, "Faults"): pid_node follows the
/joint_trajectory horizon and then holds the standing crouch when /joint_targets stop; a cpg_node that
joins a running sim re-enters the gait from that crouch (CPGGaitSource.reenter); the sim waits for a late
torque (late_torque_wait) and then goes on with the held one; a restarted sim starts at t = 0, which
pid_node and cpg_node take for a reset (runtime.CLOCK_RESET_S) and start over.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.graph.probe import Probe, RobotTrack
from cpg_walker.nodes import interface as ifc

#: Sim s of odometry the walking speed is measured over (about two strides).
WINDOW_S = 2.0
#: "Walking again": the speed over the last WINDOW_S at least this fraction of the speed before the faults.
WALKING_FRACTION = 0.5
#: The order the nodes are killed and restarted in.
FAULT_ORDER = ("cpg_node", "pid_node", "sim_node")


#: The /diagnostics status of each node that publishes one (FaultGraph.restart forgets the dead node's).
STATUS = {"cpg_node": "cpg_walker/cpg", "sim_node": "cpg_walker/sim"}


def _no_signals():
    from rclpy.signals import SignalHandlerOptions

    return SignalHandlerOptions.NO


@dataclass
class FaultResult:
    node: str
    killed_at_s: float  # sim time of the kill
    restarted_after_wall_s: float  # wall s from the kill to the restart
    fell: bool
    fall_time_s: float | None  # sim time (of the sim run then going; after a sim fault, the new one's)
    walking_again_s: float | None  # sim s from the kill until walking again (sim fault: the new run's t)
    walking_again_wall_s: float | None  # wall s from the kill until walking again
    up_at_s: float  # sim time the new node was up (`FaultGraph.wait_up`; sim fault: 0, the new run)
    walking_after_up_s: float | None  # sim s from then until walking again (incl. the WINDOW_S)
    speed_before_mps: float
    speed_after_mps: float | None  # over the WINDOW_S at which it counted as walking again
    sim_reset: bool = False  # the sim restarted at t = 0 (the others saw time go back)


#: /odom/ground_truth and /sim/fallen as the monitor tracks them (graph/probe.py).
Odometry = RobotTrack


class FaultGraph:
    """The walking graph and a monitor (graph/probe.py ``Probe``: /odom/ground_truth, /sim/fallen,
    /diagnostics) on its domain; `kill` / `restart` a node; wait on sim time and on what the nodes say on
    /diagnostics. A context manager that stops every process it started."""

    def __init__(self, out_dir: str | Path, zeta: float = 1.0, domain_id: int | None = None,
                 say=None, pacing: str = "realtime"):
        from cpg_walker.graph.processes import Graph

        self.out = Path(out_dir)
        self.graph = Graph(self.out / "logs", domain_id=domain_id)
        self.zeta = float(zeta)
        self.pacing = pacing
        self.odom = RobotTrack()  # the probe's, once started
        self.say = say or (lambda text: print(f"faults: {text}", file=sys.stderr, flush=True))
        self.restarts: dict[str, int] = {}
        self.probe: Probe | None = None
        self._holders: list = []  # (context, node): participants holding a killed node's DDS ports
        self._up_besides: set[bytes] = set()  # a restarted pid_node's predecessor's subscription ids

    # -------------------------------------------------------------- processes
    def params(self, node: str) -> dict:
        lockstep = ifc.controllers_lockstep(self.pacing)
        if node == "sim_node":
            return {"pacing": self.pacing, "duration": 0.0, "stop_on_fall": False}
        if node == "pid_node":
            return {"wait_for_targets": True, "lockstep": lockstep}
        return {"zeta": self.zeta, "lockstep": lockstep}

    def start(self) -> None:
        """pid_node and cpg_node, then the sim (realtime) once cpg_node is up, as users start the graph."""
        keys = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOCALHOST_ONLY")
        self._saved_env = {k: os.environ.get(k) for k in keys}
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # as the graph's nodes (Graph.env)
        os.environ.pop("ROS_LOCALHOST_ONLY", None)
        self.probe = Probe(self.graph.domain_id, "faults_monitor", robot=True, diagnostics=True,
                           parameter_services=False)
        self.odom = self.probe.robot
        self.graph.start("pid_node", **self.params("pid_node"))
        self.graph.start("cpg_node", **self.params("cpg_node"))
        # cpg_node is up when its CPG is loaded: then it subscribes to /sim/servo_hold, its last topic (a
        # loaded machine: minutes)
        cpg = ifc.NODE_NAMES[ifc.CPG_NODE]
        self.wait(lambda: self.probe.subscribed(cpg, ifc.SIM_SERVO_HOLD), 600.0, "cpg_node's CPG loaded",
                  node="cpg_node")
        self.wait(lambda: self.probe.node.count_publishers(ifc.JOINT_TRAJECTORY) > 0, 300.0, "cpg_node up")
        self.graph.start("sim_node", **self.params("sim_node"))

    def status(self, node: str) -> dict[str, str]:
        """The latest /diagnostics key-values of ``node`` (cpg_node, sim_node; {} before any)."""
        return self.probe.status(STATUS[node])

    def value(self, node: str, key: str, default: float | None = None) -> float | None:
        """A numeric /diagnostics value of ``node`` ('none' or not yet said: ``default``)."""
        return self.probe.value(STATUS[node], key, default)

    def kill(self, node: str) -> None:
        """SIGKILL the node's process group (no clean-up, as a crash); then take its DDS ports
        (`hold_ports`)."""
        proc = self.graph.procs[node]
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.popen.wait(timeout=30)
        self.hold_ports()

    def hold_ports(self) -> None:
        """A participant of this process takes the lowest free participant id: the killed node's, so its
        restart gets another. A new participant on the dead one's id (the same UDP and shared-memory port
        numbers) stayed deaf to the running nodes now and then (2 of 12 cpg_node restarts here; a fresh
        participant saw its endpoints, the running ones exchanged only SPDP with it): they keep sending to
        the dead process's shared-memory port (Fast-DDS issues 2811, 5053). With the ports held: 0 of 20.
        A shared-memory-free restart is not available: with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
        rmw_fastrtps keeps shared memory whatever FASTDDS_BUILTIN_TRANSPORTS says (measured)."""
        import rclpy

        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=self.graph.domain_id, signal_handler_options=_no_signals())
        self._holders.append((ctx, rclpy.create_node("faults_port_holder", context=ctx,
                                                     start_parameter_services=False)))

    def restart(self, node: str) -> None:
        """Start ``node`` again with the same parameters (its previous log kept as <node>.<n>.log)."""
        n = self.restarts.get(node, 0) + 1
        self.restarts[node] = n
        if node in STATUS:  # what the dead node said is not the new one's
            self.probe.forget(STATUS[node])
        if node == "pid_node":  # its dead predecessor's subscription may linger in the graph
            self._up_besides = self.probe.subscription_gids(ifc.NODE_NAMES[node], ifc.JOINT_STATES)
        log = self.graph.procs[node].log_path
        if log.exists():
            log.rename(log.with_name(f"{node}.{n}.log"))
        self.graph.start(node, **self.params(node))

    # -------------------------------------------------------------- waiting
    def spin(self, seconds: float) -> None:
        self.probe.spin_for(seconds)

    def wait(self, until, timeout: float, what: str, node: str = "sim_node") -> None:
        """Spin until ``until()``; TimeoutError naming ``what`` (and ``node``'s log tail) after ``timeout``
        wall s (a hang guard, not a speed claim); RuntimeError if ``node`` exits meanwhile."""
        proc = self.graph.procs.get(node)

        def tail() -> str:
            return proc.log()[-1500:] if proc else ""

        end = time.monotonic() + timeout
        while not until():
            if proc is not None and proc.popen.poll() is not None:
                raise RuntimeError(f"{what}: {node} exited with status {proc.popen.returncode}; log tail:\n"
                                   f"{tail()}")
            if time.monotonic() > end:
                raise TimeoutError(f"{what}: not within {timeout} wall s (sim at {self.odom.t:.2f} s); "
                                   f"{node} log tail:\n{tail()}")
            self.probe.executor.spin_once(timeout_sec=0.01)

    def up(self, node: str) -> bool:
        """Whether a restarted ``node`` is up: cpg_node has re-entered the gait (/diagnostics
        ``reentries``), pid_node has its own /joint_states subscription (not its dead predecessor's)."""
        if node == "cpg_node":
            return self.value("cpg_node", "reentries", 0) >= 1
        if node == "pid_node":
            return self.probe.subscribed(ifc.NODE_NAMES[node], ifc.JOINT_STATES, self._up_besides)
        return bool(self.status(node))

    def wait_up(self, node: str, timeout: float) -> None:
        self.wait(lambda: self.up(node), timeout, f"the restarted {node} up", node=node)

    def wait_sim(self, t: float, timeout: float = 600.0) -> None:
        run = self.odom.runs
        self.wait(lambda: self.odom.runs == run and self.odom.t >= t, timeout, f"sim time {t} s")

    def wait_walking(self, speed_mps: float, after_s: float, limit_s: float, timeout: float,
                     run: int | None = None) -> float | None:
        """Sim time (of sim run ``run``, default the current) at which the speed over the last WINDOW_S,
        measured from ``after_s`` on, first reaches ``speed_mps``; None if not by ``limit_s`` sim s or
        after a fall."""
        run = self.odom.runs if run is None else run
        found: list[float] = []

        def done() -> bool:
            o = self.odom
            if o.runs != run:
                return False
            if o.fell_at is not None or o.t >= limit_s:
                return True
            if o.t >= after_s + WINDOW_S:
                v = o.speed()
                if v is not None and v >= speed_mps:
                    found.append(o.t)
                    return True
            return False

        self.wait(done, timeout, f"walking again (or {limit_s} sim s)")
        return found[0] if found else None

    def close(self) -> None:
        try:
            self.graph.stop_all()
        finally:
            for ctx, holder in self._holders:
                import rclpy

                holder.destroy_node()
                rclpy.try_shutdown(context=ctx)
            if self.probe is not None:
                self.probe.close()
            for k, v in getattr(self, "_saved_env", {}).items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v

    def __enter__(self) -> FaultGraph:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def inject(g: FaultGraph, node: str, before: float, away_wall_s: float, recover_s: float,
           timeout: float) -> FaultResult:
    """Kill ``node`` now, start it again ``away_wall_s`` wall s later, and wait until the robot walks again
    (up to ``recover_s`` sim s after the new node is up, or of the new run for the sim)."""
    t_kill, w_kill = g.odom.t, time.monotonic()
    runs = g.odom.runs
    g.say(f"killing {node} at sim {t_kill:.2f} s")
    g.kill(node)
    g.spin(away_wall_s)
    g.restart(node)
    restarted = time.monotonic() - w_kill
    g.say(f"restarted {node} after {restarted:.1f} wall s (sim at {g.odom.t:.2f} s)")
    reset = node == "sim_node"
    if reset:  # the new sim's time starts at 0: its run is the next one
        g.wait(lambda: g.odom.runs > runs, timeout, "the restarted sim's odometry")
        start, origin, limit = 0.0, 0.0, recover_s
    else:  # walking is measured from the moment the new node is up (not on the motion before)
        g.wait_up(node, timeout)
        g.spin(0.2)  # the odometry that came meanwhile
        start, origin = g.odom.t, t_kill
        limit = start + recover_s
    g.say(f"{node} up at sim {g.odom.t:.2f} s")
    at = g.wait_walking(WALKING_FRACTION * before, start, limit, timeout, run=runs + int(reset))
    wall = time.monotonic() - w_kill
    fell = g.odom.fell_at is not None
    res = FaultResult(
        node=node, killed_at_s=round(t_kill, 3), restarted_after_wall_s=round(restarted, 2), fell=fell,
        fall_time_s=None if not fell else round(g.odom.fell_at, 3),
        walking_again_s=None if at is None else round(at - origin, 3),
        walking_again_wall_s=None if at is None else round(wall, 2),
        up_at_s=round(start, 3), walking_after_up_s=None if at is None else round(at - start, 3),
        speed_before_mps=round(before, 4),
        speed_after_mps=None if at is None else round(g.odom.speed(), 4), sim_reset=reset)
    state = "fell" if fell else ("walking again" if at is not None else "not walking")
    g.say(f"{node}: {state}" + (f" {res.walking_again_s:.2f} sim s after the kill ({res.walking_again_wall_s}"
                                " wall s)" if at is not None else ""))
    return res


def run_faults(out_dir: str | Path, zeta: float = 1.0, warm_s: float = 14.0, away_wall_s: float = 2.0,
               recover_s: float = 25.0, settle_s: float = 6.0, faults: tuple[str, ...] = FAULT_ORDER,
               timeout: float = 900.0, domain_id: int | None = None) -> dict:
    """Walk ``warm_s`` sim s, then each fault in turn (`inject`), ``settle_s`` sim s of walking between
    them; write faults.json and faults.md to ``out_dir``; return the report. ``domain_id``: the graph's
    DDS domain (None: a quiet one)."""
    bad = [f for f in faults if f not in FAULT_ORDER]
    if bad:
        raise InputError(f"unknown node(s) {bad}; faults are of {list(FAULT_ORDER)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: list[FaultResult] = []
    w0 = time.monotonic()
    with FaultGraph(out, zeta=zeta, domain_id=domain_id) as g:
        g.start()
        g.say(f"graph on DDS domain {g.graph.domain_id}; walking to sim {warm_s:g} s")
        g.wait_sim(warm_s, timeout)
        before = g.odom.speed(4.0)
        if before is None or before < 0.02 or g.odom.fell_at is not None:
            raise RuntimeError(f"the robot is not walking before the faults (speed {before}, fell at "
                               f"{g.odom.fell_at})")
        g.say(f"walking at {before:.3f} m/s")
        fallen = False
        for node in faults:
            if fallen and node != "sim_node":
                g.say(f"the robot has fallen: no {node} fault (a sim restart stands it up again)")
                continue
            if results and not fallen:
                g.wait_sim(g.odom.t + settle_s, timeout)
            res = inject(g, node, before, away_wall_s, recover_s, timeout)
            results.append(res)
            fallen = res.fell
    report = {"zeta": zeta, "pacing": "realtime", "window_s": WINDOW_S, "walking_fraction": WALKING_FRACTION,
              "away_wall_s": away_wall_s, "wall_s": round(time.monotonic() - w0, 1),
              "faults": [asdict(r) for r in results]}
    (out / "faults.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / "faults.md").write_text(markdown_table(report))
    return report


def markdown_table(report: dict) -> str:
    """The per-fault table (docs/faults.md)."""
    def f(v, fmt="{:.2f}"):
        return "-" if v is None else fmt.format(v)

    lines = ["| node killed (SIGKILL) | at sim s | restarted after (wall s) | up at sim s | fell | walking "
             "again after the kill (sim s) | (wall s) | after up (sim s) | speed before / after (m/s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in report["faults"]:
        again = f(r["walking_again_s"]) + (" (new run's t)" if r["sim_reset"] else "")
        lines.append(f"| {r['node']} | {r['killed_at_s']:.2f} | {r['restarted_after_wall_s']:.1f} | "
                     f"{r['up_at_s']:.2f} | {'yes' if r['fell'] else 'no'} | {again} | "
                     f"{f(r['walking_again_wall_s'], '{:.1f}')} | {f(r['walking_after_up_s'])} | "
                     f"{r['speed_before_mps']:.3f} / {f(r['speed_after_mps'], '{:.3f}')} |")
    return "\n".join(lines) + "\n"
