"""Start the ROS graph from Python (no ``ros2 launch`` needed): each node as a subprocess in its own
process group, on an isolated DDS domain, with its parameters file (config/<node name>.yaml, as the launch
files pass it) and overrides; stopped with SIGINT, then SIGKILL.

    with Graph(log_dir) as g:
        g.start("sim_node", pacing="lockstep", duration=5.0)
        g.start("pid_node", lockstep=True)
        g.wait("sim_node", timeout=60)

A node can be placed elsewhere (``Placement``): its command line run under a prefix (e.g. ``ip netns exec
NS``, graph/netns.py) with environment overrides (e.g. its discovery peers).

Every node writes its run statistics at exit to ``<log dir>/<node>.stats.json`` (its ``stats_file``
parameter, which ``start`` sets): ``g.stats("cpg_node")`` reads them; nothing parses the log for them.

Used by ``cpg-walker replay --graph``, ``cpg-walker walk``, ``cpg-walker two-hosts``, the benchmark and
the multi-process tests.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.nodes.interface import NODE_NAMES
from cpg_walker.nodes.params import params_file

NODES = tuple(NODE_NAMES)
#: Nodes stopped after all the others, with their own wall-s timeout: the recorder keeps listening until
#: the rest have gone quiet, then completes its bag (computing /tf takes a while on a long run).
STOP_LAST = {"recorder_node": 600.0}


#: The DDS domains ROS 2 allows (ROS_DOMAIN_ID, --domain-id).
DOMAIN_RANGE = (0, 232)


def check_domain_id(domain_id: int, origin: str = "the DDS domain") -> int:
    """``domain_id`` if it is in DOMAIN_RANGE; InputError naming ``origin`` otherwise."""
    if not DOMAIN_RANGE[0] <= domain_id <= DOMAIN_RANGE[1]:
        raise InputError(f"{origin} must be in {DOMAIN_RANGE[0]}..{DOMAIN_RANGE[1]}, got {domain_id}")
    return domain_id


def env_domain_id() -> int | None:
    """ROS_DOMAIN_ID as a domain in 0..232; None when unset or empty; InputError when anything else. Only
    ASCII digits, with ASCII white space around them, as rcl reads it: str.strip() and int() also take
    "\x1c0" or Unicode digits, which a node started with that environment would refuse (the fuzz test
    found "0\x1c" starting a whole graph in domain 0)."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip(" \t\n\r\v\f")
    if not text:
        return None
    if not (text.isascii() and text.isdigit()):
        raise InputError(f"ROS_DOMAIN_ID must be an integer in {DOMAIN_RANGE[0]}..{DOMAIN_RANGE[1]}, got "
                         f"{text!r}")
    return check_domain_id(int(text), "ROS_DOMAIN_ID")


def random_domain_id() -> int:
    """A DDS domain in 1..101 (higher ids can collide with the ephemeral port range)."""
    return random.SystemRandom().randint(1, 101)


def domain_is_quiet(domain_id: int, wait: float = 0.5) -> bool:
    """True when no other ROS node shows up on ``domain_id`` (this host) within ``wait`` seconds: two
    graphs on one domain would exchange messages (random ids in 1..101 do collide now and then when
    several test runs share a machine)."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    saved = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = rclpy.Context()
    try:
        rclpy.init(context=ctx, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("graph_domain_probe", context=ctx, start_parameter_services=False)
        end = time.monotonic() + wait
        others: list[str] = []
        while time.monotonic() < end and not others:
            time.sleep(0.05)
            others = [n for n in node.get_node_names() if n != "graph_domain_probe"]
        node.destroy_node()
        return not others
    finally:
        rclpy.try_shutdown(context=ctx)
        if saved is None:
            os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
        else:
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = saved


def quiet_domain_id(attempts: int = 5) -> int:
    """A random domain in 1..101 on which no other node is seen (the last candidate after ``attempts``)."""
    domain = random_domain_id()
    for _ in range(attempts - 1):
        if domain_is_quiet(domain):
            return domain
        domain = random_domain_id()
    return domain


def isolated_env(domain_id: int, base: dict | None = None) -> dict:
    """The environment of an isolated graph: its own domain, discovery on this host only."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated; conflicts with the range above
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    return env


