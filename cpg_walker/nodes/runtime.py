"""Process plumbing shared by the node executables: ``--help``, init, spin, clean exit on SIGINT/SIGTERM."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from cpg_walker.nodes.interface import NODE_NAMES, PACINGS  # noqa: F401 (also imported from here)
from cpg_walker.paths import config_path

if TYPE_CHECKING:  # rclpy itself is imported where it is used: the CLI imports PACINGS from here
    from rclpy.node import Node

#: Sim s a /clock or state stamp may lie before the newest one seen before a node takes it for a restarted
#: (reset) sim and starts its own state over (docs/ROS_INTERFACE.md, "Faults"); smaller steps back are
#: stale or re-sent messages.
CLOCK_RESET_S = 1.0


#: A stamp more than this past the newest one taken is taken only once the next confirms it (a stray
#: far-future stamp would otherwise make every real message after it look old: StampGuard).
CLOCK_JUMP_NS = 1_000_000_000


def clock_went_back(newest_ns: int | None, t_ns: int) -> bool:
    """True when ``t_ns`` lies more than CLOCK_RESET_S before ``newest_ns``: the sim has restarted."""
    return newest_ns is not None and newest_ns - t_ns > CLOCK_RESET_S * 1e9


class StampGuard:
    """Judges each stamp against the newest one taken: a jump (more than CLOCK_JUMP_NS ahead, or more
    than CLOCK_RESET_S back) is a stray until the next stamp confirms it by continuing from it within
    CLOCK_JUMP_NS (going back, the same stamp again confirms it too: a restarted lockstep sim re-sends
    its first state). One stray message (a corrupt stamp, a second publisher) neither freezes a node nor
    restarts it; a real jump (a stall, a restarted sim) is taken one message later."""

    TAKE, DROP, RESET = "take", "drop", "reset"

    def __init__(self) -> None:
        self.pending: int | None = None
        self.dropped = 0

    def judge(self, newest_ns: int | None, t_ns: int) -> str:
        """TAKE (no jump, or a confirmed one ahead), RESET (a confirmed jump back) or DROP."""
        ahead = newest_ns is not None and t_ns - newest_ns > CLOCK_JUMP_NS
        if not ahead and not clock_went_back(newest_ns, t_ns):
            self.pending = None
            return self.TAKE
        seen, self.pending = self.pending, t_ns
        if seen is not None and (0 < t_ns - seen <= CLOCK_JUMP_NS or (not ahead and t_ns == seen)):
            self.pending = None
            return self.TAKE if ahead else self.RESET
        self.dropped += 1
        return self.DROP


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


class ActivityStats:
    """CPU and wall time of a node from its first handled message to exit (excludes start-up imports)."""

    def __init__(self) -> None:
        self.count = 0
        self.cpu0 = self.wall0 = 0.0

    def tick(self) -> None:
        import time

        if self.count == 0:
            self.cpu0, self.wall0 = time.process_time(), time.monotonic()
        self.count += 1

    def summary(self) -> dict:
        import time

        if self.count == 0:
            return {"messages": 0}
        cpu, wall = time.process_time() - self.cpu0, time.monotonic() - self.wall0
        return {"messages": self.count, "active_wall_s": round(wall, 3), "active_cpu_s": round(cpu, 3),
                "cpu_fraction": round(cpu / wall, 3) if wall > 0 else None}


class TickStats:
    """Wall-clock timing of a node's ticks (one per new ``/clock`` sample): the period between consecutive
    ticks against the nominal one (the sim-time step between them, i.e. the wall period at real-time
    factor 1), the work time per tick, and overruns (work longer than the nominal period). Keeps the
    last ``window`` ticks (bounded memory); the summary is over them."""

    def __init__(self, window: int = 200_000) -> None:
        from collections import deque

        self.period_s: deque[float] = deque(maxlen=window)
        self.nominal_s: deque[float] = deque(maxlen=window)
        self.work_s: deque[float] = deque(maxlen=window)
        self.ticks = 0
        self.repeats = 0
        self.overruns = 0
        self._last: tuple[float, int] | None = None  # (wall start, sim ns) of the previous tick

    def tick(self, wall_start: float, sim_ns: int, work_s: float) -> None:
        """A tick at sim time ``sim_ns`` began at ``wall_start`` (perf_counter) and took ``work_s``."""
        if self._last is not None and sim_ns <= self._last[1]:
            self.repeats += 1  # a re-sent (or old) clock sample: not a new tick of the loop
            return
        self.ticks += 1
        if self._last is not None:
            nominal = (sim_ns - self._last[1]) / 1e9
            self.period_s.append(wall_start - self._last[0])
            self.nominal_s.append(nominal)
            if work_s > nominal:
                self.overruns += 1
        self.work_s.append(work_s)
        self._last = (wall_start, sim_ns)

    def summary(self) -> dict:
        """Milliseconds: wall period (and the nominal one), jitter = period - nominal, work per tick
        (mean/std/p50/p99/max each; jitter also p50/p99/max of its magnitude); counts."""
        import numpy as np

        def stats(a) -> dict:
            a = np.asarray(a) * 1e3
            return {"mean": round(float(a.mean()), 4), "std": round(float(a.std()), 4),
                    "p50": round(float(np.median(a)), 4), "p99": round(float(np.percentile(a, 99)), 4),
                    "max": round(float(a.max()), 4)}

        out: dict = {"ticks": self.ticks, "repeated_clock": self.repeats, "overruns": self.overruns}
        if self.work_s:
            out["work_ms"] = stats(self.work_s)
        if self.period_s:
            period, nominal = np.asarray(self.period_s), np.asarray(self.nominal_s)
            out["period_ms"] = {"nominal": round(float(np.median(nominal)) * 1e3, 4), **stats(period),
                                "count": int(period.size)}
            jitter = period - nominal
            absj = stats(np.abs(jitter))
            out["jitter_ms"] = {**stats(jitter), "abs_p50": absj["p50"], "abs_p99": absj["p99"],
                                "abs_max": absj["max"]}
        return out


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
    from cpg_walker.nodes.params import SCHEDULING, declare_params

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


def run_main(argv: list[str], make_node: Callable, loop: Callable | None = None) -> int:
    """rclpy.init, build the node, then ``loop(node)`` (default: spin) until Ctrl-C/SIGTERM/shutdown;
    destroy the node and shut down without a traceback. Returns the exit status."""
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

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


def _typed(description: str, ptype: int, read_only: bool) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=read_only, type=ptype)


def float_param(description: str, lo: float | None = None, hi: float | None = None,
                read_only: bool = False) -> ParameterDescriptor:
    """A double parameter, in [lo, hi] when both are given."""
    d = _typed(description, ParameterType.PARAMETER_DOUBLE, read_only)
    if lo is not None and hi is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return d


def int_param(description: str, lo: int, hi: int, read_only: bool = False) -> ParameterDescriptor:
    """An integer parameter in [lo, hi]."""
    d = _typed(description, ParameterType.PARAMETER_INTEGER, read_only)
    d.integer_range = [IntegerRange(from_value=lo, to_value=hi, step=1)]
    return d


def bool_param(description: str, read_only: bool = False) -> ParameterDescriptor:
    return _typed(description, ParameterType.PARAMETER_BOOL, read_only)


def str_param(description: str, read_only: bool = False) -> ParameterDescriptor:
    return _typed(description, ParameterType.PARAMETER_STRING, read_only)


def floats_param(description: str, read_only: bool = False) -> ParameterDescriptor:
    return _typed(description, ParameterType.PARAMETER_DOUBLE_ARRAY, read_only)


def strs_param(description: str, read_only: bool = False) -> ParameterDescriptor:
    return _typed(description, ParameterType.PARAMETER_STRING_ARRAY, read_only)


def declare(node: Node, name: str, descriptor: ParameterDescriptor) -> object:
    """Declare ``name`` with the descriptor's type and return its value. The value has one home, the
    node's parameters file config/<node name>.yaml: passed with ``--params-file`` (or a ``-p`` override),
    or, when the node was started without a value for it (a bare ``ros2 run``), read from the packaged
    copy of that file. No value in either: a ValueError naming the parameter and the file."""
    from rclpy.exceptions import ParameterUninitializedException
    from rclpy.parameter import Parameter

    name_refusals(node)
    packaged = packaged_parameters(node)
    if name in packaged and name not in node._parameter_overrides:
        node.declare_parameter(name, packaged[name], descriptor)
        if not getattr(node, "_packaged_params_logged", False):
            node._packaged_params_logged = True
            node.get_logger().info(f"parameters not given on the command line are read from "
                                   f"{params_file(node.get_name())}")
    else:
        node.declare_parameter(name, Parameter.Type(descriptor.type), descriptor)
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        raise ValueError(f"parameter {name!r} of /{node.get_name()} has no value: start the node with "
                         f"--ros-args --params-file {params_file(node.get_name())}") from None


def name_refusals(node: Node) -> None:
    """Make every refused parameter change say which parameter it refused: rclpy's own checks answer a
    wrong type ("Wrong parameter type, expected ...") or an undeclare without the name, so a client setting
    several at once could not tell which. Wraps the node's ``set_parameters_atomically`` (what the
    set_parameters services call), once; reasons that already name the parameter are kept as they are."""
    if getattr(node, "_refusals_named", False):
        return
    node._refusals_named = True
    plain = node.set_parameters_atomically

    def set_parameters_atomically(parameters):
        result = plain(parameters)
        if not result.successful:
            names = [p.name for p in parameters if p.name not in result.reason]
            if len(names) == len(parameters):  # none named yet
                result.reason = f"{', '.join(names)}: {result.reason or 'refused'}"
        return result

    node.set_parameters_atomically = set_parameters_atomically


def packaged_parameters(node: Node) -> dict:
    """The ros__parameters of the node's packaged parameters file (empty if there is none), cached."""
    cached = getattr(node, "_packaged_params", None)
    if cached is None:
        from cpg_walker.paths import ros_parameters

        try:
            cached = ros_parameters(params_file(node.get_name()), node.get_name())
        except FileNotFoundError:
            cached = {}
        node._packaged_params = cached
    return cached


def params_file(node_name: str) -> Path:
    """The parameters file of the node named ``node_name``: config/<node_name>.yaml (in the package's share
    directory); FileNotFoundError if there is none."""
    return config_path(f"{node_name}.yaml")


def override_names(node: Node, prefix: str) -> list[str]:
    """Names under ``prefix`` (``kp.``) the node was started with (params file or ``-p``): for parameter
    sets that are open-ended (pid_node's per-joint gains). rclpy keeps the start-up overrides in
    ``Node._parameter_overrides`` and, unlike rclcpp (``NodeOptions::parameter_overrides``), has no public
    accessor."""
    return sorted(n for n in node._parameter_overrides if n.startswith(prefix))


def latency_summary(samples_s: list[float]) -> dict:
    """p50/p99/max of latencies (s) in milliseconds, with the count."""
    if not samples_s:
        return {"count": 0}
    import numpy as np

    a = np.asarray(samples_s) * 1e3
    return {"count": int(a.size), "p50_ms": round(float(np.percentile(a, 50)), 4),
            "p99_ms": round(float(np.percentile(a, 99)), 4), "max_ms": round(float(a.max()), 4)}
