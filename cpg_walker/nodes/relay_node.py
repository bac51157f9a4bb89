"""relay_node: a degraded link between remapped topics, for fault injection (``ros2 run cpg_walker
relay_node``; ``cpg-walker transport`` and test/test_ros_transport.py start it).

For each topic of ``topics`` (type from ``types``) it takes the messages serialized (``raw``: no
deserialization) and republishes them on ``prefix`` + topic (``/joint_states`` -> ``/net/joint_states``),
dropping a fraction ``loss`` (seeded) and delaying each by ``delay`` + U(0, ``jitter``) wall seconds, order
kept (nodes/lossy_link.py). The consumers subscribe to the relay's outputs through remaps (``CONSUMERS``,
``consumer_remaps``: pid_node's /joint_targets and /joint_states, cpg_node's /imu); the publishers are
untouched. ``loss``, ``delay`` and ``jitter`` are settable at run time; invalid values are refused with the
reason. The run statistics at exit (the ``stats_file`` parameter's JSON) hold, per topic, the counters
and the measured delay; while messages flow, /diagnostics says the same every ``diagnostics_period``
wall seconds.

The delay is wall-clock time: meaningful in realtime pacing; in lockstep pacing it only slows the loop
down (the sim waits for every answer), and a dropped message is ridden out by the sim's re-send
(``lockstep_resend``) and the controllers' waits.
"""

from __future__ import annotations

import time
from functools import partial

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from cpg_walker.nodes import specs
from cpg_walker.nodes.interface import (
    CPG_NODE,
    DEPTH,
    DIAGNOSTICS,
    IMU,
    JOINT_STATES,
    JOINT_TARGETS,
    NODE_NAMES,
    PID_NODE,
    RELAY_NODE,
)
from cpg_walker.nodes.lossy_link import LossyLink, link_error
from cpg_walker.nodes.messages import message_class
from cpg_walker.nodes.params import declare_params
from cpg_walker.nodes.runtime import (
    HotPath,
    exit_stats,
    gc_summary,
    parse_cli,
    run_main,
    scheduling_request,
    spin_once_guarded,
)

#: The node's name (config/relay.yaml).
NAME = NODE_NAMES[RELAY_NODE]
#: Subscriptions of the consumers that a relay may sit in front of, by node executable (only subscribers
#: are remapped: the publishers keep the plain topic the relay listens to).
CONSUMERS = {PID_NODE: (JOINT_TARGETS, JOINT_STATES), CPG_NODE: (IMU,)}
#: Wall s between runs of the executor (parameters, services) and between diagnostics checks.
SLOW_SPIN_S = 0.02


def consumer_remaps(overrides: dict | None = None) -> dict[str, dict[str, str]]:
    """Remaps (``from -> to``) by node executable that route the consumers of the relayed topics through
    the relay's outputs (prefix + topic): ``topics`` and ``prefix`` from ``overrides``, else the relay's
    file (config/relay.yaml)."""
    from cpg_walker.paths import ros_parameters

    values = {**ros_parameters(f"{NAME}.yaml", NAME), **(overrides or {})}
    topics, prefix = list(values["topics"]), str(values["prefix"])
    return {node: {t: prefix + t for t in subs if t in topics} for node, subs in CONSUMERS.items()
            if any(t in topics for t in subs)}


