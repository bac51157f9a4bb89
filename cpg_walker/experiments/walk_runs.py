"""One in-process walk described by data, and many of them in parallel: the engine of `cpg-walker sweep`
and `cpg-walker feedback-search`.

A ``WalkSpec`` says what to run (ζ, α, when they are commanded, the feedback variant — pathway names and
FeedbackConfig overrides, by name, so new pathways and fields need no code here —, floor friction scale,
a lateral push); ``run_walk`` runs it with walker.loop.run_replay and a (Feedback)CPGGaitSource and
returns its metrics measured over the *window* from the command to the end; ``run_many`` maps specs over
a process pool with progress on stderr.

Starts: ``"standing"`` — the robot starts standing and ζ, α are requested at t = 0 (the gait source
applies them as soon as it can: with the "recording" transition when the hand-over cross-fade ends);
``"at_<T>s"`` (e.g. "at_10s") — the walk starts at ζ = α = 1 and ζ, α are commanded at T s.
"""

from __future__ import annotations

import copy
import math
import os
import re
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.walker.feedback import PAPER_PATHWAYS, FeedbackConfig, FeedbackController, default_pathways
from cpg_walker.walker.gait_source import CPGGaitSource, FeedbackGaitSource
from cpg_walker.walker.governor import GovernorConfig
from cpg_walker.walker.learning import cpg_defaults, load_controller
from cpg_walker.walker.loop import heading_at

#: the paper's lateral law as printed (eqs 14-15 with |psi|)
PAPER_OVERRIDES = {"lateral_mode": "abs"}
_START = re.compile(r"^at_(\d+(?:\.\d+)?)s$")


def variant(name: str) -> tuple[tuple[str, ...] | None, dict]:
    """(pathways, FeedbackConfig overrides) of a named variant: off (no feedback), paper (the three
    pathways of Sec. III-B as printed), ours (config/feedback.yaml's default pathways)."""
    if name == "off":
        return None, {}
    if name == "paper":
        return PAPER_PATHWAYS, dict(PAPER_OVERRIDES)
    if name == "ours":
        return default_pathways(), {}
    raise InputError(f"unknown feedback variant {name!r}; use off, paper or ours")


def start_time(start: str) -> float:
    """Sim time (s) at which ζ, α are requested: 0 for "standing", T for "at_Ts"."""
    if start == "standing":
        return 0.0
    m = _START.match(start)
    if not m:
        raise InputError(f"start {start!r}: use 'standing' or 'at_<T>s' (e.g. 'at_10s')")
    return float(m.group(1))


@dataclass(frozen=True)
class Push:
    """A horizontal push on the torso at ``at_s`` (sim s), perpendicular to the robot's heading then
    (``direction`` +1 = to its left, −1 = to its right): impulse ``impulse_ns`` (N s) spread over
    ``duration_s``."""

    at_s: float
    impulse_ns: float
    duration_s: float = 0.1
    direction: float = 1.0


@dataclass(frozen=True)
class WalkSpec:
    """One walk. ``variant`` names the feedback ("off", "paper", "ours" or any label when ``pathways`` is
    given); ``pathways``/``overrides`` (FeedbackConfig field -> value) override the variant's."""

    zeta: float = 1.0
    alpha: float = 1.0
    start: str = "standing"
    duration_after_s: float = 60.0  # walked after the command (the window the metrics cover)
    variant: str = "ours"
    pathways: tuple[str, ...] | None = None
    overrides: dict = field(default_factory=dict)
    friction_scale: float = 1.0
    push: Push | None = None
    schedule: tuple[tuple[float, float, float], ...] = ()  # further (t, ζ, α) commands
    transition: str = "recording"
    segments: tuple[tuple[float, float], ...] = ()  # extra (from, to) sim-s windows to measure
    record_targets: bool = False  # keep the CPG DOFs' targets (Fig. 8)
    label: str = ""
    governed: bool = False  # the governor between the commands and the CPG, as in cpg_node (False: the raw
    #                         controller, what the sweeps measure)

    def feedback(self) -> tuple[tuple[str, ...] | None, dict]:
        paths, ov = variant(self.variant) if self.pathways is None else (tuple(self.pathways), {})
        return paths, {**ov, **self.overrides}

    def as_dict(self) -> dict:
        d = asdict(self)
        d["schedule"] = [list(s) for s in self.schedule]
        d["segments"] = [list(s) for s in self.segments]
        d.pop("record_targets")
        return d


