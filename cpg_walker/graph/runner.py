"""The node graph in the foreground (``cpg-walker graph``): start it with
``cpg_walker.graph.processes.Graph``, stream the nodes' log lines with a prefix, stop everything on Ctrl-C /
SIGTERM / SIGHUP or when a node (normally the sim, at the end of ``duration``) exits."""

from __future__ import annotations

import math
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from cpg_walker.errors import InputError

PREFIX = {"sim_node": "sim", "pid_node": "pid", "cpg_node": "cpg", "target_player_node": "player",
          "recorder_node": "rec", "foxglove_node": "fox", "odom_node": "odom"}


@dataclass
class GraphSpec:
    """What ``cpg-walker graph`` was asked for; None = the node's parameters file decides."""

    pacing: str | None = None
    duration: float | None = None
    zeta: float | None = None
    alpha: float | None = None
    player: bool = False
    domain_id: int | None = None
    params: list[tuple[str, str, object]] = field(default_factory=list)
    log_dir: str | None = None
    record: str | None = None  # a directory: recorder_node writes recording.mcap there
    foxglove: str | None = None  # [HOST:]PORT ('' = the default): foxglove_node, the live view

    def sim_value(self, name: str) -> object:
        """The sim's ``pacing`` / ``duration``: as given, else its parameters file's."""
        from cpg_walker.paths import ros_parameters

        given = getattr(self, name)
        return ros_parameters("sim.yaml", "sim")[name] if given is None else given

    def node_params(self) -> dict[str, dict[str, object]]:
        """Each node's start-up parameters, the overrides of its parameters file (validated: ValueError)."""
        from cpg_walker.nodes.interface import PACINGS, controllers_lockstep
        from cpg_walker.paths import ros_parameters
        from cpg_walker.walker.governor import GovernorConfig, command_error

        pacing, duration = self.sim_value("pacing"), self.sim_value("duration")
        if pacing not in PACINGS:
            raise InputError(f"pacing must be one of {PACINGS}, got {pacing!r}")
        if not (duration >= 0 and math.isfinite(duration)):
            raise InputError(f"--duration must be >= 0 sim seconds (0: until stopped), got {duration}")
        target = "target_player_node" if self.player else "cpg_node"
        sim = {name: (float(value) if name == "duration" else value)
               for name, value in (("pacing", self.pacing), ("duration", self.duration)) if value is not None}
        # odom_node first (subscribed before the sim's first state); the estimate is odom -> base_link on
        # /tf, so the sim's ground truth is not (REP-105)
        out: dict[str, dict[str, object]] = {
            "odom_node": {},
            "pid_node": {"lockstep": controllers_lockstep(pacing), "wait_for_targets": True},
            target: {"lockstep": controllers_lockstep(pacing)} if not self.player else {},
            "sim_node": {"publish_tf": False, **sim},
        }
        for name in ("zeta", "alpha"):
            value = getattr(self, name)
            if value is None:
                continue
            if self.player:
                raise InputError(f"--{name} is a cpg_node parameter; not with --player")
            governed = ros_parameters("cpg.yaml", "cpg")["governor"]
            for node, pname, pvalue in self.params:
                if (node, pname) == ("cpg_node", "governor"):
                    governed = pvalue
            reason = command_error(name, value, GovernorConfig.load() if governed is True else None)
            if reason:
                raise InputError(f"--{name}: {reason}")
            out["cpg_node"][name] = float(value)
        if self.foxglove is not None:
            from cpg_walker.nodes.foxglove_view import parse_address

            host, port = parse_address(self.foxglove)
            out["foxglove_node"] = {"host": host, "port": port}
        for node, name, value in self.params:
            if node not in out:
                raise InputError(f"-p {node}:{name}: {node} is not part of this graph ({', '.join(out)})")
            out[node][name] = value
        return out

    def with_run_record(self, params: dict[str, dict[str, object]], log_dir: Path) -> Path:
        """sim_node's run record (its ``record_path``: the fall and where) in ``log_dir`` unless the user
        gave one; one sample per RECORD_PERIOD_S, so a run until Ctrl-C stays small. Returns its path."""
        sim = params["sim_node"]
        sim.setdefault("record_path", str(log_dir / "sim_record.json"))
        sim.setdefault("record_period", RECORD_PERIOD_S)
        return Path(str(sim["record_path"]))