class RelayNode(Node):
    """One LossyLink per relayed topic; messages released by ``spin_relay`` when due."""

    def __init__(self, **node_options) -> None:
        from rclpy.qos import QoSProfile

        super().__init__(NAME, **node_options)
        v = declare_params(self, specs.RELAY)
        topics, types = list(v["topics"]), list(v["types"])
        self.prefix = str(v["prefix"])
        loss, delay, jitter = v["loss"], v["delay"], v["jitter"]
        seed, depth = int(v["seed"]), int(v["queue_depth"])
        self.diag_period = float(v["diagnostics_period"])
        self.scheduling = scheduling_request(v)  # applied once started (runtime.settle_process)
        if len(topics) != len(types) or not topics:
            raise ValueError(f"topics ({len(topics)}) and types ({len(types)}) must be non-empty lists of "
                             "the same length")
        if not self.prefix.startswith("/") or self.prefix == "/":
            raise ValueError(f"prefix must be an absolute namespace like /net, got {self.prefix!r}")
        reason = link_error(loss, delay, jitter)
        if reason:
            raise ValueError(reason)
        qos = QoSProfile(depth=depth)
        self.links: dict[str, LossyLink] = {}
        self.pubs: dict[str, object] = {}
        subs = []
        for i, (topic, type_name) in enumerate(zip(topics, types, strict=True)):
            cls = message_class(type_name)
            self.links[topic] = LossyLink(loss, delay, jitter, seed=seed * 1000 + i)
            self.pubs[topic] = self.create_publisher(cls, self.prefix + topic, qos)
            subs.append(self.create_subscription(cls, topic, partial(self._on_message, topic), qos, raw=True))
        self.hot = HotPath(self, subs)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS, DEPTH)
        self._diag_received = 0
        self.add_on_set_parameters_callback(self._on_set)
        self.get_logger().info(f"relaying {', '.join(topics)} to {self.prefix}/...: {self._settings()}")

    def _settings(self) -> str:
        link = next(iter(self.links.values()))
        return f"loss {link.loss:g}, delay {link.delay_s:g} s, jitter {link.jitter_s:g} s"

    def _on_set(self, params) -> SetParametersResult:
        link = next(iter(self.links.values()))
        new = {"loss": link.loss, "delay": link.delay_s, "jitter": link.jitter_s}
        changed = False
        for prm in params:
            if prm.name in new:
                new[prm.name] = prm.value
                changed = True
        if not changed:
            return SetParametersResult(successful=True)
        reason = link_error(new["loss"], new["delay"], new["jitter"])
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        for lk in self.links.values():
            lk.configure(new["loss"], new["delay"], new["jitter"])
        self.get_logger().info(f"link now: {self._settings()}")
        return SetParametersResult(successful=True)

    def _on_message(self, topic: str, data: bytes) -> None:
        link = self.links[topic]
        now = time.monotonic()
        if link.offer(now, data) and link.next_due() <= now:
            self._flush(topic, now)  # no delay: out at once

    def _flush(self, topic: str, now: float) -> None:
        pub = self.pubs[topic]
        for data in self.links[topic].release(now):
            pub.publish(data)

    def flush_due(self) -> float | None:
        """Publish every due message; the wall time the next one is due (None: none queued)."""
        now = time.monotonic()
        nxt = None
        for topic, link in self.links.items():
            due = link.next_due()
            if due is not None and due <= now:
                self._flush(topic, now)
                due = link.next_due()
            if due is not None and (nxt is None or due < nxt):
                nxt = due
        return nxt

    def summary(self) -> dict:
        return {topic: link.summary() for topic, link in self.links.items()}

    def publish_diagnostics(self) -> None:
        """/diagnostics with the counters, if messages came in since the last (a quiet graph: none, so a
        watchdog on /diagnostics still sees a stalled sim)."""
        received = sum(lk.received for lk in self.links.values())
        if received == self._diag_received:
            return
        self._diag_received = received
        st = DiagnosticStatus(name="cpg_walker/relay", hardware_id="relay", level=DiagnosticStatus.OK,
                              message=self._settings())
        for topic, s in self.summary().items():
            st.values += [KeyValue(key=f"{topic} {k}", value=str(s[k]))
                          for k in ("received", "dropped", "forwarded", "queued")]
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def on_exit(self) -> None:
        exit_stats(self, {"topics": self.summary(), "gc": gc_summary(self)})


def spin_relay(node: RelayNode) -> None:
    """Take messages as they come, publish each when due (waiting at most until the next is due), run
    the executor and the diagnostics now and then."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    next_slow = next_diag = 0.0
    while rclpy.ok(context=node.context):
        nxt = node.flush_due()
        now = time.monotonic()
        node.hot.poll(0.005 if nxt is None else min(0.005, max(0.0, nxt - now)))
        if now >= next_slow:
            spin_once_guarded(node, executor, 0.0)
            next_slow = now + SLOW_SPIN_S
        if now >= next_diag:
            node.publish_diagnostics()
            next_diag = now + node.diag_period


def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("relay_node", "Relays topics with loss, delay and jitter (fault injection).",
                     specs.node_help(RELAY_NODE), argv)
    return run_main(argv, RelayNode, loop=spin_relay)


if __name__ == "__main__":
    raise SystemExit(main())
