"""`cpg-walker envelope`: which (ζ, α) walk, from standing and changed at run time (issue 24, "The
envelope, measured") — a map every later controller change can be compared with.

The grid is data, in config/envelope.yaml (``--quick``: its ``quick:`` section merged over it): ζ forward
and backward × α × start, each walked ``duration_after_s`` after the command with the feedback the nodes
use (variant "ours"). Starts (experiments/walk_runs.py): "standing" — ζ, α requested at t = 0 and applied
when the start-up cross-fade ends (``t_applied_s``, ≈ 6.6 s); "at_10s" — the walk at ζ = α = 1, then ζ, α
commanded at 10 s (applied at once: ``t_applied_s`` = 10).

Per cell: ``fell``, ``fall_time_s`` (sim time from t = 0) and ``fall_after_s`` (from ``t_applied_s``);
``steady_speed_mps`` (the speed along the heading at the command over the second half of the window
[command, end]: the gait's, not the start-up's), ``mean_speed_mps``, ``lateral_drift_m`` and
``heading_change_deg`` over the window (walk_runs.window_metrics). ``status``: "walks", "stalls" (walks,
|steady speed| < ``stalled_mps``), "falls" or "error".

Writes DIR/envelope.json (provenance, config, grid, cells, per-ζ summary), DIR/envelope.md (the summary
and one table per start) and DIR/envelope.png (one map per start: ζ on x, α on y).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.experiments.config_file import Config, deep_merge
from cpg_walker.experiments.walk_runs import WalkSpec, run_many, run_walk, start_time, variant

#: the metrics of run_walk a cell keeps (the rest — spec, torques, steps — is the sweep's business)
CELL_KEYS = ("fell", "fall_time_s", "duration_s", "t_cmd_s", "window_s", "distance_m", "steady_speed_mps",
             "mean_speed_mps", "lateral_drift_m", "heading_change_deg", "steps", "step_length_m")


def load_config(path: str | Path | None = None, quick: bool = False) -> dict:
    """config/envelope.yaml (or ``path``), validated; ``quick`` merges its ``quick:`` section."""
    from cpg_walker.paths import config_path

    if path and not Path(path).exists() and len(Path(path).parts) == 1:
        path = config_path(str(path))  # a name in the package's config/
    c = Config(path or config_path("envelope.yaml"))
    template = Config(config_path("envelope.yaml")).data if path else c.data
    template = {k: v for k, v in template.items() if k != "quick"}
    base = {k: v for k, v in c.data.items() if k != "quick"}
    c.check_known(base, template)
    c.check_known(c.data.get("quick") or {}, template, ("quick",))
    cfg = deep_merge(base, c.data.get("quick") or {}) if quick else base
    for key in template:
        if key not in cfg:
            raise c.error((key,), "missing")
    where = ("quick",) if quick else ()

    def numbers(key: tuple, xs, lo: float | None = None) -> list[float]:
        if not isinstance(xs, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                               and math.isfinite(x) for x in xs):
            raise c.error(key, f"must be a list of numbers, got {xs!r}")
        if lo is not None and any(x < lo for x in xs):
            raise c.error(key, f"every value must be >= {lo:g}, got {xs!r}")
        return [float(x) for x in xs]

    if not isinstance(cfg["zeta"], dict) or set(cfg["zeta"]) != {"forward", "backward"}:
        raise c.error((*where, "zeta"), "must have 'forward' and 'backward' lists")
    zetas = numbers(("zeta", "forward"), cfg["zeta"]["forward"]) + \
        numbers(("zeta", "backward"), cfg["zeta"]["backward"])
    if not zetas:
        raise c.error(("zeta",), "no zeta to walk")
    if not numbers(("alpha",), cfg["alpha"], 0.0):
        raise c.error(("alpha",), "no alpha to walk")
    if cfg["variant"] is False:
        raise c.error(("variant",), "write 'off' in quotes: YAML reads a bare off as false")
    try:
        variant(cfg["variant"])
    except ValueError as exc:
        raise c.error(("variant",), str(exc)) from None
    if not isinstance(cfg["starts"], list) or not cfg["starts"]:
        raise c.error(("starts",), "must be a non-empty list")
    for s in cfg["starts"]:
        try:
            start_time(str(s))
        except ValueError as exc:
            raise c.error(("starts",), str(exc)) from None
    for key in ("duration_after_s", "stalled_mps"):
        v = cfg[key]
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
                and (v > 0 or key == "stalled_mps")):
            raise c.error((key,), f"must be a positive number, got {v!r}")
    if cfg["transition"] not in ("recording", "standing"):
        raise c.error(("transition",), f"use recording or standing, got {cfg['transition']!r}")
    return cfg


def grid(cfg: dict) -> dict:
    """The grid's axes: ζ ascending (backward first), α ascending, the starts in the config's order."""
    return {"zeta": sorted({float(z) for k in ("forward", "backward") for z in cfg["zeta"][k]}),
            "alpha": sorted({float(a) for a in cfg["alpha"]}), "starts": [str(s) for s in cfg["starts"]]}


def specs(cfg: dict) -> list[WalkSpec]:
    g = grid(cfg)
    return [WalkSpec(zeta=z, alpha=a, start=s, variant=cfg["variant"], transition=cfg["transition"],
                     duration_after_s=float(cfg["duration_after_s"]), label="envelope")
            for s in g["starts"] for z in g["zeta"] for a in g["alpha"]]


def applied_at(start: str, transition: str) -> float:
    """Sim time at which ζ, α take effect: the end of the start-up cross-fade for "standing" (the gait
    source defers a command given before it), the command's time otherwise."""
    t = start_time(start)
    if start != "standing":
        return t
    from cpg_walker.experiments.walk_runs import _controller
    from cpg_walker.walker.gait_source import CPGGaitSource

    return round(max(t, CPGGaitSource(_controller(), transition=transition).takeover_s), 3)


