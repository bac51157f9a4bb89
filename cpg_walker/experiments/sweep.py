"""`cpg-walker sweep`: issue 11's experiment (paper Sec. IV) as one reproducible command.

The grid is data, in config/sweep.yaml (``--quick``: its ``quick:`` section merged over it):

* ζ forward and backward × feedback variant (off / paper as printed / ours = config/feedback.yaml's
  default pathways) × start ("standing": requested at t = 0; "at_10s": commanded at 10 s), each walked
  ``duration_after_s`` after the command; metrics over that window (experiments/walk_runs.py);
* α sweep at ζ = 1 (step length and speed vs α; the paper: ≈ linear, α = 0 stops), and a walk whose α
  goes to 0 and back (stops, then resumes);
* the largest lateral push recovered at ζ = 1 per variant and direction: bisection on the impulse;
* the paper's Fig. 8: the Hip1, Ankle2, Ankle1, Knee targets at ζ = 1.2 with and without feedback.

A run's ``duration_s`` is the sim time walked from t = 0 (to the fall, if it fell), ``fall_time_s`` from
t = 0 too; ``window_s`` is the measured window. Every walk runs in a process pool (``jobs``). Writes
DIR/sweep.json (``{"runs": [...], "alpha": ..., "push": ..., "fig8": ...}``), DIR/sweep.md and the PNGs
speed_vs_zeta, fall_map, heading, alpha, fig8.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.experiments.config_file import Config, deep_merge
from cpg_walker.experiments.study import Engine, EngineSettings, study_options, task
from cpg_walker.experiments.walk_runs import (
    CELL_LEGEND,
    Push,
    WalkSpec,
    _safe,
    result_cell,
    run_walk,
    start_time,
    variant,
)
from cpg_walker.robot.joints import PAPER_LEG_DOFS

FIG8_DOFS = ("Hip1", "Ankle2", "Ankle1", "Knee")
#: |speed| below which a walk counts as stopped (α = 0): 1 cm/s, a tenth of the gait's speed
STOPPED_MPS = 0.01
FIG8_SIDE = "r"


def load_config(path: str | Path | None = None, quick: bool = False) -> dict:
    """config/sweep.yaml (or ``path``), validated; ``quick`` merges its ``quick:`` section."""
    from cpg_walker.paths import config_path

    c = Config(path or config_path("sweep.yaml"))
    base = {k: v for k, v in c.data.items() if k != "quick"}
    template = Config(config_path("sweep.yaml")).data if path else c.data
    template = {k: v for k, v in template.items() if k != "quick"}
    c.check_known(base, template)
    c.check_known(c.data.get("quick") or {}, template, ("quick",))
    cfg = deep_merge(base, c.data.get("quick") or {}) if quick else base
    for key in template:
        if key not in cfg:
            raise c.error((key,), "missing")
    for v in [*cfg["variants"], *(v for k in ("alpha", "push", "fig8") for v in cfg[k]["variants"])]:
        if v is False:
            raise c.error(("variants",), "write 'off' in quotes: YAML reads a bare off as false")
        try:
            variant(v)
        except ValueError as exc:
            raise c.error(("variants",), str(exc)) from None
    for s in [*cfg["starts"], cfg["alpha"]["start"], cfg["fig8"]["start"]]:
        try:
            start_time(s)
        except ValueError as exc:
            raise c.error(("starts",), str(exc)) from None
    for key in ("duration_after_s",):
        if not (isinstance(cfg[key], (int, float)) and cfg[key] > 0):
            raise c.error((key,), f"must be a positive number, got {cfg[key]!r}")
    t = cfg["transitions"]
    if not (isinstance(t.get("phases"), int) and t["phases"] >= 1 and t.get("states")
            and all(isinstance(s, list) and len(s) == 2 for s in t["states"])):
        raise c.error(("transitions",), "states: a list of [zeta, alpha]; phases: an integer >= 1")
    p = cfg["push"]
    if not (p["max_impulse_Ns"] > 0 and p["iterations"] >= 1 and p["duration_s"] > 0):
        raise c.error(("push",), "max_impulse_Ns, duration_s must be > 0 and iterations >= 1")
    return cfg


# ------------------------------------------------------------------------------------------- tasks
def grid_specs(cfg: dict) -> list[WalkSpec]:
    zetas = [*cfg["zeta"]["forward"], *cfg["zeta"]["backward"]]
    return [WalkSpec(zeta=float(z), start=s, variant=v, duration_after_s=float(cfg["duration_after_s"]),
                     transition=cfg["transition"])
            for s in cfg["starts"] for z in zetas for v in cfg["variants"]]


def alpha_specs(cfg: dict) -> list[WalkSpec]:
    a = cfg["alpha"]
    specs = [WalkSpec(zeta=float(a["zeta"]), alpha=float(x), start=a["start"], variant=v,
                      duration_after_s=float(cfg["duration_after_s"]), transition=cfg["transition"],
                      label="alpha")
             for v in a["variants"] for x in a["values"]]
    sr = a["stop_resume"]
    t0, t1, t2, settle = (float(sr[k]) for k in ("stop_at_s", "resume_at_s", "end_s", "settle_s"))
    for v in a["variants"]:
        specs.append(WalkSpec(zeta=float(a["zeta"]), alpha=0.0, start=f"at_{t0:g}s", variant=v,
                              duration_after_s=t2 - t0, transition=cfg["transition"],
                              schedule=((t1, float(a["zeta"]), float(sr["resume_alpha"])),),
                              segments=((t0 - 5.0, t0), (t0 + settle, t1), (t1 + settle, t2)),
                              label="stop_resume"))
    return specs


def fig8_specs(cfg: dict) -> list[WalkSpec]:
    f = cfg["fig8"]
    return [WalkSpec(zeta=float(f["zeta"]), start=f["start"], variant=v, duration_after_s=float(f["after_s"]),
                     transition=cfg["transition"], record_targets=True, label="fig8") for v in f["variants"]]


def push_bisection(task: dict) -> dict:
    """Largest impulse (N s) of a lateral torso push at ζ (and ``alpha``, default 1; 0: standing)
    recovered (no fall for ``after_s``): bisection on [0, max_impulse_Ns] (``governed``: through the
    governor, as cpg_node). The result is the largest recovered impulse tried (0: none)."""
    lo, hi = 0.0, float(task["max_impulse_Ns"])
    tried = []
    for _ in range(int(task["iterations"])):
        mid = 0.5 * (lo + hi)
        spec = WalkSpec(zeta=float(task["zeta"]), alpha=float(task.get("alpha", 1.0)), start="standing",
                        variant=task["variant"],
                        duration_after_s=float(task["at_s"]) + float(task["after_s"]),
                        transition=task["transition"], governed=bool(task.get("governed", False)),
                        push=Push(float(task["at_s"]), mid, float(task["duration_s"]),
                                  float(task["direction"])))
        m = run_walk(spec)
        tried.append({"impulse_Ns": round(mid, 4), "fell": m["fell"], "fall_time_s": m["fall_time_s"]})
        lo, hi = (mid, hi) if not m["fell"] else (lo, mid)
    return {"variant": task["variant"], "direction": task["direction"], "zeta": task["zeta"],
            "alpha": float(task.get("alpha", 1.0)),
            "max_recovered_impulse_Ns": round(lo, 4), "first_fall_impulse_Ns": round(hi, 4),
            "resolution_Ns": round(hi - lo, 4), "tried": tried}


def _task_value(result: dict) -> float:
    """A sweep trial's value: the push recovered (N s), or the distance walked (m)."""
    if "max_recovered_impulse_Ns" in result:
        return float(result["max_recovered_impulse_Ns"])
    return float(result.get("distance_m") or 0.0)