def param_arg(name: str, value: object) -> str:
    """``name:=value`` in the YAML form rclpy parses with the declared type (floats keep a '.')."""
    def fmt(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, int):
            return str(v)
        if isinstance(v, list | tuple):
            return "[" + ",".join(fmt(x) for x in v) + "]"
        s = str(v)
        return s if s else "''"
    return f"{name}:={fmt(value)}"


def stats_path(log_dir: str | Path, node: str) -> Path:
    """Where ``Graph`` has ``node`` (an executable) write its run statistics: <log_dir>/<node>.stats.json."""
    return Path(log_dir) / f"{node}.stats.json"


def read_stats(path: str | Path) -> dict:
    """A node's run statistics (the JSON its ``stats_file`` names); {} when it wrote none (still running,
    killed, or it failed before its exit)."""
    import json

    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        return {}


@dataclass(frozen=True)
class Placement:
    """Where a node process runs: ``prefix`` before its command line (e.g. ``ip netns exec NS``) and
    ``env`` over the graph's environment (e.g. ROS_STATIC_PEERS)."""

    prefix: tuple[str, ...] = ()
    env: Mapping[str, str] = field(default_factory=dict)


@dataclass
class NodeProcess:
    name: str
    popen: subprocess.Popen
    log_path: Path
    started: float

    @property
    def pid(self) -> int:
        return self.popen.pid

    def cpu_seconds(self) -> float:
        """User + system CPU time the process has used so far (from /proc)."""
        try:
            fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return float("nan")
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""


