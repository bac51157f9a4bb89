"""Process plumbing shared by the node executables: ``--help``, init, spin, clean exit on SIGINT/SIGTERM."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

from cpg_walker.nodes.interface import NODE_NAMES
from cpg_walker.nodes.params import SCHEDULING, declare_params

if TYPE_CHECKING:  # rclpy itself is imported where it is used
    from rclpy.node import Node



def parse_cli(prog: str, description: str, interface: str, argv: list[str] | None = None) -> list[str]:
    """Handle ``--help`` (prints ``interface``) over the non-ROS arguments; return argv for rclpy.init."""
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv if argv is None else argv)
    name = NODE_NAMES.get(prog, prog)
    files = (f"parameter values: config/{name}.yaml, the packaged one unless --params-file gives another; "
             "-p name:=value overrides one")
    parser = argparse.ArgumentParser(
        prog=prog, description=description, epilog=f"{interface}\n{files}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        usage=f"{prog} [--help] [--ros-args [--params-file FILE] [-p name:=value ...]]",
    )
    parser.parse_args(remove_ros_args(argv)[1:])
    return argv


class Throttle:
    """Warnings throttled per reason (rclpy's throttle is per call site, so one reason would hide the
    others): ``warn(node, key, text)`` logs at most once per ``period`` wall seconds for each key."""

    def __init__(self, period: float = 1.0) -> None:
        self.period = period
        self.last: dict[str, float] = {}
        self.suppressed: dict[str, int] = {}

    def warn(self, node, key: str, text: str) -> None:
        import time

        now = time.monotonic()
        if now - self.last.get(key, -1e9) < self.period:
            self.suppressed[key] = self.suppressed.get(key, 0) + 1
            return
        n = self.suppressed.pop(key, 0)
        self.last[key] = now
        node.get_logger().warn(text + (f" ({n} more since the last warning)" if n else ""))


def exit_log(node, text: str) -> None:
    """Log at exit: through the node's logger while its context is up, else on stderr (after SIGINT
    rclpy has already shut the context down, and /rosout can no longer be published)."""
    if node.context.ok():
        node.get_logger().info(text)
    else:
        print(f"[INFO] [{node.get_name()}]: {text}", file=sys.stderr, flush=True)


def exit_stats(node, stats: dict, text: str | None = None) -> None:
    """The node's run statistics at exit: written as JSON to the path of its ``stats_file`` parameter
    (params.STATS; '' = none), which is what the graph tooling reads (graph/processes.py ``Graph.stats``),
    and logged for people as ``text`` (default ``stats {...}``; nothing parses that line)."""
    import json

    path = node.get_parameter("stats_file").value if node.has_parameter("stats_file") else ""
    if path:
        try:
            write_json_atomic(path, stats)
        except OSError as exc:
            exit_log(node, f"could not write the run statistics to {path}: {exc}")
    exit_log(node, text if text is not None else "stats " + json.dumps(stats))


def write_json_atomic(path, data: dict) -> None:
    """``data`` as JSON at ``path``, atomically: a temporary file in the same directory renamed over it
    (a reader sees the whole file or none)."""
    import json
    import os
    import tempfile

    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".stats-", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(data, fh, indent=1)
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


class GcPauses:
    """Python's cyclic garbage collector as seen from a control loop: collections per generation and how
    long they held the interpreter (a collection stops every thread's Python code). ``install`` hooks
    ``gc.callbacks`` (two clock reads per collection); ``summary`` in milliseconds."""

    def __init__(self) -> None:
        self.count = [0, 0, 0]
        self.total_s = 0.0
        self.max_s = 0.0
        self._t0 = 0.0

    def install(self) -> GcPauses:
        import gc

        gc.callbacks.append(self._callback)
        return self

    def _callback(self, phase: str, info: dict) -> None:
        import time

        if phase == "start":
            self._t0 = time.perf_counter()
            return
        dt = time.perf_counter() - self._t0
        self.count[info["generation"]] += 1
        self.total_s += dt
        self.max_s = max(self.max_s, dt)

    def summary(self) -> dict:
        import gc

        return {"collections": list(self.count), "total_ms": round(self.total_s * 1e3, 3),
                "max_ms": round(self.max_s * 1e3, 3), "frozen_objects": gc.get_freeze_count()}


def declare_scheduling(node: Node) -> dict:
    """Declare the OS scheduling parameters of a control node (values in its parameters file; specs:
    params.SCHEDULING): ``realtime_priority`` (SCHED_FIFO priority 1-99; 0 = none), ``nice`` (used when no
    real-time priority is set or allowed; 0 = leave) and ``cpu_affinity`` (a taskset-style bit mask; 0 =
    any CPU). Returns them as ``scheduling_request`` does; ``apply_scheduling`` acts on them once the node
    has started."""
    return scheduling_request(declare_params(node, SCHEDULING))


def scheduling_request(values: dict) -> dict:
    """The scheduling parameters among declared ``values`` as ``apply_scheduling`` takes them (the mask as
    CPU numbers)."""
    return {"realtime_priority": int(values["realtime_priority"]), "nice": int(values["nice"]),
            "cpu_affinity": cpus_of_mask(int(values["cpu_affinity"]))}


def cpus_of_mask(mask: int) -> list[int]:
    """CPU numbers of a taskset-style bit mask (0 = none given: any CPU)."""
    return [i for i in range(mask.bit_length()) if mask >> i & 1]


def _thread_ids() -> list[tuple[int, str]]:
    """(thread id, name) of this process's threads (Linux /proc)."""
    import os

    out = []
    for entry in os.scandir("/proc/self/task"):
        try:
            with open(f"{entry.path}/comm") as fh:
                out.append((int(entry.name), fh.read().strip()))
        except OSError:
            continue  # the thread has exited
    return out


def gc_summary(node: Node) -> dict | None:
    """The node's garbage-collection pauses since ``settle_process`` (None if it was not settled)."""
    pauses = getattr(node, "gc_pauses", None)
    return pauses.summary() if pauses is not None else None


def apply_scheduling(node: Node, request: dict) -> str:
    """Give the running node the OS's help the request asks for, as far as it is permitted; log one info
    line saying what is in effect, and return it. Threads: the node's loop (the main thread) and the
    middleware's (DDS receive, event and discovery threads, named by the middleware); unnamed worker pools
    (BLAS, numba) keep normal scheduling, so a spinning worker can never starve the machine. The affinity
    applies to every thread. Where something is not permitted (no root / CAP_SYS_NICE, not Linux) the node
    runs on with normal scheduling."""
    import os

    try:
        threads = _thread_ids()
    except OSError:
        threads = []
    main_name = next((name for tid, name in threads if tid == os.getpid()), None)
    hot = [tid for tid, name in threads if tid == os.getpid() or name != main_name]
    done: list[str] = []
    skipped: list[str] = []
    prio, nice, cpus = request["realtime_priority"], request["nice"], request["cpu_affinity"]
    if prio > 0:
        try:
            for tid in hot:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(prio))
            done.append(f"SCHED_FIFO priority {prio} on {len(hot)} threads")
        except (OSError, AttributeError) as exc:
            skipped.append(f"SCHED_FIFO not permitted ({exc.__class__.__name__})")
            prio = 0
    if prio == 0 and nice != 0:
        try:
            for tid in hot:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
            done.append(f"nice {nice} on {len(hot)} threads")
        except (OSError, AttributeError) as exc:
            skipped.append(f"nice {nice} not permitted ({exc.__class__.__name__})")
    if cpus:
        try:
            for tid, _ in threads or [(0, "")]:
                os.sched_setaffinity(tid, cpus)
            done.append(f"CPUs {','.join(map(str, cpus))}")
        except (OSError, AttributeError) as exc:
            skipped.append(f"CPU affinity {cpus} not applied ({exc.__class__.__name__})")
    text = "scheduling: " + ("; ".join(done) if done else "normal")
    if skipped:
        text += " (" + "; ".join(skipped) + ")"
    node.get_logger().info(text)
    return text