def cell(m: dict, spec: WalkSpec, t_applied: float, stalled_mps: float) -> dict:
    """One run_walk result as a cell of the map."""
    c = {"zeta": spec.zeta, "alpha": spec.alpha, "start": spec.start, "t_applied_s": t_applied}
    if "error" in m:
        return {**c, "status": "error", "error": m["error"], "fell": None, "fall_time_s": None,
                "fall_after_s": None}
    c.update({k: m.get(k) for k in CELL_KEYS})
    c["fall_after_s"] = round(m["fall_time_s"] - t_applied, 3) if m["fell"] else None
    slow = abs(m["steady_speed_mps"]) < stalled_mps
    c["status"] = "falls" if m["fell"] else ("stalls" if slow else "walks")
    return c


def summarize(cells: list[dict], g: dict) -> list[dict]:
    """Per start and ζ: the α that walk (status walks or stalls), their range, whether they are contiguous
    in the grid, and the falls at the range's edges (the next α below and above it) with their fall times
    after the command took effect."""
    out = []
    for s in g["starts"]:
        for z in g["zeta"]:
            row = {c["alpha"]: c for c in cells if c["start"] == s and c["zeta"] == z}
            ok = [a for a in g["alpha"] if row.get(a, {}).get("status") in ("walks", "stalls")]
            d = {"start": s, "zeta": z, "walking_alpha": ok,
                 "alpha_min": min(ok) if ok else None, "alpha_max": max(ok) if ok else None}
            if ok:
                i0, i1 = g["alpha"].index(min(ok)), g["alpha"].index(max(ok))
                d["contiguous"] = len(ok) == i1 - i0 + 1
                below = g["alpha"][i0 - 1] if i0 > 0 else None
                above = g["alpha"][i1 + 1] if i1 + 1 < len(g["alpha"]) else None
            else:
                d["contiguous"] = True
                below, above = None, None
            d["edge_falls"] = [{"alpha": a, "fall_after_s": row[a].get("fall_after_s")}
                               for a in (below, above) if a is not None and a in row
                               and row[a].get("status") == "falls"]
            if not ok:  # nothing walks: the quickest and slowest falls
                falls = [row[a] for a in g["alpha"] if row.get(a, {}).get("status") == "falls"]
                d["fall_after_s_range"] = ([min(f["fall_after_s"] for f in falls),
                                            max(f["fall_after_s"] for f in falls)] if falls else None)
            out.append(d)
    return out


