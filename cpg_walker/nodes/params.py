"""Node parameters as data: a ParamSpec per parameter (name, type, description, range, read-only) is the
one place a parameter is described; from a node's tuple of specs come its declaration (``declare_params``:
the ParameterDescriptor with the range, the value from config/<node>.yaml), the check of a new value
(``check``) and its reference page (cpg_walker.graph.reference).

A node declares its parameters with ``values = declare_params(self, SPECS)`` and reads them from the
returned dict (name -> value)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from cpg_walker.paths import config_path

if TYPE_CHECKING:
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


#: The run statistics every node writes at exit (runtime.exit_stats): read by the graph tooling
#: (graph/processes.py ``Graph.stats``), never parsed from the log.
STATS = (
    string("stats_file", "write the node's run statistics here as JSON at exit (a temporary file renamed "
           "into place); '' = none", read_only=True),
)


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS ParameterDescriptor of ``spec`` (type, description, read_only, range)."""
    if spec.type == "double":
        return float_param(spec.description, spec.lo, spec.hi, read_only=spec.read_only)
    if spec.type == "integer":
        return int_param(spec.description, spec.lo, spec.hi, read_only=spec.read_only)
    make = {"bool": bool_param, "string": str_param, "double_array": floats_param,
            "string_array": strs_param}[spec.type]
    return make(spec.description, read_only=spec.read_only)


def declare_params(node: Node, specs: tuple[ParamSpec, ...] | list[ParamSpec]) -> dict[str, object]:
    """Declare each spec on ``node`` in order (``declare``: the value from the parameters file given,
    else the packaged config/<node>.yaml; none: a ValueError naming the parameter and the file) and
    return name -> value."""
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
           "<!-- generated by `python -m cpg_walker.graph.reference --out docs/reference`: do not edit -->",
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


# ---------------------------------------------------------------- declaring
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


def name_refusals(node: Node, explain=None) -> None:
    """Make every refused parameter change say why, naming the parameter: rclpy's own checks answer a wrong
    type ("Wrong parameter type, expected ...") or an undeclare without the name, and a descriptor's range
    only "out of range", so a client setting several at once could not tell which or why. ``explain(name,
    value)`` (str, or None: nothing to add) gives the reason where it says more than rclpy's check; a
    reason that does not name a parameter gets the names in front. Wraps the node's
    ``set_parameters_atomically`` (what the set_parameters services call) once; a later call only sets
    ``explain``."""
    if explain is not None:
        node._refusal_explain = explain
    if getattr(node, "_refusals_named", False):
        return
    node._refusals_named = True
    plain = node.set_parameters_atomically

    def set_parameters_atomically(parameters):
        result = plain(parameters)
        if not result.successful:
            say = getattr(node, "_refusal_explain", None)
            why = [r for p in parameters if (r := say(p.name, p.value))] if say else []
            if why:
                result.reason = "; ".join(why)
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
