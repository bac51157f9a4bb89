"""``ros2 topic pub`` without ros2cli: a message filled from YAML values (``{linear: {x: 0.1}}``), with a
clear error naming a field that does not exist or a value of the wrong type, published at a rate, once or
N times (the core of ``cpg-walker topic pub``; flags and output as ros2cli's, Jazzy)."""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable
from typing import Any

from cpg_walker.errors import InputError, ToolError
from cpg_walker.graph.ros2cli import Session, node_name
from cpg_walker.nodes.messages import message_class

FLOAT_TYPES = {"float", "double", "float32", "float64", "long double"}
#: Integer field types -> their range (rclpy's generated setters check nothing unless asked to).
INT_RANGES = {f"{u}int{n}": ((0, 2**n - 1) if u else (-2**(n - 1), 2**(n - 1) - 1))
              for u in ("", "u") for n in (8, 16, 32, 64)} | {"char": (0, 255)}
BYTE_TYPES = {"byte", "octet"}  # a bytes object of length 1 in Python
STAMP_NOW = "now"  # a builtin_interfaces/Time field's value: the time of each publication (as ros2)
HEADER_AUTO = "auto"  # a std_msgs/Header field's value: a header stamped at each publication (as ros2)


def _element(type_str: str) -> tuple[str, bool, int | None, bool]:
    """(element type, is an array, its size or bound, the size is exact): ``sequence<double, 3>`` ->
    (``double``, True, 3, False); ``double[3]`` -> (``double``, True, 3, True); ``double`` -> (``double``,
    False, None, False)."""
    if type_str.startswith("sequence<"):
        inner = type_str[len("sequence<"):-1].rsplit(",", 1)
        bounded = len(inner) == 2 and inner[1].strip().isdigit()
        return (inner[0] if bounded else type_str[len("sequence<"):-1]).strip(), True, (
            int(inner[1]) if bounded else None), False
    m = re.fullmatch(r"(.+)\[(\d+)\]", type_str)
    return (m.group(1), True, int(m.group(2)), True) if m else (type_str, False, None, False)


def _check_size(value: list, type_str: str, size: int | None, exact: bool, where: str) -> None:
    if size is not None and (len(value) != size if exact else len(value) > size):
        raise InputError(f"field {where!r} is a {type_str}: {'exactly' if exact else 'at most'} {size} "
                         f"items, got {len(value)}")


def _scalar(value: Any, base: str, where: str) -> Any:
    """``value`` as a field of primitive type ``base`` wants it (ValueError naming ``where``)."""
    bad = ValueError(f"field {where!r} is a {base}, got {value!r}")
    if base in FLOAT_TYPES:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad
        return float(value)
    if base in INT_RANGES or base in BYTE_TYPES:
        lo, hi = INT_RANGES.get(base, (0, 255))
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        if not lo <= value <= hi:
            raise InputError(f"field {where!r} is a {base}: {value} is outside [{lo}, {hi}]")
        return bytes([value]) if base in BYTE_TYPES else value
    if base == "boolean":
        if not isinstance(value, bool):
            raise bad
        return value
    if base.startswith(("string", "wstring")):
        if isinstance(value, dict | list):
            raise bad
        text = value if isinstance(value, str) else str(value)  # data: 5 -> '5', as ros2
        bound = re.fullmatch(r"w?string<=(\d+)", base)
        if bound and len(text) > int(bound.group(1)):
            raise InputError(f"field {where!r} is a {base}: {len(text)} characters")
        return text
    return value


def fill_message(msg: Any, values: Any, stamps: list[Callable[[Any], None]] | None = None,
                 prefix: str = "") -> Any:
    """Set ``msg``'s fields from ``values`` (a dict, nested for nested messages); ``stamps`` collects the
    setters of ``now`` / ``auto`` stamps (each takes a builtin_interfaces Time). ValueError naming the
    field (its dotted path) when it does not exist or its value does not fit."""
    stamps = [] if stamps is None else stamps
    kind = _type_name(type(msg))
    if not isinstance(values, dict):
        example = next(iter(msg.get_fields_and_field_types()), "field")
        what = f"field {prefix.rstrip('.')!r} is a {kind}" if prefix else f"the values fill a {kind}"
        raise InputError(f"{what}: give a dictionary of its fields, e.g. '{{{example}: ...}}', "
                         f"got {values!r}")
    fields = msg.get_fields_and_field_types()
    for key, value in values.items():
        where = prefix + str(key)
        if key not in fields:
            raise InputError(f"no field {where!r} in {kind} (its fields: {', '.join(fields) or 'none'})")
        base, is_array, size, exact = _element(fields[key])
        if is_array and not isinstance(value, list):
            raise InputError(f"field {where!r} is a {fields[key]}, got {value!r} (give a list)")
        if is_array:
            _check_size(value, fields[key], size, exact, where)
        if "/" not in base:  # primitive
            if is_array:
                value = [_scalar(v, base, f"{where}[{i}]") for i, v in enumerate(value)]
            else:
                value = _scalar(value, base, where)
            try:
                setattr(msg, key, value)
            except (AssertionError, TypeError, ValueError, OverflowError) as exc:
                raise InputError(f"field {where!r} ({fields[key]}) cannot be {value!r}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        elif is_array:
            cls = message_class(base)
            items = [fill_message(cls(), v, stamps, f"{where}[{i}].") for i, v in enumerate(value)]
            try:
                setattr(msg, key, items)
            except (AssertionError, TypeError, ValueError) as exc:
                raise InputError(f"field {where!r} ({fields[key]}) cannot hold {len(items)} items: "
                                 f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        elif value == STAMP_NOW and base == "builtin_interfaces/Time":
            stamps.append(lambda t, m=msg, k=key: setattr(m, k, t))
        elif value == HEADER_AUTO and base == "std_msgs/Header":
            header = getattr(msg, key)
            stamps.append(lambda t, h=header: setattr(h, "stamp", t))
        else:
            fill_message(getattr(msg, key), value, stamps, where + ".")
    return msg


def _type_name(cls: type) -> str:
    """``geometry_msgs/msg/Twist`` of a generated message class."""
    module = cls.__module__.split(".")
    return f"{module[0]}/{module[1]}/{cls.__name__}" if len(module) >= 2 else cls.__name__


def build_message(type_name: str, text: str) -> tuple[type, Any, list[Callable[[Any], None]]]:
    """(class, filled message, stamp setters) from a type name and YAML ``text`` (ValueError on bad
    YAML, an unknown field or a value of the wrong type)."""
    import yaml

    try:
        cls = message_class(type_name)
    except ToolError as exc:
        raise InputError(str(exc)) from None
    try:
        values = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"the values are not YAML: {str(exc).splitlines()[0]}") from None
    if values is None:
        values = {}
    if not isinstance(values, dict):
        raise InputError(f"the values need to be a dictionary in YAML format, e.g. '{{field: value}}', "
                         f"got {text!r}")
    stamps: list[Callable[[Any], None]] = []
    return cls, fill_message(cls(), values, stamps), stamps


def qos_profile(preset: str = "default", reliability: str | None = None, durability: str | None = None,
                depth: int | None = None, history: str | None = None) -> Any:
    """ros2's ``--qos-profile`` preset with the ``--qos-*`` overrides (rclpy's short keys: ValueError
    naming a bad one and the valid ones)."""
    from rclpy import qos as q

    def pick(kind: Any, key: str, flag: str) -> Any:
        try:
            return kind.get_from_short_key(key)
        except (KeyError, ValueError):
            raise InputError(f"{flag} {key!r} is not one of: {', '.join(kind.short_keys())}") from None

    shared = pick(q.QoSPresetProfiles, preset, "--qos-profile")  # copied: the preset is rclpy's own
    profile = q.QoSProfile(**{k.lstrip("_"): getattr(shared, k.lstrip("_")) for k in q.QoSProfile.__slots__})
    if history:
        profile.history = pick(q.QoSHistoryPolicy, history, "--qos-history")
    if durability:
        profile.durability = pick(q.QoSDurabilityPolicy, durability, "--qos-durability")
    if reliability:
        profile.reliability = pick(q.QoSReliabilityPolicy, reliability, "--qos-reliability")
    if depth is not None and depth >= 0:
        profile.depth = depth
    elif profile.durability == q.QoSDurabilityPolicy.TRANSIENT_LOCAL and profile.depth == 0:
        profile.depth = 1
    return profile


def publish(s: Session, topic: str, cls: type, msg: Any, stamps: list[Callable[[Any], None]], *,
            period: float = 1.0, print_nth: int = 1, times: int = 0, wait_matching: int = 0,
            max_wait: float | None = None, qos: Any = None, keep_alive: float = 0.1,
            out: Any = None) -> int:
    """ros2's publish loop: wait for ``wait_matching`` subscriptions (ToolError after ``max_wait`` wall
    s), print ``publisher: beginning loop``, publish now and every ``period`` wall s (``times`` in all;
    0 = until interrupted), print every ``print_nth``-th as ``publishing #N: <repr>``, then keep the node
    ``keep_alive`` s for the messages to reach the wire. Returns the number published."""
    out = sys.stdout if out is None else out
    pub = s.node.create_publisher(cls, node_name(topic), 10 if qos is None else qos)
    start = last_log = None
    while pub.get_subscription_count() < wait_matching:
        now = time.monotonic()
        start = now if start is None else start
        if last_log is None or now - last_log >= 1.0:
            print(f"Waiting for at least {wait_matching} matching subscription(s)...", file=out, flush=True)
            last_log = now
        if max_wait is not None and now - start >= max_wait:
            raise ToolError(f"Timed out waiting for subscribers: expected {wait_matching} subscribers but "
                            f"only got {pub.get_subscription_count()}")
        s.executor.spin_once(timeout_sec=0.1)
    print("publisher: beginning loop", file=out, flush=True)
    count = 0
    due = time.monotonic()
    while times == 0 or count < times:
        now = time.monotonic()
        if now < due:
            s.executor.spin_once(timeout_sec=min(due - now, 0.1))
            continue
        if stamps:
            stamp = s.node.get_clock().now().to_msg()
            for set_stamp in stamps:
                set_stamp(stamp)
        count += 1
        if print_nth and count % print_nth == 0:
            print(f"publishing #{count}: {msg!r}\n", file=out, flush=True)
        pub.publish(msg)
        due = max(due + period, now)
    time.sleep(keep_alive)
    return count