def run_envelope(out_dir: str | Path, quick: bool = False, jobs: int | None = None, config: str | None = None,
                 duration_after_s: float | None = None, command: str = "cpg-walker envelope",
                 progress_enabled: bool = True) -> dict:
    """Walk every cell of config/envelope.yaml; write DIR/envelope.json, envelope.md and envelope.png."""
    import time

    from cpg_walker.experiments.provenance import load_average, provenance
    from cpg_walker.progress import Progress

    cfg = load_config(config, quick)
    if duration_after_s is not None:
        if not (math.isfinite(duration_after_s) and duration_after_s > 0):
            raise InputError(f"--duration must be positive, got {duration_after_s}")
        cfg["duration_after_s"] = float(duration_after_s)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prov = provenance(command)
    g = grid(cfg)
    todo = specs(cfg)
    t0 = time.monotonic()
    progress = Progress(len(todo), "envelope", unit="walks", enabled=progress_enabled)
    res = run_many(run_walk, todo, jobs, progress)
    progress.close()
    prov["wall_s"] = round(time.monotonic() - t0, 1)
    prov["load_average_end"] = load_average()
    prov["jobs"] = jobs
    applied = {s: applied_at(s, cfg["transition"]) for s in g["starts"]}
    cells = [cell(m, sp, applied[sp.start], float(cfg["stalled_mps"]))
             for m, sp in zip(res, todo, strict=True)]
    report = {"provenance": prov, "quick": quick, "config": cfg, "grid": g, "t_applied_s": applied,
              "cells": cells, "summary": summarize(cells, g)}
    (out / "envelope.json").write_text(json.dumps(report, indent=1) + "\n")
    report["png"] = str(plot_map(report, out / "envelope.png"))
    (out / "envelope.md").write_text(markdown(report))
    return report


# ------------------------------------------------------------------------------------------- text
def _alpha_range(d: dict) -> str:
    if not d["walking_alpha"]:
        return "none"
    lo, hi = d["alpha_min"], d["alpha_max"]
    txt = f"{lo:g}–{hi:g}" if lo != hi else f"{lo:g}"
    return txt if d["contiguous"] else txt + " (only " + ", ".join(f"{a:g}" for a in d["walking_alpha"]) + ")"


def _edges(d: dict) -> str:
    if d["walking_alpha"]:
        return ", ".join(f"α {e['alpha']:g}: {e['fall_after_s']:.1f} s" for e in d["edge_falls"]) or "—"
    r = d.get("fall_after_s_range")
    return f"all fall, {r[0]:.1f}–{r[1]:.1f} s" if r else "—"


def cell_text(c: dict) -> str:
    """A cell in a markdown table: "F +d s" (fell d s after the command took effect), else the steady
    speed, heading change and lateral drift ("stalls" marked)."""
    if c["status"] == "error":
        return "error"
    if c["status"] == "falls":
        return f"F +{c['fall_after_s']:.1f} s"
    mark = " (stalls)" if c["status"] == "stalls" else ""
    return (f"{c['steady_speed_mps']:+.3f} m/s {c['heading_change_deg']:+.0f}° "
            f"{c['lateral_drift_m']:+.2f} m{mark}")


def markdown(report: dict) -> str:
    cfg, g, p = report["config"], report["grid"], report["provenance"]
    lines = [f"# cpg-walker envelope{' --quick' if report['quick'] else ''}", "",
             f"Which (ζ, α) walk with the feedback variant `{cfg['variant']}`, "
             f"{cfg['duration_after_s']:g} sim s walked after the command. Starts: "
             + "; ".join(f"{s}: ζ, α take effect at {report['t_applied_s'][s]:g} s" for s in g["starts"])
             + " (standing: requested at t = 0, applied when the start-up cross-fade ends, so walked "
             f"{cfg['duration_after_s'] - report['t_applied_s'].get('standing', 0.0):g} s after that; at_Ts: "
             "the walk at ζ = α = 1 until T s).", "",
             "## Summary: the α that walk, per ζ", "",
             "Edge falls: the nearest α outside the walking range that fell, and how long after the command "
             "took effect.", "",
             "| ζ | " + " | ".join(f"{s}: α that walk | {s}: edge falls" for s in g["starts"]) + " |",
             "|---|" + "---|---|" * len(g["starts"])]
    by = {(d["start"], d["zeta"]): d for d in report["summary"]}
    for z in g["zeta"]:
        cells = []
        for s in g["starts"]:
            d = by[(s, z)]
            cells += [_alpha_range(d), _edges(d)]
        lines.append(f"| {z:+g} | " + " | ".join(cells) + " |")
    for s in g["starts"]:
        lines += ["", f"## {s}", "",
                  "Cell: F +d s = fell d s after the command took effect; else the speed along the heading "
                  "at the command over the window's second half, the heading change and the lateral drift "
                  f"over the window; (stalls) = |speed| < {cfg['stalled_mps']:g} m/s.", "",
                  "| ζ \\ α | " + " | ".join(f"{a:g}" for a in g["alpha"]) + " |",
                  "|---|" + "---|" * len(g["alpha"])]
        for z in g["zeta"]:
            row = {c["alpha"]: c for c in report["cells"] if c["start"] == s and c["zeta"] == z}
            texts = [cell_text(row[a]) if a in row else "" for a in g["alpha"]]
            lines.append(f"| {z:+g} | " + " | ".join(texts) + " |")
    lines += ["", f"Map: {Path(report.get('png', 'envelope.png')).name}", "",
              f"Command `{p['command']}`, commit {p['commit']}, {p['date']}, {p['cpus']} cores, load "
              f"{p['load_average_start']} at the start and {p.get('load_average_end')} at the end, "
              f"{p.get('wall_s')} s wall.", ""]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------- plot
