"""``ros2 param`` / ``ros2 topic``-like tools for a pip-only install (no ros2cli): the core of
``cpg-walker param`` and ``cpg-walker topic`` (node listing/info and topic info: ros2cli_graph.py;
``topic pub``: ros2cli_pub.py).

Everything goes through the real ROS graph: the nodes' parameter services (rcl_interfaces
ListParameters / GetParameters / SetParameters) and subscriptions to the topics, with the message types
discovered from the graph. The DDS domain is the environment's ``ROS_DOMAIN_ID`` (0 if unset).
"""

from __future__ import annotations

import math
import os
import statistics
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

from cpg_walker.errors import InputError, ToolError
from cpg_walker.nodes.messages import message_class


def domain_id() -> int:
    """The DDS domain the tools join: ``ROS_DOMAIN_ID`` or 0."""
    from cpg_walker.graph.processes import env_domain_id

    domain = env_domain_id()
    return 0 if domain is None else domain


class Session:
    """One rclpy context + node on the environment's domain; a context manager. The node is hidden (its
    name starts with ``_``, like ros2cli's own ``_ros2cli_*`` nodes) unless ``hidden`` is False: `node
    list` does not show the tools themselves."""

    def __init__(self, name: str = "cpg_walker_tool", hidden: bool = True, pid_suffix: bool = True):
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        self.domain = domain_id()
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=self.domain, signal_handler_options=SignalHandlerOptions.NO)
        full = (f"{name}_{os.getpid()}" if pid_suffix else name).lstrip("_")
        self.node = rclpy.create_node(f"_{full}" if hidden else full, context=self.ctx,
                                      start_parameter_services=False, enable_rosout=False)
        from rclpy.executors import SingleThreadedExecutor

        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)

    def spin_until(self, done: Callable[[], bool], timeout: float | None) -> bool:
        """Spin (in 0.1 s slices, so Ctrl-C is handled) until ``done()`` or ``timeout`` wall seconds."""
        end = None if timeout is None else time.monotonic() + timeout
        while not done():
            if end is not None and time.monotonic() >= end:
                return False
            left = 0.1 if end is None else max(0.0, min(0.1, end - time.monotonic()))
            self.executor.spin_once(timeout_sec=left)
        return True

    def settled(self, snapshot: Callable[[], Any], ready: Callable[[Any], bool] = bool, settle: float = 0.5,
                timeout: float = 3.0) -> Any:
        """The graph as ``snapshot()`` sees it once it is ``ready`` and unchanged for ``settle`` wall
        seconds (discovery goes one endpoint at a time), or as it is after ``timeout``."""
        end = time.monotonic() + timeout
        last = snapshot()
        stable_since = time.monotonic()
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
            now = snapshot()
            if now != last:
                last, stable_since = now, time.monotonic()
            elif ready(now) and time.monotonic() - stable_since >= settle:
                break
        return last

    def call(self, srv_type: Any, name: str, request: Any, timeout: float, what: str) -> Any:
        """Call service ``name``; ToolError ``what`` not found / no answer within ``timeout``."""
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise ToolError(f"{what} not found in domain {self.domain}; is the graph running? "
                            f"(no {name} service within {timeout:g} s)")
        future = client.call_async(request)
        if not self.spin_until(future.done, timeout):
            raise ToolError(f"no answer from {name} within {timeout:g} s")
        return future.result()

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def node_name(name: str) -> str:
    """``cpg`` or ``/cpg`` -> ``/cpg``."""
    name = name.strip()
    if not name or name == "/":
        raise InputError("a node name is required, e.g. /cpg")
    return name if name.startswith("/") else "/" + name


# ----------------------------------------------------------------------------------------- parameters

TYPE_NAMES = {1: "Boolean", 2: "Integer", 3: "Double", 4: "String", 5: "Byte array", 6: "Boolean array",
              7: "Integer array", 8: "Double array", 9: "String array"}


def from_parameter_value(v: Any) -> Any:
    """An rcl_interfaces ParameterValue -> a Python value (None when not set)."""
    fields = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
              5: "byte_array_value", 6: "bool_array_value", 7: "integer_array_value",
              8: "double_array_value", 9: "string_array_value"}
    if v.type not in fields:
        return None
    value = getattr(v, fields[v.type])
    return list(value) if v.type >= 5 else value


