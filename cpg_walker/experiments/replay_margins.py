"""Margins of the in-process replay: one parameter at a time around the nominal configuration (leg/body
kp and kd, floor friction, control delay, armature), both recorded gaits, 30 s each; writes JSON + PNG.

A point "walks" when the robot has not fallen after the full duration and moved forward at a mean speed of
at least MIN_SPEED_MPS (0.5 m in 30 s; a third of the slow walk's speed).
"""

from __future__ import annotations

import json
from pathlib import Path

from cpg_walker.robot.gait_data import GaitPlayback, load_gait
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.pid import PidLaw, load_pid_config
from cpg_walker.walker.loop import control_period, run_replay

SWEEPS: dict[str, list[float]] = {
    "kp": [40, 60, 80, 100, 130, 160, 200, 250, 300],
    "kd": [1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0],
    "friction": [0.3, 0.5, 0.7, 1.0, 1.3, 1.6, 2.0],
    "delay_s": [0.0, 0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.008],
    "armature": [0.0, 0.003, 0.005, 0.01, 0.02, 0.04],
}
QUICK: dict[str, list[float]] = {"kp": [60, 100, 200], "delay_s": [0.0, 0.004]}
MIN_SPEED_MPS = 0.5 / 30.0


def run_point(
    gait: str, param: str | None = None, value: float | None = None, duration: float = 30.0
) -> dict:
    """One replay with ``param`` set to ``value`` (None: the nominal configuration)."""
    sim_cfg: dict = {}  # overrides of hoap2.xml's physics
    pid_cfg = load_pid_config()
    delay = None  # run_replay's default: one control period
    if param in ("kp", "kd"):
        for group in ("leg", "body"):
            pid_cfg[f"{param}.{group}"] = float(value)
    elif param == "delay_s":
        delay = float(value)
    elif param in ("friction", "armature"):
        sim_cfg[param] = float(value)
    elif param is not None:
        raise ValueError(f"unknown sweep parameter {param!r}")
    sim = Hoap2Sim(sim_cfg)
    source = GaitPlayback(load_gait(gait))
    pid = PidLaw.from_config(config=pid_cfg)
    result = run_replay(sim, source, pid, duration, delay_s=delay)
    m = result.metrics
    keys = ("fell", "fall_time_s", "distance_m", "lateral_drift_m", "heading_change_deg")
    walks = (not m["fell"]) and m["distance_m"] > MIN_SPEED_MPS * duration
    return {"gait": gait, "param": param, "value": value, "walks": walks, **{k: m[k] for k in keys}}


def run_margins(out_dir: str | Path, quick: bool = False, duration: float = 30.0, progress=None) -> dict:
    """Sweep every parameter of SWEEPS (QUICK if ``quick``) for both gaits; write margins.json/png."""
    sweeps = QUICK if quick else SWEEPS
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    points: list[dict] = []
    total = 2 * sum(len(v) for v in sweeps.values())
    for param, values in sweeps.items():
        for value in values:
            for gait in ("walk", "slow"):
                points.append(run_point(gait, param, value, duration))
                if progress is not None:
                    progress.update(len(points))
    ranges = {}
    for param, values in sweeps.items():
        ok = [v for v in values if all(p["walks"] for p in points if p["param"] == param and p["value"] == v)]
        ranges[param] = {"both_walk": ok, "tested": values}
    nominal = {"physics": Hoap2Sim().physics(), "control_period_s": control_period(),
               "delay_s": control_period()}
    report = {"duration_s": duration, "sim": nominal, "pid": load_pid_config(), "ranges": ranges,
              "points": points, "total": total}
    (out / "margins.json").write_text(json.dumps(report, indent=2) + "\n")
    _plot(points, sweeps, out / "margins.png")
    return report


def _plot(points: list[dict], sweeps: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(sweeps), figsize=(3.2 * len(sweeps), 3.0), squeeze=False)
    for ax, (param, _values) in zip(axes[0], sweeps.items(), strict=True):
        for gait, marker in (("walk", "o"), ("slow", "s")):
            pts = [p for p in points if p["param"] == param and p["gait"] == gait]
            xs = [p["value"] for p in pts]
            ys = [p["distance_m"] for p in pts]
            colors = ["tab:green" if p["walks"] else "tab:red" for p in pts]
            ax.plot(xs, ys, color="0.6", lw=0.8)
            ax.scatter(xs, ys, c=colors, marker=marker, label=gait, zorder=3)
        ax.set_xlabel(param)
        ax.set_title(f"{param} (green = 30 s walk)", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("distance in 30 s [m]")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