#: status -> map value (colour index)
_CODE = {"walks": 3, "stalls": 2, "falls": 1, "error": 0}


def plot_map(report: dict, path: Path) -> Path:
    """One panel per start: ζ on x, α on y; green = walks (text: speed m/s), yellow = stalls, red = falls
    (text: s after the command took effect, paler the later), grey = error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    g = report["grid"]
    zs, als, starts = g["zeta"], g["alpha"], g["starts"]
    dur = float(report["config"]["duration_after_s"])
    cmap = ListedColormap(["0.75", "#d62728", "#f2d541", "#5cb85c"])
    fig, axes = plt.subplots(len(starts), 1, figsize=(max(6.0, 0.62 * len(zs) + 1.8),
                                                      (0.42 * len(als) + 1.3) * len(starts) + 1.0),
                             squeeze=False)
    for ax, s in zip(axes[:, 0], starts, strict=True):
        img = np.full((len(als), len(zs)), np.nan)
        fade = np.zeros((len(als), len(zs)))
        for c in (c for c in report["cells"] if c["start"] == s):
            i, j = als.index(c["alpha"]), zs.index(c["zeta"])
            img[i, j] = _CODE[c["status"]]
            if c["status"] == "falls":
                txt = f"F{c['fall_after_s']:.0f}" if c["fall_after_s"] >= 9.5 else f"F{c['fall_after_s']:.1f}"
                fade[i, j] = min(1.0, max(0.0, c["fall_after_s"] / dur))
            elif c["status"] == "error":
                txt = "err"
            else:
                txt = f"{c['steady_speed_mps']:+.2f}".replace("0.", ".")
            ax.text(j, i, txt, ha="center", va="center", fontsize=7,
                    color="white" if c["status"] == "falls" and fade[i, j] < 0.5 else "black")
        ax.imshow(img, cmap=cmap, vmin=-0.5, vmax=3.5, origin="lower", aspect="auto")
        # falls late in the window are paler: a white veil proportional to the fall time
        veil = np.zeros((len(als), len(zs), 4))
        veil[..., :3] = 1.0
        veil[..., 3] = np.where(img == _CODE["falls"], 0.6 * fade, 0.0)
        ax.imshow(veil, origin="lower", aspect="auto")
        ax.set_xticks(range(len(zs)), [f"{z:+g}" for z in zs], fontsize=8)
        ax.set_yticks(range(len(als)), [f"{a:g}" for a in als], fontsize=8)
        ax.set_xticks(np.arange(-0.5, len(zs)), minor=True)
        ax.set_yticks(np.arange(-0.5, len(als)), minor=True)
        ax.grid(which="minor", color="white", lw=1)
        ax.tick_params(which="minor", length=0)
        ax.set_xlabel("ζ (negative: backwards)")
        ax.set_ylabel("α")
        when = report["t_applied_s"][s]
        title = (f"from standing (ζ, α applied at the end of the start-up, {when:g} s)" if s == "standing"
                 else f"changed at run time ({s}: from ζ = α = 1 at {when:g} s)")
        ax.set_title(title, fontsize=10)
    fig.legend(handles=[Patch(color="#5cb85c", label="walks (text: m/s, 2nd half of the window)"),
                        Patch(color="#f2d541", label="stalls (walks, |speed| small)"),
                        Patch(color="#d62728", label="falls (text: s after the command; paler = later)"),
                        Patch(color="0.75", label="error")],
               loc="lower center", ncol=2, fontsize=8, frameon=False)
    p = report.get("provenance", {})
    p = report.get("provenance", {})
    fig.suptitle(f"envelope{' (quick)' if report['quick'] else ''}: {dur:g} s after the command, feedback "
                 f"'{report['config']['variant']}', commit {str(p.get('commit'))[:8]}", fontsize=9, y=0.995)
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