_CTRL: dict[str, Any] = {}


def _controller():
    """A fresh copy of the default learned CPG (loaded once per process)."""
    from cpg_walker.walker import storage

    if "ctrl" not in _CTRL:
        ctrl, _CTRL["origin"], _ = load_controller(cpg_defaults()["cpg_file"])
        _CTRL["ctrl"] = storage.to_dict(ctrl)
    return storage.from_dict(copy.deepcopy(_CTRL["ctrl"]))


class _Recorder:
    """Wraps a target source; keeps the CPG DOFs' targets every ``every_s`` (sim s)."""

    def __init__(self, source, idx: np.ndarray, every_s: float = 0.01):
        self._s, self._idx, self._every = source, idx, every_s
        self.names = source.names
        self.rows: list[np.ndarray] = []
        self._next = 0.0
        if hasattr(source, "observe"):
            self.observe = source.observe

    def targets(self, t: float):
        q, qd = self._s.targets(t)
        if t >= self._next - 1e-9:
            self.rows.append(np.concatenate([[t], q[self._idx]]))
            self._next = t + self._every
        return q, qd


def run_walk(spec: WalkSpec) -> dict:
    """Run ``spec``; the metrics (see module docstring) plus the spec. Metrics cover the window
    [t_cmd, end] (t_cmd = start_time(spec.start)): distance along, drift across and heading change
    relative to the pose at t_cmd, mean speed over the window, ``steady_speed_mps`` over its second
    half, step length (window distance / touchdowns in it), mean |torque| over the 10 CPG-driven
    joints, fall time counted from t = 0. ``friction_scale`` multiplies the floor's sliding friction and
    sets every geom to it (Hoap2Sim's ``friction``; hoap2.xml gives all geoms the floor's value)."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.joints import JOINT_NAMES
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.controller import DOFS
    from cpg_walker.walker.loop import run_replay

    t_cmd = start_time(spec.start)
    if not (spec.duration_after_s > 0 and spec.friction_scale > 0):
        raise ValueError("walk: duration_after_s and friction_scale must be positive")
    duration = t_cmd + spec.duration_after_s
    ctrl = _controller()
    paths, ov = spec.feedback()
    sched = list(spec.schedule)
    kw: dict = {"transition": spec.transition}
    if spec.start == "standing":
        kw.update(zeta=spec.zeta, alpha=spec.alpha)
    else:
        sched.append((t_cmd, spec.zeta, spec.alpha))
    kw["schedule"] = sched
    kw["governor"] = GovernorConfig.load() if spec.governed else None
    fb = None
    if paths is None:
        source = CPGGaitSource(ctrl, **kw)
    else:
        fb = FeedbackController(FeedbackConfig.load(**ov), paths)
        source = FeedbackGaitSource(ctrl, fb, **kw)
    sim_cfg = {}
    if spec.friction_scale != 1.0:
        sim_cfg["friction"] = Hoap2Sim().physics()["friction"] * spec.friction_scale
    sim = Hoap2Sim(sim_cfg)
    sim.reset()
    idx = np.array([JOINT_NAMES.index(j) for j in DOFS])
    rec = _Recorder(source, idx) if spec.record_targets else None
    torque: list[float] = []
    pushed = {"done": spec.push is None}

    def on_log(s: Hoap2Sim) -> None:
        t = s.time
        if t >= t_cmd:
            torque.append(float(np.mean(np.abs(s.data.ctrl[s._act[idx]]))))
        if not pushed["done"] and t >= spec.push.at_s:
            h = s.heading()
            f = spec.push.direction * spec.push.impulse_ns / spec.push.duration_s
            s.apply_push([-math.sin(h) * f, math.cos(h) * f, 0.0], spec.push.duration_s)
            pushed["done"] = True

    r = run_replay(sim, rec or source, PidLaw.from_config(), duration, on_log=on_log)
    m = window_metrics(r, t_cmd)
    m.update({"fell": bool(r.fell), "fall_time_s": None if r.fall_time_s is None else round(r.fall_time_s, 3),
              "duration_s": round(float(r.duration_s), 3), "t_cmd_s": t_cmd,
              "mean_abs_torque_Nm": round(float(np.mean(torque)), 4) if torque else None,
              "feedback": paths is not None, "pathways": None if paths is None else list(paths),
              "phase_resets": len(fb.resets) if fb is not None else 0})
    m.update(zeta=spec.zeta, alpha=spec.alpha, start=spec.start, variant=spec.variant, spec=spec.as_dict())
    if spec.segments:
        m["segments"] = [{"from_s": a, "to_s": b, **window_metrics(r, a, b)} for a, b in spec.segments]
    if rec is not None:
        m["targets"] = {"names": list(DOFS), "rows": np.array(rec.rows).round(5).tolist()}
    return m


def window_metrics(r, t0: float, t1: float | None = None) -> dict:
    """Distance, drift, heading change, speeds and step length of ReplayResult ``r`` from sim time t0 to
    t1 (None: the end; a fall ends it earlier). Heading change: walker.loop.heading_at (the yaw averaged
    over a stride) at the end minus at t0."""
    if t1 is not None:
        n = max(1, int(np.searchsorted(r.t, t1, side="right")))
        r = copy.copy(r)
        r.t, r.base_xy, r.heading = r.t[:n], r.base_xy[:n], r.heading[:n]
        r.touchdowns = {k: [x for x in v if x <= t1] for k, v in r.touchdowns.items()}
    i0 = min(int(np.searchsorted(r.t, t0)), len(r.t) - 1)
    h0 = heading_at(r, float(r.t[i0]))
    fwd = np.array([math.cos(h0), math.sin(h0)])
    left = np.array([-math.sin(h0), math.cos(h0)])
    d = r.base_xy[-1] - r.base_xy[i0]
    span = float(r.t[-1] - r.t[i0])
    im = min(int(np.searchsorted(r.t, r.t[i0] + span / 2)), len(r.t) - 1)
    half = float(r.t[-1] - r.t[im])
    steps = sum(1 for side in ("left", "right") for x in r.touchdowns[side] if x > r.t[i0])
    dist = float(d @ fwd)
    return {
        "window_s": round(span, 3),
        "distance_m": round(dist, 4),
        "lateral_drift_m": round(float(d @ left), 4),
        "heading_change_deg": round(math.degrees(heading_at(r, float(r.t[-1])) - h0), 2),
        "mean_speed_mps": round(dist / span, 4) if span > 0 else 0.0,
        "steady_speed_mps": round(float((r.base_xy[-1] - r.base_xy[im]) @ fwd) / half, 4) if half > 0
        else 0.0,
        "steps": steps,
        "step_length_m": round(dist / steps, 4) if steps else None,
    }


#: what a result_cell says, for the tables' captions
CELL_LEGEND = ("F t s (+d) = fell at sim time t, d s after the command; else speed over the window's second "
               "half, heading change (stride means) and lateral drift over the window")


def result_cell(m: dict) -> str:
    """One walk in a markdown table cell: "error", "F t s (+d)" (fell at sim time t, d s after the
    command), else speed over the window's second half, heading change and lateral drift."""
    if "error" in m:
        return "error"
    if m["fell"]:
        return f"F {m['fall_time_s']:.1f} s (+{m['fall_time_s'] - m['t_cmd_s']:.1f})"
    return f"{m['steady_speed_mps']:+.3f} m/s {m['heading_change_deg']:+.0f}° {m['lateral_drift_m']:+.2f} m"


def _safe(fn: Callable, item):
    try:
        return fn(item)
    except Exception as exc:  # a crashed run is reported, not fatal to the sweep
        return {"error": f"{type(exc).__name__}: {exc}"}


def run_many(fn: Callable, items: Iterable, jobs: int | None = None, progress=None) -> list:
    """``[fn(x) for x in items]`` over ``jobs`` processes (default os.cpu_count(); 1 = in this process),
    in order; ``progress.update(k)`` as each finishes. ``fn`` must be a module-level function."""
    items = list(items)
    jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    out: list = [None] * len(items)
    if jobs == 1 or len(items) <= 1:
        for k, x in enumerate(items):
            out[k] = _safe(fn, x)
            if progress is not None:
                progress.update(k + 1)
        return out
    import multiprocessing as mp
    from functools import partial

    with mp.get_context("spawn").Pool(min(jobs, len(items))) as pool:
        done = 0
        for k, res in pool.imap_unordered(partial(_indexed, fn), list(enumerate(items))):
            out[k] = res
            done += 1
            if progress is not None:
                progress.update(done)
    return out


def _indexed(fn: Callable, kx: tuple[int, Any]) -> tuple[int, Any]:
    return kx[0], _safe(fn, kx[1])