def parse_value(text: str, current_type: int | None = None) -> Any:
    """A command-line value as ``ros2 param set`` reads it (YAML: ``0.8`` double, ``1`` integer, ``true``
    bool, ``[1, 2]`` array, else string); an integer (or ``nan``/``inf``) for a double parameter is sent
    as a double."""
    import yaml

    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text
    if value is None:
        value = text
    if current_type == 3 and not isinstance(value, bool):  # a double parameter
        if isinstance(value, int):
            value = float(value)
        elif isinstance(value, str):
            try:
                value = float(value)  # nan, inf, -inf
            except ValueError:
                pass
    if current_type == 8 and isinstance(value, list) and all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in value):
        value = [float(x) for x in value]
    return value


def to_parameter_value(value: Any) -> Any:
    """A Python value -> an rcl_interfaces ParameterValue of the matching type."""
    from rcl_interfaces.msg import ParameterType, ParameterValue

    T = ParameterType
    if isinstance(value, bool):
        return ParameterValue(type=T.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=T.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=T.PARAMETER_DOUBLE, double_value=value)
    if isinstance(value, list) and value:
        if all(isinstance(x, bool) for x in value):
            return ParameterValue(type=T.PARAMETER_BOOL_ARRAY, bool_array_value=value)
        if all(isinstance(x, int) and not isinstance(x, bool) for x in value):
            return ParameterValue(type=T.PARAMETER_INTEGER_ARRAY, integer_array_value=value)
        if all(isinstance(x, int | float) and not isinstance(x, bool) for x in value):
            return ParameterValue(type=T.PARAMETER_DOUBLE_ARRAY, double_array_value=[float(x) for x in value])
        if all(isinstance(x, str) for x in value):
            return ParameterValue(type=T.PARAMETER_STRING_ARRAY, string_array_value=value)
    return ParameterValue(type=T.PARAMETER_STRING, string_value=str(value))


def list_parameters(s: Session, node: str, timeout: float = 10.0) -> list[str]:
    """The parameter names of ``node``, sorted."""
    from rcl_interfaces.srv import ListParameters

    node = node_name(node)
    res = s.call(ListParameters, f"{node}/list_parameters", ListParameters.Request(), timeout, f"node {node}")
    return sorted(res.result.names)


def get_parameters(s: Session, node: str, names: list[str], timeout: float = 10.0) -> list[Any]:
    """The ParameterValues of ``names`` of ``node`` (type 0 = not set)."""
    from rcl_interfaces.srv import GetParameters

    node = node_name(node)
    res = s.call(GetParameters, f"{node}/get_parameters", GetParameters.Request(names=names), timeout,
                 f"node {node}")
    if len(res.values) != len(names):
        raise ToolError(f"{node} did not return {', '.join(names)} (not declared?)")
    return list(res.values)


def set_parameter(s: Session, node: str, name: str, text: str, timeout: float = 10.0) -> tuple[bool, str]:
    """Set ``name`` of ``node`` from its command-line text; (successful, the node's reason)."""
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters

    current = get_parameters(s, node, [name], timeout)[0]
    value = to_parameter_value(parse_value(text, current.type))
    node = node_name(node)
    req = SetParameters.Request(parameters=[Parameter(name=name, value=value)])
    res = s.call(SetParameters, f"{node}/set_parameters", req, timeout, f"node {node}")
    result = res.results[0]
    return bool(result.successful), result.reason


def describe_parameters(s: Session, node: str, names: list[str], timeout: float = 10.0) -> list[Any]:
    """The ParameterDescriptors of ``names`` of ``node`` (ToolError naming an undeclared one)."""
    from rcl_interfaces.srv import DescribeParameters

    node = node_name(node)
    res = s.call(DescribeParameters, f"{node}/describe_parameters", DescribeParameters.Request(names=names),
                 timeout, f"node {node}")
    if len(res.descriptors) != len(names):  # rclpy answers none at all when one name is not declared
        declared = set(list_parameters(s, node, timeout))
        missing = [n for n in names if n not in declared] or names
        raise ToolError(f"{node} has no parameter {', '.join(missing)} (not declared)")
    return list(res.descriptors)


DESCRIPTOR_TYPE_NAMES = {0: "not set"} | {t: n.lower() for t, n in TYPE_NAMES.items()}  # describe's