def _task_attrs(item: tuple[str, object], result: dict) -> dict:
    kind, x = item
    if kind == "push":
        return {"kind": "push", "variant": x["variant"], "direction": x["direction"], "zeta": x["zeta"]}
    return {"kind": x.label or "walk", "zeta": x.zeta, "alpha": x.alpha, "variant": x.variant,
            "start": x.start, "fell": result.get("fell"), "error": result.get("error")}


@task(value=_task_value, attrs=_task_attrs)
def sweep_task(item: tuple[str, object]) -> dict:
    """One task of the sweep's study: ("push", bisection task) or ("walk", WalkSpec)."""
    kind, x = item
    return push_bisection(x) if kind == "push" else _safe(run_walk, x)


def run_sweep(out_dir: str | Path, quick: bool = False, jobs: int | None = None, config: str | None = None,
              duration_after_s: float | None = None, progress_enabled: bool = True,
              storage: str | None = None, study: str | None = None, resume: bool = False,
              settings: EngineSettings | None = None) -> dict:
    """Run everything of config/sweep.yaml as the study ``study`` (default "sweep") in ``storage`` (default
    DIR/study.db, made afresh unless ``resume``; ``settings``: its engine's, default config/study.yaml) and
    write DIR/sweep.json, sweep.md and the PNGs."""
    from cpg_walker.progress import Progress

    cfg = load_config(config, quick)
    if duration_after_s is not None:
        if not duration_after_s > 0:
            raise InputError(f"--duration must be positive, got {duration_after_s}")
        cfg["duration_after_s"] = float(duration_after_s)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = cfg["push"]
    pushes = [{"variant": v, "direction": float(d), "transition": cfg["transition"],
               **{k: p[k] for k in ("zeta", "at_s", "after_s", "duration_s", "max_impulse_Ns", "iterations")}}
              for v in p["variants"] for d in p["directions"]]
    grid, alphas, fig8 = grid_specs(cfg), alpha_specs(cfg), fig8_specs(cfg)
    items = [("push", t) for t in pushes] + [("walk", s) for s in [*grid, *alphas, *fig8]]
    url, name = study_options(storage, study, out, "sweep")
    with Engine(url, name, "sweep", jobs, settings, direction="maximize", attrs={"config": cfg},
                resume=resume, replace=storage is None and not resume) as engine:
        progress = Progress(len(items), "sweep", unit="tasks", enabled=progress_enabled)
        res = engine.map(sweep_task, items, "sweep", progress)
        progress.close()
        report = _report(out, cfg, quick, pushes, grid, alphas, fig8, res)
        from cpg_walker.experiments.transitions import from_config, run_transitions

        states, phases, times = from_config(cfg["transitions"])
        tr = run_transitions(out, states, phases, jobs, times, engine=engine)
    report["transitions"] = {"falls": tr["falls"], "runs": len(tr["runs"])}
    report["pngs"].append(str(out / "transitions.png"))
    return report


