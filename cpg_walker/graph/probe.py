"""A monitor node in this process on a graph's DDS domain, shared by the experiments and the tests: what
the graph says on its topics, machine-readable, instead of its nodes' log prose.

    probe = Probe(graph.domain_id, "faults_monitor", robot=True, diagnostics=True)
    probe.wait(lambda: probe.value("cpg_walker/cpg", "reentries", 0) >= 1, "cpg_node re-entered", 300.0)
    probe.robot.t, probe.robot.speed(2.0), probe.robot.fell_at
    probe.close()

- ``robot=True``: /odom/ground_truth and the latched /sim/fallen into ``probe.robot`` (a ``RobotTrack``:
  the current sim run's (t, x, y), runs seen, the fall);
- ``diagnostics=True``: /diagnostics, the latest key-values per status name (``status``, ``value``;
  ``forget`` one when its node restarts): cpg_node's ``cpg_walker/cpg`` (state, reentries, rejoined_at_s,
  reentry_cause, clock_resets, servos_held, ...), sim_node's ``cpg_walker/sim`` (sim_time_s, fallen,
  servo_hold, servo_holds, late_*, ...), relay_node's ``cpg_walker/relay``;
- ``listen`` (keep every message of a topic) and ``subscribe`` (a callback);
- spinning with deadlines: ``spin_for``, ``wait`` (raises ``Timeout``: TimeoutError; a subclass may
  raise another), ``wait_endpoints``;
- the graph: ``subscription_gids`` / ``subscribed`` (a node's subscriptions by their endpoint ids, to tell
  a restarted node's from its dead predecessor's); services ``call``, ``set_param``, ``get_params``.

The wall-clock deadlines only end a wait that hangs; they are never a claim about speed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from cpg_walker.nodes import interface as ifc

#: Wall s ``wait`` allows by default.
WAIT_S = 90.0


@dataclass
class RobotTrack:
    """/odom/ground_truth (t, x, y) of the current sim run, and the latched /sim/fallen."""

    samples: list[tuple[float, float, float]] = field(default_factory=list)
    runs: int = 0  # sim runs seen after the first (a restarted sim's time goes back)
    fell_at: float | None = None

    def add(self, t: float, x: float, y: float) -> None:
        if self.samples and t < self.samples[-1][0] - 0.5:
            self.samples, self.fell_at = [], None
            self.runs += 1
        self.samples.append((t, x, y))

    def fallen(self, fell: bool) -> None:
        if fell and self.fell_at is None:
            self.fell_at = self.t

    @property
    def t(self) -> float:
        return self.samples[-1][0] if self.samples else 0.0

    def speed(self, window_s: float = 2.0, until: float | None = None) -> float | None:
        """Planar speed (m/s) over the window_s sim s ending at ``until`` (default: the newest sample)."""
        end = self.t if until is None else until
        pts = [s for s in self.samples if end - window_s - 1e-9 <= s[0] <= end + 1e-9]
        if len(pts) < 2 or pts[-1][0] - pts[0][0] < 0.9 * window_s:
            return None
        (t0, x0, y0), (t1, x1, y1) = pts[0], pts[-1]
        return math.hypot(x1 - x0, y1 - y0) / (t1 - t0)


def _number(text: str | None) -> float | None:
    """A diagnostic value as a number; None for none / absent / not a number."""
    try:
        return float(text) if text is not None else None
    except ValueError:
        return None


class Probe:
    """An rclpy node in its own context on ``domain_id`` (signal handlers left to the caller)."""

    Timeout: type[Exception] = TimeoutError

    def __init__(self, domain_id: int, name: str = "probe", *, robot: bool = False,
                 diagnostics: bool = False, parameter_services: bool = True):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.ctx, start_parameter_services=parameter_services)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self.robot = RobotTrack()
        self.statuses: dict[str, dict[str, str]] = {}  # status name -> its latest key-values
        self.status_levels: dict[str, int] = {}
        self.status_stamps: dict[str, float] = {}  # status name -> sim s of its latest message
        self._param_clients: dict[str, object] = {}
        if robot:
            self.watch_robot()
        if diagnostics:
            self.watch_diagnostics()

    # ------------------------------------------------------------------ subscriptions
    def subscribe(self, topic: str, msg_type, callback: Callable, qos=50):
        """A subscription calling ``callback(msg)`` as this probe spins."""
        return self.node.create_subscription(msg_type, topic, callback, qos)

    def listen(self, topic: str, msg_type, qos=50) -> None:
        """Keep every message on ``topic`` in ``received[topic]`` as (wall monotonic s, message)."""
        self.received[topic] = []
        self.subscribe(topic, msg_type, lambda m: self.received[topic].append((time.monotonic(), m)), qos)

    def watch_robot(self) -> None:
        """/odom/ground_truth and /sim/fallen into ``robot``."""
        from nav_msgs.msg import Odometry
        from std_msgs.msg import Bool

        def odom(msg) -> None:
            s, p = msg.header.stamp, msg.pose.pose.position
            self.robot.add(s.sec + s.nanosec * 1e-9, p.x, p.y)

        self.subscribe(ifc.ODOM_GROUND_TRUTH, Odometry, odom, 100)
        self.subscribe(ifc.SIM_FALLEN, Bool, lambda msg: self.robot.fallen(bool(msg.data)), ifc.latched_qos())

    def watch_diagnostics(self) -> None:
        """/diagnostics: the latest key-values of each status name (``status``, ``value``)."""
        from diagnostic_msgs.msg import DiagnosticArray

        def diag(msg) -> None:
            t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            for st in msg.status:
                self.statuses[st.name] = {kv.key: kv.value for kv in st.values}
                self.status_levels[st.name] = int.from_bytes(st.level, "little") \
                    if isinstance(st.level, bytes) else int(st.level)
                self.status_stamps[st.name] = t

        self.subscribe(ifc.DIAGNOSTICS, DiagnosticArray, diag, 100)

    def status(self, name: str) -> dict[str, str]:
        """The latest key-values of the /diagnostics status ``name`` ({} before any)."""
        return self.statuses.get(name, {})

    def value(self, name: str, key: str, default: float | None = None) -> float | None:
        """A numeric value of status ``name`` ('none' or absent: ``default``)."""
        found = _number(self.statuses.get(name, {}).get(key))
        return default if found is None else found

    def forget(self, name: str) -> None:
        """Drop what status ``name`` said so far (its node restarted: wait for the new one's)."""
        self.statuses.pop(name, None)
        self.status_levels.pop(name, None)
        self.status_stamps.pop(name, None)

    # ------------------------------------------------------------------ the graph
    def subscription_gids(self, node_name: str, topic: str) -> set[bytes]:
        """Endpoint ids of ``node_name``'s subscriptions to ``topic`` the graph shows now (a killed node's
        may linger until its lease expires)."""
        return {bytes(info.endpoint_gid) for info in self.node.get_subscriptions_info_by_topic(topic)
                if info.node_name == node_name}

    def subscribed(self, node_name: str, topic: str, besides: set[bytes] = frozenset()) -> bool:
        """Whether ``node_name`` has a subscription to ``topic`` other than those in ``besides``."""
        return bool(self.subscription_gids(node_name, topic) - set(besides))

    # ------------------------------------------------------------------ spinning
    def spin_for(self, seconds: float, until: Callable[[], bool] | None = None) -> bool:
        """Spin ``seconds`` wall s, or until ``until()``; whether ``until()`` came true (True without it)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)
            if until is not None and until():
                return True
        return until is None

    def wait(self, until: Callable[[], bool], what: str | Callable[[], str], timeout: float = WAIT_S,
             each: Callable[[], None] | None = None) -> None:
        """Spin until ``until()``; ``Timeout`` naming ``what`` (text, or a function giving it) when
        ``timeout`` wall s pass first. ``each()``, if given, runs every 10 ms meanwhile."""
        now = time.monotonic()
        end, next_each = now + timeout, now
        while not until():
            now = time.monotonic()
            if now > end:
                raise self.Timeout(f"not within {timeout:g} s: {what() if callable(what) else what}")
            if each is not None and now >= next_each:
                each()
                next_each = now + 0.01
            self.executor.spin_once(timeout_sec=0.01)

    def wait_endpoints(self, topic: str, publishers: int = 1, subscribers: int = 1,
                       timeout: float = WAIT_S) -> None:
        """Wait until the graph shows at least ``publishers`` and ``subscribers`` on ``topic`` (this probe's
        own included)."""
        self.wait(lambda: self.node.count_publishers(topic) >= publishers
                  and self.node.count_subscribers(topic) >= subscribers,
                  lambda: f"{topic}: {self.node.count_publishers(topic)} publishers, "
                          f"{self.node.count_subscribers(topic)} subscribers", timeout)

    # ------------------------------------------------------------------ services
    def call(self, srv_type, name: str, timeout: float = WAIT_S):
        """Call service ``name`` with an empty request; its response."""
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise self.Timeout(f"service {name} not available")
        future = client.call_async(srv_type.Request())
        self.wait(future.done, f"an answer from {name}", timeout)
        return future.result()

    def set_param(self, node: str, name: str, value, timeout: float = WAIT_S,
                  answer_timeout: float = WAIT_S):
        """Set one parameter of ``/node`` through its set_parameters service; the SetParametersResult.
        ``value``: a number (sent as a double) or a ready rcl_interfaces ParameterValue. ``timeout``: for
        the service to show up (the node may still be starting)."""
        from rcl_interfaces.msg import Parameter
        from rcl_interfaces.srv import SetParameters

        client = self._param_clients.get(node)
        if client is None:
            client = self.node.create_client(SetParameters, f"/{node}/set_parameters")
            if not client.wait_for_service(timeout_sec=timeout):
                raise self.Timeout(f"/{node}/set_parameters not available")
            self._param_clients[node] = client
        value = value if not isinstance(value, float | int) else double(value)
        future = client.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=value)]))
        self.wait(future.done, f"an answer setting {node}.{name}", answer_timeout)
        return future.result().results[0]

    def get_params(self, node: str, names: list[str], timeout: float = WAIT_S) -> list:
        """The ParameterValues of ``names`` of ``/node`` through its get_parameters service."""
        from rcl_interfaces.srv import GetParameters

        get = self.node.create_client(GetParameters, f"/{node}/get_parameters")
        if not get.wait_for_service(timeout_sec=timeout):
            raise self.Timeout(f"/{node}/get_parameters not available")
        future = get.call_async(GetParameters.Request(names=names))
        self.wait(future.done, f"an answer from /{node}/get_parameters", timeout)
        return list(future.result().values)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def double(x: float):
    """A double ParameterValue."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(x))


def string(s: str):
    """A string ParameterValue."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=s)
