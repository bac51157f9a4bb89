"""cpg_node's feedback and /cmd_vel parameters: their declarations (values in config/cpg.yaml; the feedback
constants' defaults in config/feedback.yaml) and the checks of a value set at run time (ValueError with
the reason, naming the parameter)."""

from __future__ import annotations

from dataclasses import asdict, fields
from typing import get_type_hints

from cpg_walker.nodes.runtime import (
    bool_param,
    declare,
    float_param,
    packaged_parameters,
    str_param,
    strs_param,
)
from cpg_walker.nodes.validation import check_finite_scalar
from cpg_walker.walker import feedback as feedback_core
from cpg_walker.walker.cmd_vel import LIMIT_KEYS, CmdVelLimits, SpeedMap
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig

#: The float ``cmd_vel.*`` parameters: (key, description, min, max); their values: config/cpg.yaml.
CMD_VEL_PARAMS = (
    ("timeout", "sim s without a /cmd_vel message before stepping stops (alpha -> 0)", 0.01, 60.0),
    ("max_linear_x", "largest forward linear.x followed (m/s; larger is clamped)", 0.0, 1.0),
    ("min_linear_x", "most negative (backward) linear.x followed (m/s; smaller is clamped)", -1.0, 0.0),
    ("max_angular_z", "largest |angular.z| followed (rad/s; larger is clamped)", 0.0, 1.0),
    ("stand_below", "|linear.x| below this (m/s): stand (alpha 0)", 0.0, 0.1),
    ("alpha_fall_rate", "the alpha command falls at most this much per sim s (a stop takes 1/rate s)",
     0.01, 100.0),
)
assert tuple(k for k, *_ in CMD_VEL_PARAMS) == LIMIT_KEYS
#: The feedback's float parameters set at run time: name -> (min, max).
FEEDBACK_RANGES = {"sensor_timeout": (1e-3, 10.0), "feedback_fade": (0.0, 60.0), "sensor_wait": (1e-3, 60.0)}
#: FeedbackConfig field types exposed as ROS parameters, and their parameter descriptors' makers.
FIELD_PARAMS = {float: float_param, str: str_param, bool: bool_param}


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


def config_fields() -> dict[str, type]:
    """FeedbackConfig's fields of a type that is a ROS parameter (the ``feedback.<field>`` parameters)."""
    hints = get_type_hints(FeedbackConfig)
    return {f.name: hints[f.name] for f in fields(FeedbackConfig) if hints.get(f.name) in FIELD_PARAMS}


def field_value(name: str, value: object) -> object:
    """A ``feedback.<name>`` value checked for its field's type (floats finite)."""
    kind = config_fields()[name]
    if kind is float:
        return check_finite_scalar(f"feedback.{name}", value)
    if not isinstance(value, kind):
        raise ValueError(f"feedback.{name} must be a {kind.__name__}, got {type(value).__name__}")
    return value


def declare_feedback(node) -> tuple[FeedbackConfig, tuple[str, ...], dict[str, float]]:
    """Declare ``feedback_pathways``, ``sensor_timeout``, ``feedback_fade``, ``sensor_wait`` and
    ``feedback.<field>`` for every FeedbackConfig field of a plain type, its default the value in
    config/feedback.yaml (the one home; the node's parameters file may override it). Returns the config,
    the pathways and the three float settings, validated (ValueError with the reason)."""
    packaged = packaged_parameters(node)  # a bare start: the packaged params file's overrides
    node.declare_parameter("feedback_pathways", list(packaged.get(
        "feedback_pathways", feedback_core.default_pathways())), strs_param(
        f"feedback pathways in use, any of {', '.join(PATHWAYS)}"))
    pathways = pathway_list(node.get_parameter("feedback_pathways").value)
    texts = {"sensor_timeout": "sim s without a newer /imu or /foot_load sample before feedback fades out",
             "feedback_fade": "sim s over which feedback fades out (stale sensors, switched off) or back in",
             "sensor_wait": "lockstep: wall s to wait for a tick's sensor samples before going on with the "
                            "newest"}
    settings = {name: check_finite_scalar(name, declare(node, name, float_param(texts[name], lo, hi)), lo, hi)
                for name, (lo, hi) in FEEDBACK_RANGES.items()}
    defaults = FeedbackConfig.load()
    for name, kind in config_fields().items():
        default = packaged.get(f"feedback.{name}", getattr(defaults, name))
        node.declare_parameter(f"feedback.{name}", kind(default), FIELD_PARAMS[kind](
            f"FeedbackConfig.{name} (walker/feedback.py; default in config/feedback.yaml)"))
    values = {name: field_value(name, node.get_parameter(f"feedback.{name}").value)
              for name in config_fields()}
    return FeedbackConfig.load(**values), pathways, settings


def declare_cmd_vel(node) -> tuple[bool, CmdVelLimits, SpeedMap]:
    """Declare the ``cmd_vel.*`` parameters (config/cpg.yaml): follow, the limits, the speed map."""
    follow = bool(declare(node, "cmd_vel.follow", bool_param(
        "follow /cmd_vel from its first message on (false: ignore it; zeta/alpha parameters only)")))
    lim = {k: declare(node, f"cmd_vel.{k}", float_param(text, lo, hi)) for k, text, lo, hi in CMD_VEL_PARAMS}
    map_file = declare(node, "cmd_vel.speed_map", str_param(
        "measured speed vs zeta/alpha for linear.x (a path, or a name in the package's config/)"))
    return follow, CmdVelLimits(**{k: float(v) for k, v in lim.items()}), load_speed_map(map_file)


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