def _report(out: Path, cfg: dict, quick: bool, pushes: list, grid: list, alphas: list, fig8: list,
            res: list) -> dict:
    """sweep.json, sweep.md and the PNGs of the tasks' results (in the order they were enqueued)."""
    n = len(pushes)
    push_res, grid_res = res[:n], res[n : n + len(grid)]
    alpha_res, fig8_res = res[n + len(grid) : n + len(grid) + len(alphas)], res[n + len(grid) + len(alphas):]
    for r in alpha_res:
        if r.get("spec", {}).get("label") == "stop_resume" and len(r.get("segments", [])) == 3:
            before, stopped, resumed = (s["mean_speed_mps"] for s in r["segments"])
            r["stops_and_resumes"] = bool(not r["fell"] and abs(stopped) < STOPPED_MPS
                                          and abs(resumed) > 0.5 * abs(before) > 0)
    runs = grid_res
    for r, s in zip(runs, grid, strict=True):  # a crashed run keeps its coordinates
        r.setdefault("zeta", s.zeta)
        r.setdefault("variant", s.variant)
        r.setdefault("start", s.start)
        r.setdefault("alpha", s.alpha)
    from cpg_walker.experiments.walk_runs import _controller

    period = _controller().period
    report = {"config": cfg, "quick": quick, "gait_period_s": period, "runs": runs,
              "alpha": alpha_res, "push": push_res,
              "fig8": {"zeta": cfg["fig8"]["zeta"], "runs": fig8_res}}
    (out / "sweep.json").write_text(json.dumps(report, indent=1) + "\n")
    report["pngs"] = [str(plot_speed(report, out / "speed_vs_zeta.png")),
                      str(plot_fall_map(report, out / "fall_map.png")),
                      str(plot_heading(report, out / "heading.png")),
                      str(plot_alpha(report, out / "alpha.png")),
                      str(plot_fig8(report, out / "fig8.png"))]
    (out / "sweep.md").write_text(markdown(report))
    return report


