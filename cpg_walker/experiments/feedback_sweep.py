"""Feedback sweep (paper Sec. IV): walk 40 s at several ζ, open loop vs the feedback pathways of
cpg/feedback.py, with ζ commanded at 10 s (after the hand-over at ζ = 1) and from the start.

`cpg-walker feedback-sweep --out DIR` writes DIR/feedback_sweep.json (one row per run: ζ, mode,
condition, fell/fall time, distance, speed, heading change) and DIR/feedback_sweep.png (distance and
mean speed vs ζ per condition, falls marked with ×). `--calibrate` first measures the pitch reference and
the right-touchdown phase at ζ = 1 (observing only) and prints them (config/feedback.yaml holds them).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from cpg_walker.experiments.cpg_walk import walk
from cpg_walker.walker.feedback import PAPER_PATHWAYS, FeedbackConfig, FeedbackController, default_pathways
from cpg_walker.walker.learning import cpg_defaults, load_controller

ZETAS = (0.8, 1.0, 1.1, 1.2, 1.3, 1.5)
#: condition name -> (pathways, config overrides); "off" = open loop (no observe at all)
CONDITIONS: dict[str, tuple[tuple[str, ...], dict]] = {
    "off": ((), {}),
    "paper": (PAPER_PATHWAYS, {}),  # eqs 14-15 (|psi|), 18, reset
    "signed+pendulum+reset": (PAPER_PATHWAYS, {"lateral_mode": "signed"}),  # beyond the paper
    "reset": (("reset",), {}),
    "ours": (default_pathways(), {}),  # config/feedback.yaml's default pathways
}
SCHEDULE_AT_S = 10.0


def one_walk(ctrl, zeta: float, mode: str, pathways: tuple[str, ...] | None, overrides: dict | None = None,
             duration: float = 40.0) -> dict:
    """One walk; mode "at10" (ζ commanded at 10 s) or "start" (ζ from the start); pathways None = off."""
    fb = None if pathways is None else FeedbackController(FeedbackConfig.load(**(overrides or {})), pathways)
    if mode == "start":
        return walk(ctrl, duration, zeta=zeta, feedback=fb)
    return walk(ctrl, duration, zeta=1.0, schedule=[(SCHEDULE_AT_S, zeta, 1.0)], feedback=fb)


def calibrate(ctrl) -> dict:
    m = one_walk(ctrl, 1.0, "at10", (), None)
    return {"pitch_mean_rad": m["tilt_after_handover"]["pitch_mean_rad"],
            "right_touchdown_phase_rad": m["right_touchdown_phase_rad"],
            "roll_abs_mean_rad": m["tilt_after_handover"]["roll_abs_mean_rad"]}


def run_sweep(out_dir: str, zetas=ZETAS, conditions: list[str] | None = None, duration: float = 40.0,
              do_calibrate: bool = False, log=print) -> dict:
    ctrl, origin, _ = load_controller(cpg_defaults()["cpg_file"])
    conds = conditions or list(CONDITIONS)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report: dict = {"cpg_file": origin, "duration_s": duration, "schedule_at_s": SCHEDULE_AT_S,
                    "feedback_config": FeedbackConfig.load().__dict__, "rows": []}
    if do_calibrate:
        report["calibration"] = calibrate(ctrl)
        log(json.dumps(report["calibration"]))
    for mode in ("at10", "start"):
        for z in zetas:
            for c in conds:
                paths, ov = CONDITIONS[c]
                t0 = time.perf_counter()
                m = one_walk(ctrl, z, mode, None if c == "off" else paths, ov, duration)
                row = {"zeta": z, "mode": mode, "condition": c, "fell": m["fell"],
                       "fall_time_s": m["fall_time_s"], "distance_m": m["distance_m"],
                       "mean_speed_mps": m["mean_speed_mps"], "heading_change_deg": m["heading_change_deg"],
                       "lateral_drift_m": m["lateral_drift_m"], "phase_resets": m.get("phase_resets", 0),
                       "wall_s": round(time.perf_counter() - t0, 2)}
                report["rows"].append(row)
                log(json.dumps(row))
    (out / "feedback_sweep.json").write_text(json.dumps(report, indent=2) + "\n")
    report["png"] = str(plot(report, out / "feedback_sweep.png"))
    return report


def plot(report: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = report["rows"]
    conds = list(dict.fromkeys(r["condition"] for r in rows))
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    for j, mode in enumerate(("at10", "start")):
        for i, key in enumerate(("distance_m", "mean_speed_mps")):
            ax = axes[i, j]
            for k, c in enumerate(conds):
                rs = [r for r in rows if r["mode"] == mode and r["condition"] == c]
                zs = [r["zeta"] + 0.012 * (k - len(conds) / 2) for r in rs]
                line, = ax.plot(zs, [r[key] for r in rs], "-o", ms=4, label=c)
                fz = [(z, r[key]) for z, r in zip(zs, rs, strict=True) if r["fell"]]
                if fz:
                    ax.plot(*zip(*fz, strict=True), "x", ms=11, mew=2.5, color=line.get_color())
            ax.set_ylabel(key)
            ax.grid(alpha=0.3)
            if i == 0:
                when = f"commanded at {report['schedule_at_s']:g} s" if mode == "at10" else "from start"
                ax.set_title(f"zeta {when} ({report['duration_s']:g} s walks; x = fell)")
            else:
                ax.set_xlabel("zeta")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