def settle_process(node: Node) -> None:
    """After a control node's start-up: move every object allocated so far (modules, the learned CPG,
    message types: ~150k objects) into the collector's permanent generation (``gc.freeze``), so a full
    collection mid-walk does not traverse them; then the OS scheduling of ``node.scheduling`` (if any)."""
    import gc

    gc.collect()
    gc.freeze()
    node.gc_pauses = GcPauses().install()
    request = getattr(node, "scheduling", None)
    if request is not None:
        apply_scheduling(node, request)


class HotPath:
    """Take messages of a few subscriptions straight from rcl, bypassing the executor.

    rclpy's executor rebuilds its wait set and generator on every ``spin_once`` (~140-200 us here even
    when idle), which dominates a 500 Hz loop. This keeps one wait set over the hot subscriptions only and
    calls their callbacks in this thread; everything else (parameters, services, /clock of use_sim_time)
    is left to an executor spun now and then. The subscriptions are ordinary ones (they appear in the
    graph); if the executor happens to take one of their messages it calls the same callback."""

    def __init__(self, node, subscriptions: list) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        self.subs = list(subscriptions)
        self.context = node.context
        self.wait_set = _rclpy.WaitSet(len(self.subs), 0, 0, 0, 0, 0, node.context.handle)

    def drain(self) -> int:
        """Run the callback of every message already waiting; return how many."""
        n = 0
        for sub in self.subs:
            while True:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    break
                sub.callback(taken[0])
                n += 1
        return n

    def poll(self, timeout_s: float = 0.0) -> int:
        """Drain; if nothing was waiting, block up to ``timeout_s`` for a message and drain again."""
        try:
            n = self.drain()
            if n or timeout_s <= 0:
                return n
            ws = self.wait_set
            ws.clear_entities()
            for sub in self.subs:
                ws.add_subscription(sub.handle)
            ws.wait(int(timeout_s * 1e9))
            return self.drain()
        except Exception:
            if self.context.ok():
                raise
            return 0  # SIGINT/SIGTERM shut the context down while we were waiting: the caller stops