# ------------------------------------------------------------------------------------------- summaries
def fall_thresholds(runs: list[dict]) -> dict:
    """Per variant × start: the smallest |ζ| forward and backward that fell (None: none fell), and
    whether ζ = 1.5 and ζ = −1.0 walked (when in the grid)."""
    out = {}
    for v in dict.fromkeys(r["variant"] for r in runs):
        for s in dict.fromkeys(r["start"] for r in runs):
            rs = [r for r in runs if r["variant"] == v and r["start"] == s and "error" not in r]
            fell = [r for r in rs if r["fell"]]
            fwd = [r["zeta"] for r in fell if r["zeta"] > 0]
            bwd = [r["zeta"] for r in fell if r["zeta"] < 0]
            d = {"first_fall_forward": min(fwd) if fwd else None,
                 "first_fall_backward": max(bwd) if bwd else None}
            for z in (1.5, -1.0):
                hit = [r for r in rs if math.isclose(r["zeta"], z)]
                if hit:
                    d[f"walked_{z:+g}"] = not hit[0]["fell"]
            out[f"{v}/{s}"] = d
    return out


def markdown(report: dict) -> str:
    runs = report["runs"]
    cfg = report["config"]
    variants = list(dict.fromkeys(r["variant"] for r in runs))
    starts = list(dict.fromkeys(r["start"] for r in runs))
    zetas = sorted(dict.fromkeys(r["zeta"] for r in runs), key=lambda z: (z < 0, abs(z)))
    cols = [(s, v) for s in starts for v in variants]
    lines = [f"# cpg-walker sweep{' --quick' if report['quick'] else ''}", "",
             f"{cfg['duration_after_s']:g} s walked after the command; cell: {CELL_LEGEND}.",
             "", "| ζ | " + " | ".join(f"{s}: {v}" for s, v in cols) + " |",
             "|---|" + "---|" * len(cols)]
    for z in zetas:
        cells = []
        for s, v in cols:
            hit = [r for r in runs if r["zeta"] == z and r["start"] == s and r["variant"] == v]
            cells.append(result_cell(hit[0]) if hit else "")
        lines.append(f"| {z:+g} | " + " | ".join(cells) + " |")
    lines += ["", "Fall thresholds (smallest |ζ| that fell; as measured above):", "",
              "| variant/start | first fall forward | first fall backward | ζ=+1.5 walked | ζ=−1 walked |",
              "|---|---|---|---|---|"]
    for k, d in fall_thresholds(runs).items():
        lines.append(f"| {k} | {d['first_fall_forward']} | {d['first_fall_backward']} | "
                     f"{d.get('walked_+1.5', '')} | {d.get('walked_-1', '')} |")
    paper = cfg["paper"]
    pts = ", ".join(f"ζ = {p['zeta']:g}: {p['speed_mps']:g} m/s" for p in paper["speed_points"])
    lines += ["", f"The paper (Sec. IV): without feedback it falls above ζ = "
              f"{paper['fall_threshold_without_feedback']:g}; with feedback {pts}, and walks backwards."]
    lines += ["", "Lateral drift (m) over the window:", "",
              "| ζ | " + " | ".join(f"{s}: {v}" for s, v in cols) + " |", "|---|" + "---|" * len(cols)]
    for z in zetas:
        cells = []
        for s, v in cols:
            hit = [r for r in runs if r["zeta"] == z and r["start"] == s and r["variant"] == v]
            cells.append(f"{hit[0]['lateral_drift_m']:+.2f}" if hit and "error" not in hit[0] else "")
        lines.append(f"| {z:+g} | " + " | ".join(cells) + " |")
    lines += ["", f"## α at ζ = {cfg['alpha']['zeta']:g} (commanded {cfg['alpha']['start']})", "",
              "| variant | α | fell | speed m/s | step length m | steps |", "|---|---|---|---|---|---|"]
    for r in report["alpha"]:
        if r.get("spec", {}).get("label") == "alpha":
            lines.append(f"| {r['variant']} | {r['alpha']:g} | {r['fell']} | {r['mean_speed_mps']:+.3f} | "
                         f"{r['step_length_m']} | {r['steps']} |")
    for r in report["alpha"]:
        if r.get("spec", {}).get("label") == "stop_resume":
            seg = r.get("segments", [])
            txt = ", ".join(f"[{s['from_s']:g}, {s['to_s']:g}] s: {s['mean_speed_mps']:+.3f} m/s, "
                            f"{s['steps']} steps" for s in seg)
            lines.append(f"\nα → 0 and back ({r['variant']}; fell: {r['fell']}; stops and resumes: "
                         f"{r.get('stops_and_resumes')}): {txt}")
    lines += ["", f"## Largest lateral push recovered at ζ = {cfg['push']['zeta']:g}", "",
              f"Torso push {cfg['push']['duration_s']:g} s long at t = {cfg['push']['at_s']:g} s, "
              f"perpendicular to the heading; recovered = no fall for {cfg['push']['after_s']:g} s after "
              "it.", "",
              "| variant | direction | max recovered (N s) | first fall (N s) |", "|---|---|---|---|"]
    for p in report["push"]:
        if "error" in p:
            lines.append(f"| ? | ? | {p['error']} | |")
            continue
        side = "left" if p["direction"] > 0 else "right"
        lines.append(f"| {p['variant']} | {side} | {p['max_recovered_impulse_Ns']} | "
                     f"{p['first_fall_impulse_Ns']} |")
    lines += ["", "Plots: " + ", ".join(Path(x).name for x in report.get("pngs", [])), ""]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------- plots
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _lines(ax, runs: list[dict], key: str) -> None:
    """One line per variant × start through the runs that did not fall; a fall is an × on the ζ axis
    (its speed, heading and drift are the fall's, not the gait's)."""
    ok = [r for r in runs if "error" not in r]
    for v in dict.fromkeys(r["variant"] for r in ok):
        for s in dict.fromkeys(r["start"] for r in ok):
            rs = sorted((r for r in ok if r["variant"] == v and r["start"] == s), key=lambda r: r["zeta"])
            walked = [r for r in rs if not r["fell"]]
            line, = ax.plot([r["zeta"] for r in walked], [r[key] for r in walked],
                            "-o" if s == "standing" else "--s", ms=4, label=f"{v}, {s}")
            fell = [r["zeta"] for r in rs if r["fell"]]
            if fell:
                ax.plot(fell, [0.0] * len(fell), "x", ms=10, mew=2, color=line.get_color())


