"""Where the HOAP-2 controller comes from: its learning settings and the learned CPG file.

One home for the lookups every consumer shares (cpg_node, ``cpg-walker cpg-walk``/``walk``/``learn``,
the benchmarks): ``learning_settings`` reads config/cpg_humanoid_learning.yaml, ``cpg_defaults`` the
walk's defaults (cpg_node's parameters file config/cpg.yaml: cpg_file, zeta, alpha), ``resolve_cpg_file``
turns a ``cpg_file`` value into a path, ``load_controller`` loads it or learns at start-up.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from cpg_walker.cpg.network import CPGParams
from cpg_walker.errors import InputError
from cpg_walker.paths import config_path, ros_parameters
from cpg_walker.walker import storage
from cpg_walker.walker.controller import HumanoidCPG, HumanoidSettings
from cpg_walker.walker.live_teaching import LiveTeachingConfig

LEARNING_CONFIG = "cpg_humanoid_learning.yaml"
#: The packaged learned CPG's name in config/ (``cpg-walker learn`` writes it; with --install into the
#: package). Which CPG a walk loads by default is cpg_node's ``cpg_file`` parameter (``cpg_defaults``).
DEFAULT_CPG_FILE = "cpg_humanoid.yaml"
#: The cpg node's name: its parameters (config/cpg.yaml) are the defaults of every walk.
CPG_NODE = "cpg"


def cpg_defaults() -> dict:
    """cpg_node's parameters from config/cpg.yaml (``cpg_file``, ``zeta``, ``alpha``, ...), flattened as
    ROS does: the defaults of the graph walk and of the in-process walk alike."""
    return ros_parameters("cpg.yaml", CPG_NODE)


def load_learning_config(path: str | Path | None = None) -> dict:
    """config/cpg_humanoid_learning.yaml (or ``path``) as a dict with 'cpg' and 'humanoid' sections."""
    path = config_path(LEARNING_CONFIG) if path is None else Path(path)
    with open(path, encoding="utf-8") as fh:
        cfg = yaml.safe_load(fh)
    if not isinstance(cfg, dict) or "humanoid" not in cfg or "cpg" not in cfg:
        raise InputError(f"{path}: expected 'cpg' and 'humanoid' sections")
    return cfg


def learning_settings(n_oscillators: int | None = None,
                      cfg: dict | None = None) -> tuple[HumanoidSettings, CPGParams]:
    """HumanoidSettings and CPGParams from the learning YAML (N overridable)."""
    cfg = cfg or load_learning_config()
    h = dict(cfg["humanoid"])
    if n_oscillators is not None:
        h["n_oscillators"] = n_oscillators
    settings = HumanoidSettings.from_mapping(h, LEARNING_CONFIG)
    params = CPGParams(**{k: float(v) for k, v in cfg["cpg"].items()}, amplitude_time_constant=0.0)
    return settings, params


def live_teaching_config(cfg: dict | None = None) -> LiveTeachingConfig:
    """The learning YAML's ``live`` section: how cpg_node judges a teaching stream."""
    cfg = cfg or load_learning_config()
    return LiveTeachingConfig.from_mapping(dict(cfg.get("live") or {}), LEARNING_CONFIG)


def resolve_cpg_file(cpg_file: str | Path) -> Path:
    """A learned-CPG file: an existing path as given, else a bare name in the package's config/."""
    path = Path(cpg_file)
    if not path.is_file() and not path.is_absolute() and len(path.parts) == 1:
        try:
            return config_path(str(path))
        except FileNotFoundError:
            pass
    if not path.is_file():
        raise FileNotFoundError(f"learned CPG file not found: {path} (run 'cpg-walker learn --out DIR')")
    return path


def load_controller(cpg_file: str | Path | None,
                    n_oscillators: int | None = None) -> tuple[HumanoidCPG, str, bool]:
    """(controller, where it came from, learning converged). ``cpg_file`` None or '' learns now from the
    recorded walk with ``n_oscillators`` (default: the learning YAML's N); a file whose N differs from a
    requested ``n_oscillators`` is an error."""
    if cpg_file:
        path = resolve_cpg_file(cpg_file)
        ctrl = storage.load(path)  # ValueError naming the file and the bad field if corrupt
        if n_oscillators is not None and ctrl.net.N != n_oscillators:
            raise InputError(f"{path} has {ctrl.net.N} oscillators per DOF, {n_oscillators} were asked for")
        return ctrl, str(path), bool(ctrl.meta.get("learning", {}).get("converged", True))
    cfg = load_learning_config()
    settings, params = learning_settings(n_oscillators, cfg)
    ctrl, report = HumanoidCPG.learn(cfg.get("gait", "walk"), settings, params)
    origin = f"learned at start-up (N={ctrl.net.N}, {report.wall_time_s:.1f} s)"
    return ctrl, origin, bool(report.converged)
