"""Foxglove's parameter panel on the ROS nodes' parameter services (foxglove_node's server listener).

Parameter names follow the ROS foxglove_bridge: ``/<node>.<parameter>`` (``/cpg.zeta``). A get asks the
node's GetParameters service; a set goes to its SetParameters service, so the node's own validation
decides (same checks, same refusals as ``cpg-walker param set``): accepted -> the value the node now holds
is returned; refused -> its old value is returned, and the node's reason is logged and sent to the clients
as a status message (error level). Read-only bridge values (``/robot_description``) refuse every set.

Threading: the foxglove-sdk calls the listener from its own threads; the service calls are made there
(``call_async``, thread-safe) and their answers are taken by the node's executor in the main thread, which
the waiting caller polls with a deadline (``timeout_s``): no lock is held across the wait, so nothing can
deadlock, and a node that does not answer gives the old value and a "no answer" reason.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import foxglove
from foxglove import Parameter, ParameterType, StatusLevel
from foxglove.websocket import ServerListener
from rcl_interfaces.msg import Parameter as RosParameter
from rcl_interfaces.msg import ParameterType as RosType
from rcl_interfaces.msg import ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter as RclpyParameter
from rclpy.parameter import parameter_value_to_python


def foxglove_name(node: str, param: str) -> str:
    """``cpg``, ``zeta`` -> ``/cpg.zeta`` (the ROS foxglove_bridge's naming)."""
    return f"/{node.strip('/')}.{param}"


def parse_target(text: str) -> tuple[str, str]:
    """``cpg.zeta`` or ``/cpg.zeta`` -> (``cpg``, ``zeta``); ValueError naming the problem."""
    node, dot, param = text.strip().lstrip("/").partition(".")
    if not dot or not node or not param or "/" in node:
        raise ValueError(f"forwarded parameter {text!r}: expected NODE.PARAMETER (e.g. cpg.zeta)")
    return node, param


def to_foxglove(name: str, value: object) -> Parameter:
    """A native value as a Foxglove parameter (floats typed float64, so 1.0 stays a float)."""
    if isinstance(value, float):
        return Parameter(name, value=value, type=ParameterType.Float64)
    if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
        return Parameter(name, value=value, type=ParameterType.Float64Array)
    return Parameter(name, value=value)


def to_ros_value(value: object, like: ParameterValue | None) -> ParameterValue:
    """A value from Foxglove as a ROS ParameterValue: a number for a double parameter is a double (JSON
    has no 1.0), anything else as rclpy infers it (a wrong type is for the node to refuse)."""
    if like is not None and like.type == RosType.PARAMETER_DOUBLE and isinstance(value, int | float) \
            and not isinstance(value, bool):
        return ParameterValue(type=RosType.PARAMETER_DOUBLE, double_value=float(value))
    if like is not None and like.type == RosType.PARAMETER_DOUBLE_ARRAY and isinstance(value, list):
        try:
            return ParameterValue(type=RosType.PARAMETER_DOUBLE_ARRAY,
                                  double_array_value=[float(v) for v in value])
        except (TypeError, ValueError):
            pass
    return RclpyParameter("p", value=value).to_parameter_msg().value


class ParameterForwarder(ServerListener):
    """The server listener: parameters of other nodes (``targets``: ``node.param`` names) and read-only
    values of the bridge (``fixed``: Foxglove name -> value). ``server`` is set once it is started;
    ``on_subscribe(topic)`` is called when a client subscribes to a channel."""

    def __init__(self, node: Node, targets: list[str], fixed: dict[str, object], timeout_s: float,
                 on_subscribe: Callable[[str], None] | None = None) -> None:
        self.node, self.timeout_s, self.fixed = node, float(timeout_s), dict(fixed)
        self.targets: dict[str, tuple[str, str]] = {}
        for text in targets:
            n, p = parse_target(text)
            self.targets[foxglove_name(n, p)] = (n, p)
        nodes = sorted({n for n, _ in self.targets.values()})
        self.get_clients = {n: node.create_client(GetParameters, f"/{n}/get_parameters") for n in nodes}
        self.set_clients = {n: node.create_client(SetParameters, f"/{n}/set_parameters") for n in nodes}
        self.server: foxglove.WebSocketServer | None = None
        self.subscribed = on_subscribe
        self.log = node.get_logger()

    # ------------------------------------------------------------------ service calls (any thread)
    def _call(self, client, request):
        """The service's answer; TimeoutError with the reason when there is none within ``timeout_s``."""
        if not client.service_is_ready():
            raise TimeoutError(f"{client.srv_name} is not available (is the node running?)")
        future = client.call_async(request)
        end = time.monotonic() + self.timeout_s
        while not future.done():  # the main thread's executor completes it
            if time.monotonic() > end:
                client.remove_pending_request(future)
                raise TimeoutError(f"no answer from {client.srv_name} within {self.timeout_s:g} s")
            time.sleep(0.002)
        return future.result()

    def _get(self, node: str, params: list[str]) -> dict[str, ParameterValue]:
        answer = self._call(self.get_clients[node], GetParameters.Request(names=params))
        return {p: v for p, v in zip(params, answer.values, strict=False)
                if v.type != RosType.PARAMETER_NOT_SET}

    def _by_node(self, names) -> dict[str, list[str]]:
        out: dict[str, list[str]] = {}
        for name in names:
            if name in self.targets:
                n, p = self.targets[name]
                out.setdefault(n, []).append(p)
        return out

    def _report(self, text: str) -> None:
        """A refusal or failure: logged, and shown to the clients as an error status."""
        self.log.warn(text)
        if self.server is not None:
            self.server.publish_status(text, StatusLevel.Error)

    def get(self, names: list[str]) -> list[Parameter]:
        """The Foxglove parameters ``names`` (all when empty) as the nodes hold them now."""
        names = list(names) or [*self.targets, *self.fixed]
        out = [to_foxglove(n, self.fixed[n]) for n in names if n in self.fixed]
        for node, params in self._by_node(names).items():
            try:
                values = self._get(node, params)
            except TimeoutError as exc:
                self._report(f"cannot get {', '.join(foxglove_name(node, p) for p in params)}: {exc}")
                continue
            out += [to_foxglove(foxglove_name(node, p), parameter_value_to_python(v))
                    for p, v in values.items()]
        return out

    def set(self, params: list[Parameter]) -> list[Parameter]:
        """Forward each parameter to its node's SetParameters; the values they hold afterwards."""
        out: list[Parameter] = []
        wanted: dict[str, dict[str, object]] = {}
        for prm in params:
            if prm.name in self.fixed:
                self._report(f"{prm.name} is read-only")
                out.append(to_foxglove(prm.name, self.fixed[prm.name]))
            elif prm.name not in self.targets:
                self._report(f"{prm.name} is not a forwarded parameter (foxglove_node's "
                             f"'parameters': {', '.join(self.targets)})")
            else:
                n, p = self.targets[prm.name]
                wanted.setdefault(n, {})[p] = prm.get_value()
        for node, values in wanted.items():
            old: dict[str, ParameterValue] = {}
            try:
                old = self._get(node, list(values))
                request = SetParameters.Request(parameters=[
                    RosParameter(name=p, value=to_ros_value(v, old.get(p))) for p, v in values.items()])
                answer = self._call(self.set_clients[node], request)
            except (TimeoutError, TypeError, ValueError) as exc:
                self._report(f"cannot set {', '.join(foxglove_name(node, p) for p in values)}: {exc}")
                out += [to_foxglove(foxglove_name(node, p), parameter_value_to_python(v))
                        for p, v in old.items()]
                continue
            for (p, v), result in zip(values.items(), answer.results, strict=True):
                name = foxglove_name(node, p)
                if result.successful:
                    self.log.info(f"set {name} = {v!r} (from Foxglove)")
                else:
                    self._report(f"{name} = {v!r} refused by /{node}: {result.reason}")
            try:
                now = self._get(node, list(values))
            except TimeoutError as exc:
                self._report(f"cannot read back {node}'s parameters: {exc}")
                now = old
            out += [to_foxglove(foxglove_name(node, p), parameter_value_to_python(v)) for p, v in now.items()]
        return out

    def changed(self, node: str, params) -> list[Parameter]:
        """The forwarded ones among a /parameter_events message's changed parameters (rcl Parameters)."""
        out = []
        for prm in params:
            name = foxglove_name(node, prm.name)
            if name in self.targets:
                out.append(to_foxglove(name, parameter_value_to_python(prm.value)))
        return out

    # ------------------------------------------------------------------ ServerListener (sdk threads)
    def on_get_parameters(self, client, param_names: list[str], request_id: str | None = None) -> list:
        return self.get(param_names)

    def on_set_parameters(self, client, parameters: list, request_id: str | None = None) -> list:
        return self.set(parameters)

    def on_subscribe(self, client, channel) -> None:
        if self.subscribed is not None:
            self.subscribed(channel.topic)