#: Errors rclpy's own callbacks raise on a malformed message (its use_sim_time TimeSource: a /clock stamp
#: before 0 -> "Seconds value must not be negative"; a huge one -> OverflowError), which would otherwise end
#: the node's spin: dropped with a throttled warning.
RCLPY_MESSAGE_ERRORS = (ValueError, OverflowError)
_rclpy_throttle = Throttle(1.0)


def spin_once_guarded(node, executor, timeout_sec: float) -> None:
    """``executor.spin_once``; a message rclpy itself cannot take (RCLPY_MESSAGE_ERRORS) is dropped with a
    throttled warning instead of stopping the node (the node's own callbacks validate what they take)."""
    try:
        executor.spin_once(timeout_sec=timeout_sec)
    except RCLPY_MESSAGE_ERRORS as exc:
        _rclpy_throttle.warn(node, type(exc).__name__, f"dropped a message rclpy could not take: {exc}")


def spin_hot(node, hot: HotPath, executor_period: float = 0.02, idle=None) -> None:
    """Serve ``hot`` continuously, the rest of the node through an executor every ``executor_period`` wall
    seconds; ``idle()`` (if given) runs at that rate too."""
    import time

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    next_slow = 0.0
    while rclpy.ok():
        hot.poll(0.005)
        now = time.monotonic()
        if now >= next_slow:
            spin_once_guarded(node, executor, 0.0)
            if idle is not None:
                idle()
            next_slow = now + executor_period


def _stop_without_raising() -> None:
    """Ctrl-C without KeyboardInterrupt. rclpy's SIGINT handler (installed by ``rclpy.init``) shuts the
    context down, which ends every loop of ours (they run ``while rclpy.ok()``), and then calls the
    handler Python had. Python's default raises KeyboardInterrupt in whatever code runs next: a garbage
    collector callback, a message's conversion, a ``__del__``, where it cannot be caught and prints a
    traceback. This one raises only before rclpy's is in place (nothing else would stop the process)."""
    import signal

    from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options

    rclpy_handles_it = (SignalHandlerOptions.ALL, SignalHandlerOptions.SIGINT)

    def on_sigint(signum, frame) -> None:
        if get_current_signal_handlers_options() not in rclpy_handles_it:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)


def run_main(argv: list[str], make_node: Callable, loop: Callable | None = None) -> int:
    """rclpy.init, build the node, then ``loop(node)`` (default: spin) until Ctrl-C/SIGTERM/shutdown;
    destroy the node and shut down without a traceback. Returns the exit status."""
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    _stop_without_raising()
    rclpy.init(args=argv)
    node = None
    status = 0
    try:
        node = make_node()
        settle_process(node)
        if loop is not None:
            loop(node)
        elif getattr(node, "hot", None) is not None:
            spin_hot(node, node.hot, idle=getattr(node, "idle", None))
        else:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            while rclpy.ok():
                spin_once_guarded(node, executor, 0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, InvalidParameterValueException, InvalidParameterTypeException) as exc:
        print(f"{argv[0]}: error: {exc}", file=sys.stderr)  # bad parameters at start-up: one line
        status = 2
    except Exception:
        # a signal arriving mid-call (publish, wait, a message's conversion: "Unable to convert call
        # argument" was seen on a SIGINT) is a normal stop: rclpy's handler shuts the context down
        import time

        give_up = time.monotonic() + 1.0
        while rclpy.ok() and time.monotonic() < give_up:
            time.sleep(0.01)
        if rclpy.ok():
            raise
    finally:
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not interrupt the clean-up
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            on_exit = getattr(node, "on_exit", None)
            if on_exit is not None:
                on_exit()
            node.destroy_node()
        from rclpy._rclpy_pybind11 import RCLError

        try:
            rclpy.try_shutdown()
        except RCLError:  # rclpy's signal handler shut the context down in between (seen on SIGINT)
            pass
    return status
