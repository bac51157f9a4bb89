"""Helpers of the multi-process ROS tests: the wall-clock deadlines, a DDS domain reserved for one test, a
probe node in the test process (waits for conditions, parameter calls through the real parameter services)
and a watchdog that ends a graph whose sim time stops advancing. The fixtures built on them are in
conftest.py.

Timing rule of these tests: a wall-clock deadline only ends a test that hangs (a process that never
starts, a message that never comes, a sim that stops advancing); it is never a claim about speed. Rates
are asserted in sim time, from the messages' stamps; wall-clock rates and durations are measured by the
benchmark (``cpg-walker bench``, experiments/bench_graph.py)."""

from __future__ import annotations

import fcntl
import os
import random
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO

from cpg_walker.graph import probe
from cpg_walker.nodes import interface as ifc

#: Wall s for node processes to start and be discovered (imports, numba, DDS discovery): took up to ~25 s
#: on the 2-core machine with two suites and other jobs running beside (see README, "Tests under load").
START_S = 180.0
#: Wall s for one thing to follow once the graph is up: a service answer, a log line, a message.
ANSWER_S = 90.0
#: The slowest sim a test waits for without calling it a hang: 1/20 of real time (lockstep graphs ran at
#: ~0.3-1x real time on that loaded machine).
MIN_REAL_TIME_FACTOR = 0.05


def sim_deadline(sim_s: float) -> float:
    """Wall s to allow a graph for ``sim_s`` sim seconds, start-up included (a hang guard, see above)."""
    return START_S + sim_s / MIN_REAL_TIME_FACTOR


# ------------------------------------------------------------------------------------- DDS domain

LOCK_DIR = Path(tempfile.gettempdir()) / "cpg_walker_test_domains"


def reserve_domain() -> tuple[int, IO]:
    """A DDS domain in 1..101 held by this process alone (an exclusive ``flock`` on its lock file, released
    when the returned file is closed or the process dies) on which no other node is seen: two test runs
    on one machine never share a domain, whatever their timing."""
    from cpg_walker.graph.processes import domain_is_quiet

    LOCK_DIR.mkdir(exist_ok=True)
    candidates = list(range(1, 102))
    random.SystemRandom().shuffle(candidates)
    for domain in candidates:
        lock = open(LOCK_DIR / f"{domain}.lock", "w")  # held until the test ends
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        if domain_is_quiet(domain, wait=1.0):
            return domain, lock
        lock.close()
    raise RuntimeError(f"no free DDS domain in 1..101 (locks in {LOCK_DIR})")


def node_pids(domain: int) -> list[int]:
    """Node processes (python -m cpg_walker.nodes.*) of this test run on ``domain``: same interpreter and
    PYTHONPATH as this process, ROS_DOMAIN_ID=domain (read from /proc)."""
    want_env = f"ROS_DOMAIN_ID={domain}".encode()
    path = os.environ.get("PYTHONPATH")
    want_path = None if path is None else f"PYTHONPATH={path}".encode()
    pids = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
            env = (proc / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if len(cmd) < 3 or not cmd[2].startswith(b"cpg_walker.nodes.") or want_env not in env:
            continue
        paths = [e for e in env if e.startswith(b"PYTHONPATH=")]
        if cmd[0] == sys.executable.encode() and paths == ([] if want_path is None else [want_path]):
            pids.append(int(proc.name))
    return pids


def kill_nodes(domain: int) -> list[int]:
    """SIGKILL this run's node processes on ``domain``; their pids."""
    pids = node_pids(domain)
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return pids


# ------------------------------------------------------------------------------------------ probe

class Probe(probe.Probe):
    """The package's probe (cpg_walker/graph/probe.py) named ``probe``, with these tests' deadlines; a
    wait that runs out is an AssertionError."""

    Timeout = AssertionError

    def __init__(self, domain_id: int, name: str = "probe", **options):
        super().__init__(domain_id, name, **options)

    def wait(self, until: Callable[[], bool], what: str | Callable[[], str], timeout: float = ANSWER_S,
             each: Callable[[], None] | None = None) -> None:
        super().wait(until, what, timeout, each)

    def wait_endpoints(self, topic: str, publishers: int = 1, subscribers: int = 1,
                       timeout: float = START_S) -> None:
        """Before a sim starts its clock: a node publishes each tick's message once, so an endpoint pair
        still being matched when the first tick comes would lose it."""
        super().wait_endpoints(topic, publishers, subscribers, timeout)

    def call(self, srv_type, name: str, timeout: float = ANSWER_S):
        return super().call(srv_type, name, timeout)

    def set_param(self, node: str, name: str, value, timeout: float = START_S):
        return super().set_param(node, name, value, timeout, ANSWER_S)

    def get_params(self, node: str, names: list[str]) -> list:
        return super().get_params(node, names, START_S)


double, string = probe.double, probe.string


# --------------------------------------------------------------------------------------- watchdog

class SimWatchdog:
    """Ends a graph run that has hung, however slowly it is allowed to go: a thread listens to
    /diagnostics on ``domain`` (the sim and cpg_node publish them only as sim time advances) and, when
    nothing comes for ``stall_s`` wall s, SIGKILLs this run's nodes on the domain, which makes the
    blocked run fail; leaving the ``with`` block then raises AssertionError naming the stall.

        with SimWatchdog(domain):
            run_graph_walk(out, duration=60.0, timeout=sim_deadline(60.0))
    """

    def __init__(self, domain: int, stall_s: float = START_S):
        self.domain, self.stall_s = domain, stall_s
        self.messages = 0
        self.sim_time = 0.0
        self.fired: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-watchdog", daemon=True)

    def _run(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        from cpg_walker.nodes.messages import stamp_ns

        probe = Probe(self.domain)
        try:
            def seen(msg) -> None:
                self.messages += 1
                self.sim_time = stamp_ns(msg) / 1e9

            probe.node.create_subscription(DiagnosticArray, ifc.DIAGNOSTICS, seen, 10)
            last, count = time.monotonic(), -1
            while not self._stop.is_set():
                probe.executor.spin_once(timeout_sec=0.1)
                if self.messages != count:
                    last, count = time.monotonic(), self.messages
                elif time.monotonic() - last > self.stall_s:
                    self.fired = (f"no sim progress (/diagnostics) for {self.stall_s:g} wall s; last sim "
                                  f"time {self.sim_time:.3f} s after {self.messages} messages; killed "
                                  f"nodes {kill_nodes(self.domain)}")
                    return
        finally:
            probe.close()

    def __enter__(self) -> SimWatchdog:
        self._thread.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._stop.set()
        self._thread.join(timeout=ANSWER_S)
        if self.fired:
            raise AssertionError(self.fired) from exc