def format_descriptor(d: Any) -> str:
    """``ros2 param describe``'s block for one ParameterDescriptor."""
    lines = [f"Parameter name: {d.name}", f"  Type: {DESCRIPTOR_TYPE_NAMES.get(d.type, 'unknown')}"]
    if d.description:
        lines.append(f"  Description: {d.description}")
    lines.append("  Constraints:")
    if d.read_only:
        lines.append("    Read only: true")
    ranges = list(d.floating_point_range) + list(d.integer_range)
    if ranges:
        r = ranges[0]
        lines += [f"    Min value: {r.from_value}", f"    Max value: {r.to_value}"]
        if r.step:
            lines.append(f"    Step: {r.step}")
    if d.additional_constraints:
        lines.append(f"    Additional constraints: {d.additional_constraints}")
    return "\n".join(lines)


def dump_parameters(s: Session, node: str, timeout: float = 10.0) -> str:
    """``ros2 param dump``'s YAML: ``/node: {ros__parameters: ...}``, dotted names nested, keys sorted."""
    node = node_name(node)
    names = list_parameters(s, node, timeout)
    values = get_parameters(s, node, names, timeout) if names else []
    return parameters_yaml(node, {n: from_parameter_value(v) for n, v in zip(names, values, strict=True)})


def parameters_yaml(node: str, values: dict[str, Any]) -> str:
    """A params file of ``values`` (name -> value) for ``node``: nested at the dots as ros2 writes it,
    except below a name that is itself a parameter (``feedback`` and ``feedback.gain``: ros2's dump fails
    there), where the rest of the name is kept as one dotted key, which ROS reads back the same."""
    import yaml

    params: dict[str, Any] = {}
    for name in sorted(values):
        parts = name.split(".")
        # the first proper prefix that is a parameter itself: nest above it, keep the rest as one key
        cut = next((i for i in range(1, len(parts)) if ".".join(parts[:i]) in values), len(parts))
        d = params
        for group in parts[:cut - 1]:
            d = d.setdefault(group, {})
        d[".".join(parts[cut - 1:])] = values[name]
    return yaml.dump({node_name(node): {"ros__parameters": params}}, default_flow_style=False)


def describe_value(v: Any) -> str:
    """``ros2 param get``'s wording: ``Double value is: 0.8``."""
    if v.type == 0:
        return "Parameter not set."
    return f"{TYPE_NAMES.get(v.type, 'Unknown')} value is: {from_parameter_value(v)}"


# ----------------------------------------------------------------------------------------------- topics

def topic_types(s: Session, settle: float = 0.5, timeout: float = 3.0) -> dict[str, list[str]]:
    """Topic -> types as discovered from the graph: waits until the list is unchanged for ``settle``
    seconds (at most ``timeout``), since discovery takes a moment."""
    return s.settled(lambda: {name: list(types) for name, types in s.node.get_topic_names_and_types()},
                     lambda now: bool(now) and _others_seen(s), settle, timeout)


def _others_seen(s: Session) -> bool:
    return any(n != s.node.get_name() for n in s.node.get_node_names())


def find_topic(s: Session, topic: str, timeout: float = 10.0) -> str:
    """The type of ``topic`` (waits up to ``timeout`` for a publisher to show up)."""
    topic = node_name(topic)
    end = time.monotonic() + timeout
    while True:
        types = dict(s.node.get_topic_names_and_types()).get(topic)
        if types and s.node.count_publishers(topic):
            return types[0]
        if time.monotonic() >= end:
            raise ToolError(f"topic {topic} not found (no publisher) in domain {s.domain} within "
                            f"{timeout:g} s; is the graph running?")
        s.executor.spin_once(timeout_sec=0.05)


def matching_qos(s: Session, topic: str) -> Any:
    """A QoS that receives from every publisher of ``topic`` (like ``ros2 topic echo``: reliable and
    transient-local only when all publishers are)."""
    from cpg_walker.nodes import interface

    return interface.matching_qos(s.node.get_publishers_info_by_topic(topic), depth=100)


def to_plain(value: Any) -> Any:
    """A message (or field) -> plain dicts/lists/numbers/strings, fields in declaration order."""
    if hasattr(value, "get_fields_and_field_types"):
        return {f: to_plain(getattr(value, f)) for f in value.get_fields_and_field_types()}
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, str | bool | int | float) or value is None:
        return value
    if hasattr(value, "tolist"):  # numpy arrays
        return value.tolist()
    if isinstance(value, list | tuple) or hasattr(value, "__iter__"):  # lists, array.array
        return [to_plain(x) for x in value]
    return str(value)