#: Sim s between the samples of the run record `cpg-walker graph` keeps for its exit status.
RECORD_PERIOD_S = 1.0


def fall_of(record_path: Path) -> tuple[float | None, list | None] | None:
    """(time, (x, y)) of the fall in sim_node's run record; None when it did not fall or left no record."""
    from cpg_walker.robot.run_record import RunRecord

    if not record_path.exists():
        return None
    record = RunRecord.load(record_path)
    return (record.fall_time_s, record.fall_xy) if record.fell else None


def resolve_domain(domain_id: int | None) -> tuple[int, str]:
    """(domain, where it came from): the option, else ROS_DOMAIN_ID, else a free one."""
    from cpg_walker.graph.processes import check_domain_id, env_domain_id, quiet_domain_id

    if domain_id is not None:
        return check_domain_id(domain_id, "--domain-id"), "--domain-id"
    env = env_domain_id()
    if env is not None:
        return env, "ROS_DOMAIN_ID"
    return quiet_domain_id(), "a free one picked at random"


#: Wall s for the recorder to start listening before the graph starts without it being an error.
RECORDER_START_S = 120.0
#: Wall s for foxglove_node's server to listen (imports, the MuJoCo model) before that is an error.
FOXGLOVE_START_S = 120.0


def start_foxglove(g, params: dict[str, object]) -> str:
    """foxglove_node on the graph ``g`` (``params``: its overrides, host and port); returns its log line
    with the ws:// URL once the server listens. ValueError with the node's own error when it cannot start
    (e.g. the port is taken)."""
    import re

    from cpg_walker.nodes.foxglove_view import READY

    g.start("foxglove_node", **params)
    try:
        g.wait_for_log("foxglove_node", READY, FOXGLOVE_START_S)
    except RuntimeError:
        log = g.procs["foxglove_node"].log()
        errors = [line for line in log.splitlines() if "error" in line.lower()]
        raise InputError(f"the Foxglove live view did not start: {errors[-1] if errors else log[-500:]}") \
            from None
    found = re.search(rf"{READY}.*", g.procs["foxglove_node"].log())
    return found.group(0) if found else READY


class LogTail:
    """Follows the nodes' log files and prints their new complete lines, prefixed with the node."""

    def __init__(self, out: TextIO):
        self.out = out
        self.pos: dict[Path, int] = {}
        self.partial: dict[Path, str] = {}

    def poll(self, logs: dict[str, Path], final: bool = False) -> None:
        for node, path in logs.items():
            try:
                with open(path, "rb") as f:
                    f.seek(self.pos.get(path, 0))
                    chunk = f.read()
                    self.pos[path] = f.tell()
            except OSError:
                continue
            text = self.partial.get(path, "") + chunk.decode(errors="replace")
            lines = text.split("\n")
            self.partial[path] = "" if final else lines.pop()
            for line in lines:
                if line or not final:
                    self.out.write(f"[{PREFIX.get(node, node)}] {line}\n")
        self.out.flush()


class _StopSignalError(Exception):
    pass


def _raise_stop(signum: int, _frame: object) -> None:
    raise _StopSignalError(signal.Signals(signum).name)


