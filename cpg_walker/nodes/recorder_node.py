"""recorder_node: records every topic of the graph to one rosbag2 MCAP (``ros2 run cpg_walker recorder_node``;
``cpg-walker walk --record``, ``cpg-walker graph --record DIR`` and ``cpg-walker record`` start it).

It only listens. Every ``scan_period`` wall seconds it lists the graph's topics and subscribes to each new
one that has a publisher, with the publishers' QoS (reliable and transient local when all of them are:
the latched /sim/fallen and /robot_description arrive even when published before), taking the messages
serialized (``raw``: no deserialization, no re-encoding) straight from rcl like the control nodes' hot
path; recording.BagRecorder writes them (its doc: bag time = sim time) and, when the recorder stops
(SIGINT/SIGTERM, or ``duration``), adds /tf and /tf_static from the simulation's exact poses and
completes the file. The bag's two files land in ``out_dir`` only then; a killed recorder leaves none.
"""

from __future__ import annotations

import json
import signal
import time
from functools import partial
from pathlib import Path

from rclpy.node import Node

from cpg_walker.errors import ToolError
from cpg_walker.nodes import specs
from cpg_walker.nodes.interface import NODE_NAMES, RECORDER_NODE, matching_qos
from cpg_walker.nodes.messages import message_class
from cpg_walker.nodes.params import declare_params
from cpg_walker.nodes.recording import CLOCK_TOPIC, BagRecorder
from cpg_walker.nodes.runtime import (
    HotPath,
    exit_log,
    exit_stats,
    gc_summary,
    parse_cli,
    scheduling_request,
    settle_process,
    spin_once_guarded,
)

#: The node's name (sim_node's ``wait_for_subscriber`` names it when a graph is recorded).
NAME = NODE_NAMES[RECORDER_NODE]

#: Log line that says the recorder is subscribed to the graph's topics (Graph.start waits for it).
READY = "recording to"


#: A QoS that receives from every publisher in ``infos`` (their TopicEndpointInfo): interface.matching_qos.
subscription_qos = matching_qos


class RecorderNode(Node):
    """Subscribes to the graph's topics as they appear and hands their messages to a BagRecorder."""

    def __init__(self, **node_options) -> None:
        super().__init__(NAME, **node_options)
        v = declare_params(self, specs.RECORDER)
        out_dir = str(v["out_dir"])
        self.scan_period = float(v["scan_period"])
        self.depth = int(v["queue_depth"])
        self.duration_ns = round(float(v["duration"]) * 1e9)
        self.scheduling = scheduling_request(v)  # applied once started (runtime.settle_process)
        sim_time = bool(self.get_parameter("use_sim_time").value)
        out = Path(out_dir) if out_dir else Path.cwd() / time.strftime("recording_%Y_%m_%d-%H_%M_%S",
                                                                          time.gmtime())
        self.bag = BagRecorder(out, sim_time=sim_time)
        self.subs: dict[str, object] = {}
        self.skipped: dict[str, str] = {}
        self.hot = HotPath(self, [])
        self.longest_gap_s = 0.0  # wall s between two polls of the subscriptions (a stall: CPU, GC)
        self.scan()
        self.get_logger().info(f"{READY} {out} ({'sim' if sim_time else 'wall-clock'} time); topics: "
                               f"{', '.join(sorted(self.subs)) or 'none yet'}")

    def scan(self) -> None:
        """Subscribe to every topic that has a publisher and is not recorded yet."""
        added = False
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subs or topic in self.skipped:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue  # subscribers only so far: its QoS and type are the publishers' to say
            reason = None
            if len(types) != 1:
                reason = f"{len(types)} types ({', '.join(types)})"
            else:
                try:
                    cls = message_class(types[0])
                except ToolError as exc:
                    reason = str(exc)
            if reason is None:
                from cpg_walker.nodes.recording import qos_of

                reason = self.bag.add_topic(topic, types[0], [qos_of(i.qos_profile) for i in infos])
            if reason is not None:
                self.skipped[topic] = reason
                self.get_logger().warn(f"not recording {topic}: {reason}")
                continue
            self.subs[topic] = self.create_subscription(
                cls, topic, partial(self._on_message, topic), subscription_qos(infos, self.depth), raw=True)
            added = True
        if added:
            self.hot = HotPath(self, list(self.subs.values()))

    def _on_message(self, topic: str, data: bytes) -> None:
        if self.bag.write(topic, data) and self.duration_ns and self.bag.until_ns is None:
            if not self.bag.sim_time:
                self.bag.until_ns = time.time_ns() + self.duration_ns
            elif topic == CLOCK_TOPIC:
                self.bag.until_ns = self.bag.clock_ns + self.duration_ns

    def done(self) -> bool:
        """``duration`` of bag time recorded (from the first /clock, or the first message without sim
        time)."""
        until = self.bag.until_ns
        return until is not None and (self.bag.clock_ns if self.bag.sim_time else time.time_ns()) >= until

    def on_exit(self) -> None:
        _normal_scheduling()  # completing the bag (the /tf computation) needs no priority
        t0 = time.monotonic()
        path = self.bag.close()
        exit_log(self, f"wrote {path}: " + json.dumps(self.bag.counts(), sort_keys=True))
        exit_stats(self, {"close_s": round(time.monotonic() - t0, 3), "bag": str(path),
                          "counts": self.bag.counts(), "longest_gap_ms": round(self.longest_gap_s * 1e3, 3),
                          "gc": gc_summary(self)})