def to_yaml(value: Any) -> str:
    """``ros2 topic echo``'s YAML form of a message or field."""
    import yaml

    plain = to_plain(value)
    if not isinstance(plain, dict | list) or not plain:
        text = yaml.safe_dump(plain, default_flow_style=True, width=1 << 30)
        return text.removesuffix("\n...\n").removesuffix("\n") + "\n"
    return yaml.safe_dump(plain, default_flow_style=False, sort_keys=False, width=1 << 30)


def field(msg: Any, path: str | None) -> Any:
    """``msg.a.b`` for ``path`` ``a.b`` (ValueError naming the missing field)."""
    if not path:
        return msg
    value = msg
    for part in path.split("."):
        if not hasattr(value, "get_fields_and_field_types") or part not in value.get_fields_and_field_types():
            raise InputError(f"no field {part!r} in {path!r} of {type(msg).__name__}")
        value = getattr(value, part)
    return value


def echo(s: Session, topic: str, count: int | None = None, path: str | None = None,
         find_timeout: float = 10.0, timeout: float | None = None) -> Iterator[str]:
    """The YAML text of each message received on ``topic`` (``count`` of them, or until ``timeout`` wall
    seconds without the count being reached: ToolError)."""
    topic = node_name(topic)
    if timeout is not None:
        find_timeout = min(find_timeout, timeout)
    cls = message_class(find_topic(s, topic, find_timeout))
    if path:
        field(cls(), path)  # a bad field is an error before any message arrives
    pending: deque = deque()
    s.node.create_subscription(cls, topic, lambda m: pending.append(m), matching_qos(s, topic))
    shown = 0
    end = None if timeout is None else time.monotonic() + timeout
    while count is None or shown < count:
        if not pending:
            left = None if end is None else end - time.monotonic()
            if left is not None and left <= 0:
                raise ToolError(f"no message on {topic} within {timeout:g} s")
            s.spin_until(lambda: bool(pending), left)
            continue
        yield to_yaml(field(pending.popleft(), path))
        shown += 1


class RateMeter:
    """Wall-clock arrival rate over the last ``window`` messages (``ros2 topic hz``'s statistics)."""

    def __init__(self, window: int = 10000):
        if window < 2:
            raise InputError(f"--window must be at least 2, got {window}")
        self.intervals: deque[float] = deque(maxlen=window - 1)
        self.last: float | None = None
        self.count = 0

    def tick(self, t: float | None = None) -> None:
        t = time.monotonic() if t is None else t
        if self.last is not None:
            self.intervals.append(t - self.last)
        self.last = t
        self.count += 1

    def summary(self) -> dict[str, float] | None:
        """rate (Hz), min/max/std of the period (s), window (messages); None before two messages."""
        iv = self.intervals
        if not iv:
            return None
        mean = sum(iv) / len(iv)
        return {"rate": 1.0 / mean if mean > 0 else math.inf, "min": min(iv), "max": max(iv),
                "std": statistics.pstdev(iv), "window": len(iv) + 1}


def format_rate(r: dict[str, float]) -> str:
    return (f"average rate: {r['rate']:.3f}\n\tmin: {r['min']:.6f}s max: {r['max']:.6f}s "
            f"std dev: {r['std']:.6f}s window: {r['window']}")


def hz(s: Session, topic: str, window: int = 10000, report_every: float = 1.0, duration: float | None = None,
       find_timeout: float = 10.0) -> Iterator[dict[str, float] | None]:
    """Every ``report_every`` wall seconds, the rate summary of ``topic`` (raw, not deserialised: wall
    clock at arrival in this process, not sim time); stops after ``duration`` wall seconds."""
    topic = node_name(topic)
    cls = message_class(find_topic(s, topic, find_timeout))
    meter = RateMeter(window)
    s.node.create_subscription(cls, topic, lambda _msg: meter.tick(), matching_qos(s, topic), raw=True)
    start = time.monotonic()
    next_report = start + report_every
    reported = -1
    while duration is None or time.monotonic() - start < duration:
        s.executor.spin_once(timeout_sec=0.05)
        if time.monotonic() >= next_report:
            next_report += report_every
            reported = meter.count
            yield meter.summary()
    if meter.count != reported:
        yield meter.summary()