def banner(domain: int, how: str, spec: GraphSpec, log_dir: Path) -> str:
    target = "target_player_node (recorded gait)" if spec.player else "cpg_node"
    duration = spec.sim_value("duration")
    until = f"{duration:g} sim s" if duration else "until Ctrl-C"
    lines = [f"ROS_DOMAIN_ID={domain} ({how}); sim_node + pid_node + {target} + odom_node, "
             f"{spec.sim_value('pacing')} "
             f"pacing, {until}",
             f"node logs: {log_dir}"]
    if spec.foxglove is not None:
        lines.append("Foxglove live view: foxglove_node logs the ws:// URL to open once it listens")
    if spec.record:
        lines.append(f"recording every topic to {Path(spec.record).resolve()}/recording.mcap (complete once "
                     "the graph has stopped)")
    lines += [
             "from another shell:"]
    if not spec.player:
        lines.append(f"  ROS_DOMAIN_ID={domain} cpg-walker param set /cpg zeta 0.8")
    lines += [f"  ROS_DOMAIN_ID={domain} cpg-walker param list /sim",
              f"  ROS_DOMAIN_ID={domain} cpg-walker topic list",
              f"  ROS_DOMAIN_ID={domain} cpg-walker topic echo /joint_targets --once",
              f"  ROS_DOMAIN_ID={domain} cpg-walker topic hz /clock"]
    return "\n".join(lines)


def run_foreground(spec: GraphSpec, out: TextIO = sys.stdout) -> tuple[int, tuple | None]:
    """Run the graph until the sim ends (or a node fails, or a signal). Returns (status, fall): status 0
    when the sim ended by itself with status 0 (or a signal stopped everything), else the failing node's;
    fall: ``fall_of`` sim_node's run record."""
    from cpg_walker.graph.processes import Graph

    params = spec.node_params()
    domain, how = resolve_domain(spec.domain_id)
    log_dir = Path(spec.log_dir) if spec.log_dir else Path(tempfile.mkdtemp(prefix="cpg_walker_graph_"))
    record_path = spec.with_run_record(params, log_dir)
    record_path.unlink(missing_ok=True)
    handlers = {s: signal.signal(s, _raise_stop) for s in (signal.SIGTERM, signal.SIGHUP)}
    tail = LogTail(out)
    status = 0
    with Graph(log_dir, domain_id=domain) as g:
        try:
            print(banner(domain, how, spec, log_dir), file=out, flush=True)
            if spec.record:
                from cpg_walker.nodes.recorder_node import NAME as RECORDER_NAME
                from cpg_walker.nodes.recorder_node import READY

                g.start("recorder_node", out_dir=str(Path(spec.record).resolve()))
                g.wait_for_log("recorder_node", READY, RECORDER_START_S)
                params["sim_node"].setdefault("wait_for_subscriber", RECORDER_NAME)  # the bag from t = 0
            if "foxglove_node" in params:
                start_foxglove(g, params.pop("foxglove_node"))  # its URL line comes with the log tail
            for node, p in params.items():
                g.start(node, **p)
            logs = {name: proc.log_path for name, proc in g.procs.items()}
            while True:
                tail.poll(logs)
                ended = {n: p.popen.poll() for n, p in g.procs.items() if p.popen.poll() is not None}
                if ended:
                    name, code = next(iter(ended.items()))
                    if name == "sim_node" and code == 0:
                        print("sim_node finished; stopping the graph", file=out, flush=True)
                    else:
                        print(f"{name} exited with status {code}; stopping the graph", file=out, flush=True)
                        status = code if code else 1
                    break
                time.sleep(0.1)
        except (KeyboardInterrupt, _StopSignalError) as exc:
            what = "SIGINT" if isinstance(exc, KeyboardInterrupt) else str(exc)
            print(f"{what}: stopping the graph", file=out, flush=True)
        finally:
            handlers.setdefault(signal.SIGINT, signal.getsignal(signal.SIGINT))
            for s in handlers:  # a second Ctrl-C must not abort the clean stop (SIGKILL after 5 s)
                signal.signal(s, signal.SIG_IGN)
            codes = g.stop_all(timeout=5.0)
            tail.poll({n: p.log_path for n, p in g.procs.items()}, final=True)
            for s, h in handlers.items():
                signal.signal(s, h)
    print("stopped: " + ", ".join(f"{n} {c}" for n, c in codes.items()), file=out, flush=True)
    return status, fall_of(record_path)