class Graph:
    """A set of node processes on one isolated domain; a context manager that always stops them."""

    def __init__(self, log_dir: str | Path, domain_id: int | None = None, use_sim_time: bool = True,
                 placement: Mapping[str, Placement] | None = None):
        """``placement``: by node executable, where it runs (default: here, with the graph's env)."""
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.domain_id = quiet_domain_id() if domain_id is None else int(domain_id)
        self.env = isolated_env(self.domain_id)
        self.use_sim_time = use_sim_time
        self.placement = dict(placement or {})
        self.procs: dict[str, NodeProcess] = {}

    def command(self, node: str, params: dict, remaps: Mapping[str, str] | None = None) -> list[str]:
        """The node's command line: its parameters file (config/<node name>.yaml), then ``params`` as
        ``-p`` overrides (after the file, so they win), then ``remaps`` (topic -> topic) as ``-r``."""
        if node not in NODES:
            raise ValueError(f"unknown node {node!r}; known: {NODES}")
        args = [sys.executable, "-m", f"cpg_walker.nodes.{node}", "--ros-args",
                "--params-file", str(params_file(NODE_NAMES[node]))]
        for name, value in {"use_sim_time": self.use_sim_time, **params}.items():
            args += ["-p", param_arg(name.replace("__", "."), value)]
        for src, dst in (remaps or {}).items():
            args += ["-r", f"{src}:={dst}"]
        return args

    def start(self, node: str, remaps: Mapping[str, str] | None = None, **params: object) -> NodeProcess:
        """Start ``node`` with its parameters file and ``params`` overriding it (``push__force=[..]`` for
        ``push.force``); ``remaps``: topic names the node uses -> the ones it gets (``-r from:=to``); it
        runs where its placement says. Its run statistics go to ``stats_path(log_dir, node)`` unless
        ``stats_file`` is given (read them with ``stats``)."""
        place = self.placement.get(node, Placement())
        log_path = self.log_dir / f"{node}.log"
        if node in NODES:
            params.setdefault("stats_file", str(stats_path(self.log_dir, node).resolve()))
            Path(str(params["stats_file"])).unlink(missing_ok=True)  # a previous run's are not this one's
        with open(log_path, "wb") as log:
            popen = subprocess.Popen([*place.prefix, *self.command(node, params, remaps)],
                                     env={**self.env, **place.env}, stdout=log,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     start_new_session=True)
        proc = NodeProcess(node, popen, log_path, time.monotonic())
        self.procs[node] = proc
        return proc

    def wait(self, node: str, timeout: float) -> int:
        """Wait for ``node`` to exit by itself; raise TimeoutError (with its log tail) if it does not."""
        proc = self.procs[node]
        try:
            return proc.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise TimeoutError(f"{node} still running after {timeout} s; log tail:\n"
                               f"{proc.log()[-2000:]}") from None

    def stop(self, node: str, timeout: float = 5.0, interrupt: bool = True) -> int | None:
        """SIGINT the node's process group, then SIGKILL after ``timeout``; return its exit status."""
        proc = self.procs[node]
        p = proc.popen
        if p.poll() is None:
            if interrupt:
                _signal_group(p.pid, signal.SIGINT)
            try:
                p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                _signal_group(p.pid, signal.SIGKILL)
                p.wait(timeout=timeout)
        else:
            _signal_group(p.pid, signal.SIGKILL)  # stray children of an exited leader, if any
        return p.returncode

    def stats(self, node: str) -> dict:
        """The run statistics ``node`` wrote at exit (its stats file; {} when it wrote none)."""
        return read_stats(self.stats_file(node))

    def stats_file(self, node: str) -> Path:
        """The path ``node``'s run statistics are written to (as started)."""
        args = self.procs[node].popen.args
        for i, arg in enumerate(args[:-1]):
            if arg == "-p" and args[i + 1].startswith("stats_file:="):
                return Path(args[i + 1].split(":=", 1)[1])
        return stats_path(self.log_dir, node)

    def wait_for_log(self, node: str, text: str, timeout: float) -> None:
        """Wait until ``node``'s log holds ``text``; RuntimeError if it exits first, TimeoutError (with its
        log tail) after ``timeout`` wall s."""
        proc = self.procs[node]
        end = time.monotonic() + timeout
        while text not in proc.log():
            if proc.popen.poll() is not None:
                raise RuntimeError(f"{node} exited with status {proc.popen.returncode}; log tail:\n"
                                   f"{proc.log()[-2000:]}")
            if time.monotonic() > end:
                raise TimeoutError(f"{node} did not log {text!r} within {timeout} s; log tail:\n"
                                   f"{proc.log()[-2000:]}")
            time.sleep(0.05)

    def stop_all(self, timeout: float = 5.0) -> dict[str, int | None]:
        """Stop every node (all get SIGINT first, then each is waited for); the STOP_LAST nodes once the
        others have stopped, each with its own timeout."""
        last = [name for name in self.procs if name in STOP_LAST]
        for name, proc in self.procs.items():
            if name not in last and proc.popen.poll() is None:
                _signal_group(proc.pid, signal.SIGINT)
        codes = {name: self.stop(name, timeout, interrupt=False) for name in list(self.procs)
                 if name not in last}
        for name in last:
            codes[name] = self.stop(name, STOP_LAST[name])
        return codes

    def __enter__(self) -> Graph:
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()


def interrupt_group(popen: subprocess.Popen, timeout: float = 30.0) -> int:
    """Stop a command started in its own session (``start_new_session``) as Ctrl-C would: SIGINT to its
    process group, then SIGKILL if it has not ended within ``timeout`` s; its exit code."""
    if popen.poll() is None:
        _signal_group(popen.pid, signal.SIGINT)
        try:
            popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _signal_group(popen.pid, signal.SIGKILL)
            popen.wait()
    return popen.returncode


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass
