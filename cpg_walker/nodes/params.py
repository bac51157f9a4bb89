"""Node parameters as data: a ParamSpec per parameter (name, type, description, range, read-only) is the
one place a parameter is described; from a node's tuple of specs come its declaration (``declare_params``:
the ParameterDescriptor with the range, the value from config/<node>.yaml), the check of a new value
(``check``) and its reference page (cpg_walker.nodes.reference).

A node declares its parameters with ``values = declare_params(self, SPECS)`` and reads them from the
returned dict (name -> value)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node

#: ParamSpec.type values, as ROS names the parameter types.
TYPES = ("double", "integer", "bool", "string", "double_array", "string_array")


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter. ``lo``/``hi``: the inclusive range of a double or integer (both or neither;
    an integer always has one); ``read_only``: set at start-up only."""

    name: str
    type: str
    description: str
    lo: float | int | None = None
    hi: float | int | None = None
    read_only: bool = False

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"parameter {self.name!r}: type must be one of {TYPES}, got {self.type!r}")
        if (self.lo is None) != (self.hi is None):
            raise ValueError(f"parameter {self.name!r}: give both ends of the range or neither")
        if self.lo is not None and self.type not in ("double", "integer"):
            raise ValueError(f"parameter {self.name!r}: only a double or integer has a range")
        if self.type == "integer" and self.lo is None:
            raise ValueError(f"parameter {self.name!r}: an integer parameter needs a range")

    @property
    def range(self) -> tuple[float | int, float | int] | None:
        return None if self.lo is None else (self.lo, self.hi)


def double(name: str, description: str, lo: float | None = None, hi: float | None = None,
           read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "double", description, lo, hi, read_only)


def integer(name: str, description: str, lo: int, hi: int, read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "integer", description, lo, hi, read_only)


def boolean(name: str, description: str, read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "bool", description, read_only=read_only)


def string(name: str, description: str, read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "string", description, read_only=read_only)


def doubles(name: str, description: str, read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "double_array", description, read_only=read_only)


def strings(name: str, description: str, read_only: bool = False) -> ParamSpec:
    return ParamSpec(name, "string_array", description, read_only=read_only)


#: The OS scheduling parameters of a control node (runtime.declare_scheduling, runtime.apply_scheduling).
SCHEDULING = (
    integer("realtime_priority", "SCHED_FIFO priority (1-99) of the node's loop and middleware threads once "
            "started; 0 = normal scheduling. Needs root or CAP_SYS_NICE, else the nice value is tried", 0, 99,
            read_only=True),
    integer("nice", "niceness (-20..19) when no real-time priority is set or permitted; 0 = leave as started",
            -20, 19, read_only=True),
    integer("cpu_affinity", "CPUs the node's threads may run on, as a bit mask like taskset's (1 = CPU 0, "
            "2 = CPU 1, 3 = both); 0 = any", 0, 2**63 - 1, read_only=True),
)


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS ParameterDescriptor of ``spec`` (type, description, read_only, range)."""
    from cpg_walker.nodes import runtime

    if spec.type == "double":
        return runtime.float_param(spec.description, spec.lo, spec.hi, read_only=spec.read_only)
    if spec.type == "integer":
        return runtime.int_param(spec.description, spec.lo, spec.hi, read_only=spec.read_only)
    make = {"bool": runtime.bool_param, "string": runtime.str_param, "double_array": runtime.floats_param,
            "string_array": runtime.strs_param}[spec.type]
    return make(spec.description, read_only=spec.read_only)


def declare_params(node: Node, specs: tuple[ParamSpec, ...] | list[ParamSpec]) -> dict[str, object]:
    """Declare each spec on ``node`` in order (runtime.declare: the value from the parameters file given,
    else the packaged config/<node>.yaml; none: a ValueError naming the parameter and the file) and
    return name -> value."""
    from cpg_walker.nodes.runtime import declare

    return {spec.name: declare(node, spec.name, descriptor(spec)) for spec in specs}


def by_name(specs) -> dict[str, ParamSpec]:
    return {spec.name: spec for spec in specs}


def check(spec: ParamSpec, value: object) -> str | None:
    """None when ``value`` fits ``spec`` (type, finite, in range); else the reason, naming the parameter
    (for an on-set callback's SetParametersResult)."""
    if spec.type == "bool":
        ok = isinstance(value, bool)
    elif spec.type == "integer":
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif spec.type == "double":
        ok = isinstance(value, int | float) and not isinstance(value, bool)
    elif spec.type == "string":
        ok = isinstance(value, str)
    elif spec.type == "string_array":
        ok = isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)
    else:  # double_array
        ok = isinstance(value, list | tuple) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    if not ok:
        return f"{spec.name} must be {_TYPE_TEXT[spec.type]}, got {value!r}"
    if spec.type in ("double", "double_array"):
        if not all(math.isfinite(v) for v in (value if spec.type == "double_array" else [value])):
            return f"{spec.name} must be finite, got {value!r}"
    if spec.range is not None and not spec.lo <= value <= spec.hi:
        return f"{spec.name} must be in {range_text(spec)}, got {value!r}"
    return None


_TYPE_TEXT = {"double": "a number", "integer": "an integer", "bool": "true or false", "string": "a string",
              "double_array": "a list of numbers", "string_array": "a list of strings"}


def range_text(spec: ParamSpec) -> str:
    """``[lo, hi]`` as the reference shows it; '' without a range."""
    if spec.range is None:
        return ""
    if spec.type == "integer":
        return f"[{spec.lo}, {spec.hi}]"
    return f"[{spec.lo:g}, {spec.hi:g}]"


def spec_of_descriptor(name: str, d) -> ParamSpec:
    """A ParamSpec read back from a declared parameter's ParameterDescriptor (for a node that does not
    declare from specs yet: cpg_node)."""
    from rcl_interfaces.msg import ParameterType as T

    kind = {T.PARAMETER_DOUBLE: "double", T.PARAMETER_INTEGER: "integer", T.PARAMETER_BOOL: "bool",
            T.PARAMETER_STRING: "string", T.PARAMETER_DOUBLE_ARRAY: "double_array",
            T.PARAMETER_STRING_ARRAY: "string_array"}[d.type]
    lo = hi = None
    if kind == "double" and d.floating_point_range:
        lo, hi = d.floating_point_range[0].from_value, d.floating_point_range[0].to_value
    elif kind == "integer" and d.integer_range:
        lo, hi = d.integer_range[0].from_value, d.integer_range[0].to_value
    return ParamSpec(name, kind, d.description, lo, hi, bool(d.read_only))


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_reference(iface, specs, source: str = "") -> str:
    """The Markdown reference of one node: its topics (from interface.INTERFACES' ``iface``, types from
    interface.TOPICS), services and parameter table (``specs``). ``source``: where the parameters were
    read from, when not from cpg_walker/nodes/specs.py."""
    from cpg_walker.nodes.interface import TOPICS

    out = [f"# {iface.executable} (node `/{iface.name}`)", "",
           "<!-- generated by `python -m cpg_walker.nodes.reference --out docs/reference`: do not edit -->",
           "",
           f"{iface.summary[0].upper()}{iface.summary[1:]}. Parameter values: `config/{iface.name}.yaml` "
           f"(`--params-file`; the packaged copy on a bare start).", "", "## Topics", ""]
    rows = [(what, TOPICS[name]) for what, names in (("subscribes", iface.subscribes),
                                                     ("publishes", iface.publishes)) for name in names]
    if rows:
        out += ["| direction | topic | type | durability | carries |", "|---|---|---|---|---|"]
        out += [f"| {what} | `{t.name}` | `{t.type}` | {'latched' if t.latched else 'volatile'} | "
                f"{_cell(t.description)} |" for what, t in rows]
        out.append("")
    if iface.note:
        out += [iface.note, ""]
    if iface.services:
        out += ["## Services", "", *(f"- `{s}` (std_srvs/srv/Trigger)" for s in iface.services), ""]
    out += ["## Parameters", ""]
    if source:
        out += [source, ""]
    out += ["| parameter | type | range | settable | description |", "|---|---|---|---|---|"]
    out += [f"| `{s.name}` | {s.type} | {range_text(s) or '-'} | "
            f"{'read-only' if s.read_only else 'at run time'} | {_cell(s.description)} |" for s in specs]
    return "\n".join(out) + "\n"