def _normal_scheduling() -> None:
    """Back to normal scheduling (SCHED_OTHER) for every thread of this process, where it was raised."""
    import os

    from cpg_walker.nodes.runtime import _thread_ids

    for tid, _ in _thread_ids():
        try:
            if os.sched_getscheduler(tid) != os.SCHED_OTHER:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        except (OSError, AttributeError):
            pass


def spin_recorder(node: RecorderNode, stopping: list[bool]) -> None:
    """Take messages until ``stopping[0]`` (a signal) or ``node.done()``, then what is still queued or on
    its way (until nothing arrived for 0.3 wall s, at most 2 s: a graph stopped first has sent all by
    then); scan for topics every ``scan_period``."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    next_slow = next_scan = 0.0
    last = time.monotonic()
    while not stopping[0] and not node.done() and node.context.ok():
        if node.subs:
            node.hot.poll(0.005)
        else:
            time.sleep(0.005)
        now = time.monotonic()
        node.longest_gap_s = max(node.longest_gap_s, now - last)
        last = now
        if now >= next_slow:
            spin_once_guarded(node, executor, 0.0)
            next_slow = now + 0.02
        if now >= next_scan:
            node.scan()
            next_scan = now + node.scan_period
    end = time.monotonic() + 2.0
    quiet_since = time.monotonic()
    while node.context.ok() and time.monotonic() < end and time.monotonic() - quiet_since < 0.3:
        if node.hot.poll(0.02) if node.subs else 0:
            quiet_since = time.monotonic()
    executor.remove_node(node)


def main(argv: list[str] | None = None) -> int:
    import sys

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    argv = parse_cli("recorder_node", "Records every topic of the graph to a rosbag2 MCAP.",
                     specs.node_help(RECORDER_NODE), argv)
    stopping = [False]

    def stop(_signum: int, _frame: object) -> None:
        stopping[0] = True

    # our own handlers, not rclpy's: a signal ends the recording, the context stays up for the drain
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, stop)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    status = 0
    try:
        node = RecorderNode()
        settle_process(node)  # gc.freeze of the start-up objects, GC pauses counted, OS scheduling
        spin_recorder(node, stopping)
    except ValueError as exc:
        print(f"{argv[0]}: error: {exc}", file=sys.stderr)
        status = 2
    finally:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN)  # a second Ctrl-C must not cut the bag short
        if node is not None:
            node.on_exit()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    raise SystemExit(main())