def plot_speed(report: dict, path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _lines(ax, report["runs"], "steady_speed_mps")
    paper = report["config"]["paper"]
    pts = paper["speed_points"]
    ax.plot([p["zeta"] for p in pts], [p["speed_mps"] for p in pts], "k*", ms=14, label="paper (Sec. IV)")
    ax.axvline(paper["fall_threshold_without_feedback"], color="0.5", ls=":",
               label="paper: falls w/o feedback")
    ax.axhline(0, color="0.8", lw=0.8)
    ax.set_xlabel("ζ")
    ax.set_ylabel("speed (m/s, second half of the window)")
    ax.set_title("speed vs ζ (× on the axis = fell)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_fall_map(report: dict, path: Path) -> Path:
    import numpy as np

    plt = _plt()
    runs = [r for r in report["runs"] if "error" not in r]
    zetas = sorted(dict.fromkeys(r["zeta"] for r in runs))
    variants = dict.fromkeys(r["variant"] for r in runs)
    cols = [(s, v) for s in dict.fromkeys(r["start"] for r in runs) for v in variants]
    img = np.full((len(zetas), len(cols)), np.nan)
    fig, ax = plt.subplots(figsize=(1.3 * len(cols) + 2, 0.32 * len(zetas) + 1.5))
    for r in runs:
        i, j = zetas.index(r["zeta"]), cols.index((r["start"], r["variant"]))
        img[i, j] = 0.0 if r["fell"] else 1.0
        txt = f"{r['fall_time_s'] - r['t_cmd_s']:.0f}s" if r["fell"] else f"{r['steady_speed_mps']:.2f}"
        ax.text(j, i, txt, ha="center", va="center", fontsize=7)
    ax.imshow(img, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    ax.set_yticks(range(len(zetas)), [f"{z:+g}" for z in zetas])
    ax.set_xticks(range(len(cols)), [f"{v}\n{s}" for s, v in cols], fontsize=8)
    ax.set_ylabel("ζ")
    ax.set_title("fall map (red: fell, text = s after the command; green: m/s)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_heading(report: dict, path: Path) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for key, ax in zip(("heading_change_deg", "lateral_drift_m"), axes, strict=True):
        _lines(ax, report["runs"], key)
        ax.axhline(0, color="0.8", lw=0.8)
        ax.set_xlabel("ζ")
        ax.set_ylabel(key)
        ax.grid(alpha=0.3)
    axes[0].set_title("heading change over the window (× on the axis = fell)")
    axes[1].set_title("lateral drift over the window")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_alpha(report: dict, path: Path) -> Path:
    plt = _plt()
    rows = [r for r in report["alpha"] if "error" not in r and r["spec"]["label"] == "alpha"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for v in dict.fromkeys(r["variant"] for r in rows):
        rs = sorted((r for r in rows if r["variant"] == v), key=lambda r: r["alpha"])
        for ax, key in zip(axes, ("step_length_m", "mean_speed_mps"), strict=True):
            ax.plot([r["alpha"] for r in rs], [r[key] or 0.0 for r in rs], "-o", label=v)
            fz = [(r["alpha"], r[key] or 0.0) for r in rs if r["fell"]]
            if fz:
                ax.plot(*zip(*fz, strict=True), "kx", ms=10)
            ax.set_xlabel("α")
            ax.set_ylabel(key)
            ax.grid(alpha=0.3)
    axes[0].set_title("step length vs α (× = fell)")
    axes[1].set_title("speed vs α")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_fig8(report: dict, path: Path) -> Path:
    """Paper Fig. 8: targets of the right Hip1, Ankle2, Ankle1, Knee over a few periods after the change
    to ζ = 1.2: open loop dotted, with feedback solid."""
    import numpy as np

    plt = _plt()
    cfg = report["config"]["fig8"]
    t_change = start_time(cfg["start"])
    span = float(cfg["plot_periods"]) * report["gait_period_s"] / abs(float(cfg["zeta"]))
    t0 = t_change + float(cfg["plot_from_s"])
    falls = [r["fall_time_s"] for r in report["fig8"]["runs"] if r.get("fell")]
    t1 = min([t0 + span, *falls])  # the window ends before the first fall...
    t0 = max(t_change, min(t0, t1 - span))  # ...and starts earlier if it must, not before the change
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for r in report["fig8"]["runs"]:
        if "error" in r or "targets" not in r:
            continue
        names = r["targets"]["names"]
        a = np.array(r["targets"]["rows"])
        sel = (a[:, 0] >= t0) & (a[:, 0] <= t1)
        for ax, dof in zip(axes.flat, FIG8_DOFS, strict=True):
            j = names.index(f"{FIG8_SIDE}leg_joint_{PAPER_LEG_DOFS[dof]}")
            style = ":" if r["variant"] == "off" else "-"
            fell = f", fell {r['fall_time_s']:.1f}s" if r["fell"] else ""
            ax.plot(a[sel, 0], np.degrees(a[sel, 1 + j]), style, label=f"{r['variant']}{fell}")
            ax.set_title(f"right {dof}")
            ax.set_ylabel("target (deg)")
            ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"Fig. 8: joint targets at ζ = {cfg['zeta']:g} (dotted: no feedback)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------- calibration
def calibrate() -> dict:
    """Walk at ζ = 1 with the feedback observing only (no pathway): the mean torso pitch after the
    hand-over and the right Hip2 phase at right touchdowns (config/feedback.yaml's pitch_reference_rad
    and reset_phase_rad)."""
    from cpg_walker.experiments.cpg_walk import walk
    from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    ctrl, _, _ = load_controller(cpg_defaults()["cpg_file"])
    m = walk(ctrl, 40.0, zeta=1.0, feedback=FeedbackController(FeedbackConfig.load(), ()))
    return {"pitch_mean_rad": m["tilt_after_handover"]["pitch_mean_rad"],
            "right_touchdown_phase_rad": m["right_touchdown_phase_rad"],
            "roll_abs_mean_rad": m["tilt_after_handover"]["roll_abs_mean_rad"]}
