"""cpg_node's parameters beyond the declaration from its specs (nodes/specs.py CPG, CPG_FEEDBACK): the
feedback family whose defaults are config/feedback.yaml's values, and the checks of values set at run
time (ValueError with the reason, naming the parameter)."""

from __future__ import annotations

from dataclasses import asdict

from cpg_walker.nodes.params import check, descriptor, packaged_parameters
from cpg_walker.nodes.specs import CPG_CMD_VEL_LIMITS, CPG_FEEDBACK
from cpg_walker.nodes.validation import check_finite_scalar
from cpg_walker.walker import feedback as feedback_core
from cpg_walker.walker.cmd_vel import LIMIT_KEYS, CmdVelLimits, SpeedMap
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig

assert tuple(s.name[len("cmd_vel."):] for s in CPG_CMD_VEL_LIMITS) == LIMIT_KEYS
#: ParamSpec type -> the Python type of a FeedbackConfig field's value.
_KIND = {"double": float, "string": str, "bool": bool}


def load_speed_map(name: object) -> SpeedMap:
    """``cmd_vel.speed_map``'s file as a SpeedMap, else ValueError with the reason."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"cmd_vel.speed_map must name a speed map file, got {name!r}")
    try:
        return SpeedMap.load(name)
    except FileNotFoundError as exc:
        raise ValueError(f"cmd_vel.speed_map: {exc}") from None


def pathway_list(value: object) -> tuple[str, ...]:
    """``feedback_pathways`` as a tuple of known, distinct names (the feedback core's rules too), else
    ValueError with the reason."""
    names = [str(v) for v in (value or [])]
    if not names:
        raise ValueError(f"feedback_pathways must name at least one of {list(PATHWAYS)} (feedback false: "
                         "none)")
    if len(set(names)) != len(names):
        raise ValueError(f"feedback_pathways names a pathway twice: {names}")
    return feedback_core.check_pathways(names)


def feedback_fields() -> dict[str, type]:
    """The ``feedback.<field>`` parameters: FeedbackConfig field name -> its value's type."""
    return {s.name[len("feedback."):]: _KIND[s.type] for s in CPG_FEEDBACK if s.name.startswith("feedback.")}


def field_value(name: str, value: object) -> object:
    """A ``feedback.<name>`` value checked for its field's type (floats finite)."""
    kind = feedback_fields()[name]
    if kind is float:
        return check_finite_scalar(f"feedback.{name}", value)
    if not isinstance(value, kind):
        raise ValueError(f"feedback.{name} must be a {kind.__name__}, got {type(value).__name__}")
    return value


def declare_feedback(node) -> tuple[FeedbackConfig, tuple[str, ...]]:
    """Declare CPG_FEEDBACK (``feedback_pathways`` and ``feedback.<field>``), each defaulting to
    config/feedback.yaml's value (the one home; the node's parameters file may override it); the config
    and the pathways, validated (ValueError with the reason)."""
    packaged = packaged_parameters(node)  # a bare start: the packaged params file's overrides
    defaults = {"feedback_pathways": list(feedback_core.default_pathways()),
                **{f"feedback.{k}": v for k, v in asdict(FeedbackConfig.load()).items()}}
    for spec in CPG_FEEDBACK:
        value = packaged.get(spec.name, defaults[spec.name])
        node.declare_parameter(spec.name, _KIND[spec.type](value) if spec.type in _KIND else value,
                               descriptor(spec))
    values = {name: field_value(name, node.get_parameter(f"feedback.{name}").value)
              for name in feedback_fields()}
    return FeedbackConfig.load(**values), pathway_list(node.get_parameter("feedback_pathways").value)


def check_value(spec, value: object) -> None:
    """ValueError with the reason when ``value`` does not fit ``spec``."""
    if reason := check(spec, value):
        raise ValueError(reason)


def check_cmd_vel(changes: dict[str, object], limits: CmdVelLimits) -> tuple[bool | None, CmdVelLimits,
                                                                              SpeedMap | None]:
    """``cmd_vel.<key>`` changes as (follow or None, the new limits, a new speed map or None)."""
    changes = dict(changes)
    follow = changes.pop("follow", None)
    if follow is not None and not isinstance(follow, bool):
        raise ValueError(f"cmd_vel.follow must be a bool, got {type(follow).__name__}")
    smap = load_speed_map(changes.pop("speed_map")) if "speed_map" in changes else None
    if changes:
        limits = CmdVelLimits(**{**limits.as_dict(),
                                 **{k: check_finite_scalar(f"cmd_vel.{k}", v) for k, v in changes.items()}})
    return follow, limits, smap


def check_feedback(changes: dict[str, object], cfg: FeedbackConfig) -> FeedbackConfig:
    """``feedback.<field>`` changes applied to ``cfg`` (FeedbackConfig's own reason for a value it
    refuses)."""
    values = {name: field_value(name, value) for name, value in changes.items()}
    return FeedbackConfig.load(**{**asdict(cfg), **values}) if values else cfg
