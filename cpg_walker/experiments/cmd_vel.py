"""/cmd_vel driving measured in-process (walker/loop.py run_replay, through experiments/walk_runs.py):

* ``measure_speed_map`` — the forward speed per ζ (α = 1) forward and backward, per α at ζ = ±1, and at
  the fast nodes (α > 1, with the ankle pathway), each from standing, over the second half of a
  ``window_s`` window after the command: the data of config/speed_map.yaml (``cpg-walker cmd-vel-map
  --out DIR`` writes DIR/speed_map.yaml + .json).
* ``run_drive`` / ``drive_set`` (run by experiments/drive_protocol.py ``drive_check``) — Twist commands
  through walker/cmd_vel.py's CmdVelFollower (as cpg_node applies
  them), commanded vs actual forward speed and turn rate from the base trajectory (the in-process
  /odom/ground_truth), and the stop after the last command (the timeout): DIR/drive_check.json, .md,
  .png (``cpg-walker drive-check --out DIR``).
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cpg_walker.experiments.walk_runs import WalkSpec, run_many, run_walk
from cpg_walker.walker.cmd_vel import REVERSE_ALPHA_RATE, CmdVelFollower, CmdVelLimits, SpeedMap, apply_output
from cpg_walker.walker.loop import heading_at

#: The speed map's grid (ζ at α = 1; α at ζ = ±1), each walked from standing.
MAP_ZETAS = tuple(s * z for s in (1, -1) for z in (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5))
MAP_ALPHAS = (0.2, 0.4, 0.6, 0.8)
#: The fast nodes (ζ, α > 1), walked with the ankle pathway (config/governor.yaml ``ankle``): the map's
#: ``fast_speed`` (forward toward α 1.4 at ζ 1.7, 1.45 fell; backward α 1.3 at ζ −1.5, 1.4 at −1.6 fell).
MAP_FAST = ((1.6, 1.2), (1.7, 1.4), (-1.5, 1.15), (-1.5, 1.3))
MAP_WINDOW_S = 30.0


def default_map_file() -> str:
    """cpg_node's ``cmd_vel.speed_map`` (config/cpg.yaml, the one home)."""
    from cpg_walker.paths import ros_parameters

    return str(ros_parameters("cpg.yaml", "cpg")["cmd_vel.speed_map"])


def map_specs(window_s: float = MAP_WINDOW_S) -> list[WalkSpec]:
    specs = [WalkSpec(zeta=z, alpha=1.0, start="standing", duration_after_s=window_s, label=f"zeta {z:g}")
             for z in MAP_ZETAS]
    specs += [WalkSpec(zeta=s, alpha=a, start="standing", duration_after_s=window_s,
                       label=f"alpha {a:g} zeta {s:g}") for s in (1.0, -1.0) for a in MAP_ALPHAS]
    specs += [WalkSpec(zeta=z, alpha=a, start="standing", duration_after_s=window_s,
                       label=f"fast {z:g}, {a:g}") for z, a in MAP_FAST]
    return specs


def measure_speed_map(out: str | Path, jobs: int = 2, window_s: float = MAP_WINDOW_S, progress=None) -> dict:
    """Walk the grid; write DIR/speed_map.json (every run) and DIR/speed_map.yaml (the map file: the runs
    that walked, speed over the window's second half). Returns the map dict."""
    specs = map_specs(window_s)
    runs = run_many(run_walk, specs, jobs=jobs, progress=progress)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for s, m in zip(specs, runs, strict=True):
        rows.append({"zeta": s.zeta, "alpha": s.alpha, "fell": m.get("fell", True), "error": m.get("error"),
                     **{k: m.get(k) for k in ("steady_speed_mps", "heading_change_deg", "lateral_drift_m")}})
    (out / "speed_map.json").write_text(json.dumps({"window_s": window_s, "runs": rows}, indent=2) + "\n")
    ok = [r for r in rows if not r["fell"] and r["error"] is None]
    doc = {"measured": {"command": "cpg-walker cmd-vel-map --out DIR", "start": "standing",
                        "window_s": window_s, "speed": "steady_speed_mps (second half of the window)"},
           "slow_abs_zeta": 1.0}
    for key, sign in (("forward", 1.0), ("backward", -1.0)):
        mine = [r for r in ok if r["zeta"] * sign > 0]
        doc[key] = {"zeta_speed": [[r["zeta"], r["steady_speed_mps"]] for r in mine if r["alpha"] == 1.0],
                    "alpha_speed": [[r["alpha"], r["steady_speed_mps"]] for r in mine if r["alpha"] < 1.0],
                    "fast_speed": [[r["zeta"], r["alpha"], r["steady_speed_mps"]] for r in mine
                                   if r["alpha"] > 1.0]}
        if not doc[key]["fast_speed"]:
            del doc[key]["fast_speed"]
    doc["fell"] = [[r["zeta"], r["alpha"]] for r in rows if r["fell"] or r["error"]]
    import yaml

    (out / "speed_map.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return doc


# ------------------------------------------------------------------------------------------- drive check
@dataclass(frozen=True)
class Drive:
    """One in-process drive: the robot walks at ζ = α = 1 (the node's start) until ``t0``, then gets
    Twist ``segments`` [(until_s, linear_x, angular_z[, linear_y]), ...] at ``rate_hz`` from ``t0``;
    nothing after the
    last segment (the timeout stops it); the walk ends ``tail_s`` after it. ``measure``: the
    (from, to) sim-s windows the table reports (default: the last 60 % of each segment)."""

    label: str
    segments: tuple[tuple[float, ...], ...]
    t0: float = 10.0
    rate_hz: float = 10.0
    tail_s: float = 8.0
    windows: tuple[tuple[float, float], ...] = field(default=())
    reverse_via_stop: bool = True  # the follower's reversal procedure (False: ζ flipped at once)
    alpha_rate: float | None = None  # the follower's limit on every rise of the α command (per sim s)
    reverse_alpha_rate: float | None = REVERSE_ALPHA_RATE  # ... on the rise after a reversal
    alpha_fall_rate: float | None = None  # cmd_vel.alpha_fall_rate (None: config/cpg.yaml's)
    governed: bool = True  # the governor between the follower and the CPG, as in cpg_node
    ankle: bool = True  # the ankle pathway may act (cpg_node: in lockstep; realtime: ankle_in_realtime)


def drive_set(quick: bool = False) -> list[Drive]:
    """The commands of the check: forward, backward, left, right, combined, a turn then straight (does
    it hold the new heading), and every drive stops on the timeout after its last command."""
    fwd = [0.02, 0.04, 0.06, 0.085, 0.1, 0.13]
    back = [-0.04, -0.085, -0.1]
    turns = [(0.085, 0.05), (0.085, 0.1), (0.085, 0.15), (0.085, -0.1), (0.085, -0.15), (0.05, 0.1),
             (-0.085, 0.1)]
    if quick:
        fwd, back, turns = [0.085], [-0.085], [(0.085, 0.1), (0.085, -0.1)]
    d = [Drive(f"v {v:+g}", ((35.0, v, 0.0),)) for v in fwd]
    # backward from the forward walk: a reversal first (stop, swap, α ramp ~20 s): measured after it
    d += [Drive(f"v {v:+g}", ((55.0, v, 0.0),)) for v in back]
    d += [Drive(f"v {v:+g} w {w:+g}", ((35.0 if v > 0 else 55.0, v, w),)) for v, w in turns]
    if not quick:
        d += [Drive(f"v +0.085 w {w:+g}", ((35.0, 0.085, w),)) for w in (0.2, -0.2, 0.3)]
        d.append(Drive("turn then straight", ((30.0, 0.085, 0.1), (45.0, 0.085, 0.0))))
        d.append(Drive("+0.085 -> stand -> +0.085",
                       ((25.0, 0.085, 0.0), (35.0, 0.0, 0.0), (55.0, 0.085, 0.0))))
        # direction changes: ours (stop, swap ζ, step with α ramping at REVERSE_ALPHA_RATE), the same
        # without the ramp, and ζ flipped at once
        for how, via, rate in (("stop-swap-ramp", True, REVERSE_ALPHA_RATE),
                               ("stop-swap, no ramp", True, None), ("zeta flipped at once", False, None)):
            for (v1, t1), (v2, t2) in (((0.11, 25.0), (-0.1, 70.0)), ((0.085, 25.0), (-0.085, 70.0)),
                                       ((0.085, 25.0), (-0.03, 45.0)), ((-0.085, 55.0), (0.085, 100.0))):
                d.append(Drive(f"{v1:+g} -> {v2:+g} ({how})", ((t1, v1, 0.0), (t2, v2, 0.0)),
                               reverse_via_stop=via, reverse_alpha_rate=rate))
    return d


class DrivenSource:
    """A FeedbackGaitSource driven by a CmdVelFollower: before each tick's ``observe`` the Twist
    commands due are given to the follower and its output applied (walker/cmd_vel.py apply_output), as
    cpg_node does on each /clock tick. Logs (t, ζ cmd, α cmd, turn rate, state) every 0.1 s."""

    def __init__(self, source, follower: CmdVelFollower, commands: list[tuple[float, ...]]):
        self.src, self.follower = source, follower
        self.names = source.names
        self.commands = commands  # (t, vx, wz, vy), sorted
        self.log: list[tuple[float, float, float, float, str]] = []
        self._next_log = 0.0

    def observe(self, t, quat_wxyz, gyro, loads) -> None:
        src = self.src
        while self.commands and self.commands[0][0] <= t + 1e-9:
            _, vx, wz, vy = self.commands.pop(0)
            self.follower.command(t, vx, wz, vy)
        if t >= src.active_from:
            out = self.follower.update(t, src.ctrl.zeta, src.ctrl.alpha)
            if out is not None:
                apply_output(src, out)
        src.observe(t, quat_wxyz, gyro, loads)
        if t >= self._next_log - 1e-9:
            c = src.ctrl
            self.log.append((round(t, 3), c.zeta_command, c.alpha_command, src.fb.turn_rate,
                             self.follower.state))
            self._next_log = t + 0.1

    def targets(self, t):
        return self.src.targets(t)


def driven_source(drive: Drive, map_file: str | None = None) -> tuple[DrivenSource, SpeedMap, CmdVelLimits]:
    """The drive's target source as cpg_node would apply its Twists (the follower, the governor unless
    ``drive.governed`` is false, the ankle pathway as ``drive.ankle``), with the speed map and limits."""
    from cpg_walker.experiments.walk_runs import _controller
    from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController
    from cpg_walker.walker.gait_source import FeedbackGaitSource
    from cpg_walker.walker.governor import GovernorConfig

    smap = SpeedMap.load(map_file or default_map_file())
    limits = CmdVelLimits.load(**({} if drive.alpha_fall_rate is None
                                  else {"alpha_fall_rate": drive.alpha_fall_rate}))
    fb = FeedbackController(FeedbackConfig.load())
    fb.ankle_allowed = drive.ankle
    src = FeedbackGaitSource(_controller(), fb, governor=GovernorConfig.load() if drive.governed else None)
    follower = CmdVelFollower(smap, limits, zeta=1.0)
    follower.reverse_via_stop = drive.reverse_via_stop
    follower.alpha_rate = drive.alpha_rate
    follower.reverse_alpha_rate = drive.reverse_alpha_rate
    cmds, t = [], drive.t0
    for until, vx, wz, vy in _segments(drive):
        while t < until - 1e-9:
            cmds.append((round(t, 6), vx, wz, vy))
            t += 1.0 / drive.rate_hz
    return DrivenSource(src, follower, cmds), smap, limits


def drive_duration(drive: Drive) -> float:
    """Sim s the drive's walk lasts: its last segment's end plus the tail."""
    return drive.segments[-1][0] + drive.tail_s


def run_drive(drive: Drive, map_file: str | None = None) -> dict:
    """One drive in-process: the trajectory's measured speed/turn per window and the stop."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.loop import run_replay

    driven, smap, limits = driven_source(drive, map_file)
    t_last = driven.commands[-1][0]
    sim = Hoap2Sim()
    sim.reset()
    r = run_replay(sim, driven, PidLaw.from_config(), drive_duration(drive))
    out: dict = {"label": drive.label, "fell": bool(r.fell),
                 "fall_time_s": None if r.fall_time_s is None else round(float(r.fall_time_s), 3),
                 "last_command_s": t_last, "timeout_s": limits.timeout, "segments": []}
    start = drive.t0
    for k, (until, vx, wz, vy) in enumerate(_segments(drive)):
        a, b = drive.windows[k] if drive.windows else (start + 0.4 * (until - start), until)
        probe = CmdVelFollower(smap, limits, zeta=1.0)
        probe.command(0.0, vx, wz, vy)
        z, al, _ = probe.target
        seg = {"from_s": start, "to_s": until, "linear_x": vx, "linear_y": vy, "angular_z": wz,
               "clamped_linear_x": limits.clamp_linear(vx), "clamped_linear_y": limits.clamp_lateral(vy),
               "clamped_angular_z": limits.clamp_angular(wz),
               "zeta": round(z, 4), "alpha": round(al, 4), "window": [round(a, 2), round(b, 2)]}
        if not r.fell or (r.fall_time_s or 0) > b:
            seg.update(trajectory_rates(r, a, b))
        if not r.fell or (r.fall_time_s or 0) > until:
            seg["whole"] = whole_segment(r, start, until)
        out["segments"].append(seg)
        start = until
    if not r.fell:
        out.update(stop_metrics(r, t_last))
    out["log"] = driven.log[::5]
    return out


def _segments(drive: Drive) -> list[tuple[float, float, float, float]]:
    """The drive's segments as (until_s, linear_x, angular_z, linear_y)."""
    return [(float(s[0]), float(s[1]), float(s[2]), float(s[3]) if len(s) > 3 else 0.0)
            for s in drive.segments]


def trajectory_rates(r, t0: float, t1: float, chunk_s: float = 1.0) -> dict:
    """Forward speed (displacement along the stride-mean heading, summed over ``chunk_s`` pieces) and
    turn rate (stride-mean heading change) between sim times t0 and t1, and lateral speed."""
    edges = np.arange(t0, t1 + 1e-9, chunk_s)
    fwd = lat = 0.0
    for a, b in itertools.pairwise(edges):
        pa, pb = _xy_at(r, a), _xy_at(r, b)
        h = heading_at(r, 0.5 * (a + b))
        d = pb - pa
        fwd += float(d @ [math.cos(h), math.sin(h)])
        lat += float(d @ [-math.sin(h), math.cos(h)])
    span = float(edges[-1] - edges[0])
    dh = heading_at(r, float(edges[-1])) - heading_at(r, float(edges[0]))
    return {"speed_mps": round(fwd / span, 4), "lateral_mps": round(lat / span, 4),
            "turn_rate_rad_s": round(dh / span, 4), "turn_rate_deg_s": round(math.degrees(dh / span), 2)}


def moved(t: np.ndarray, xy: np.ndarray, yaw: np.ndarray, a: float, b: float) -> tuple[float, float]:
    """(forward, sideways) displacement of a base trajectory (times ``t``, positions ``xy``, unwrapped
    ``yaw``) between times a and b: 1 s pieces, each along (and across) its mean heading."""
    fwd = side = 0.0
    edges = np.append(np.arange(a, b - 1e-9, 1.0), b)
    for c0, c1 in itertools.pairwise(edges):
        i0, i1 = (min(int(np.searchsorted(t, c)), len(t) - 1) for c in (c0, c1))
        h = float(np.mean(yaw[i0:i1 + 1]))
        d = xy[i1] - xy[i0]
        fwd += float(d @ [math.cos(h), math.sin(h)])
        side += float(d @ [-math.sin(h), math.cos(h)])
    return fwd, side


def whole_segment(r, t0: float, t1: float) -> dict:
    """Over all of a segment (from its command on): the angle turned (the unwrapped yaw's change) and the
    displacement along and across the heading (``moved``)."""
    i0, i1 = (min(int(np.searchsorted(r.t, x)), len(r.t) - 1) for x in (t0, t1))
    fwd, side = moved(r.t, r.base_xy, r.heading, t0, t1)
    return {"turned_rad": round(float(r.heading[i1] - r.heading[i0]), 3), "forward_m": round(fwd, 3),
            "sideways_m": round(side, 3)}


def _xy_at(r, t: float) -> np.ndarray:
    i = min(int(np.searchsorted(r.t, t)), len(r.t) - 1)
    return r.base_xy[i]


def stop_metrics(r, t_last: float) -> dict:
    """The stop after the last command at ``t_last``: last touchdown after it (s after t_last), the time
    the 1 s-window base speed first falls below 0.01 m/s, distance and heading change from then to the
    end."""
    tds = [x for side in ("left", "right") for x in r.touchdowns[side] if x > t_last]
    stopped_at = None
    for t in np.arange(t_last, float(r.t[-1]) - 1.0 + 1e-9, 0.1):
        if float(np.linalg.norm(_xy_at(r, t + 1.0) - _xy_at(r, t))) < 0.01:
            stopped_at = float(t)
            break
    out = {"steps_after_last_command": len(tds),
           "last_touchdown_after_s": round(max(tds) - t_last, 3) if tds else 0.0,
           "speed_below_1cm_s_after_s": None if stopped_at is None else round(stopped_at - t_last, 2)}
    if stopped_at is not None:
        d = r.base_xy[-1] - _xy_at(r, stopped_at)
        out["drift_after_stop_m"] = round(float(np.linalg.norm(d)), 4)
    return out


def markdown_table(runs: list[dict]) -> str:
    lines = ["| drive | linear.x cmd (clamped) | ζ, α | speed m/s | angular.z cmd (clamped) | "
             "turn °/s (rad/s) | lateral m/s | stop: last step / < 1 cm/s after last cmd |",
             "|---|---|---|---|---|---|---|---|"]
    for m in runs:
        if "error" in m:
            lines.append(f"| {m.get('label', '?')} | error: {m['error']} |||||||")
            continue
        stop = (f"{m['last_touchdown_after_s']:.2f} s / {m['speed_below_1cm_s_after_s']} s"
                if "last_touchdown_after_s" in m else "—")
        for s in m["segments"]:
            if "speed_mps" not in s:
                cell = f"F {m['fall_time_s']} s"
                lines.append(f"| {m['label']} | {s['linear_x']:+g} ({s['clamped_linear_x']:+.3f}) | "
                             f"{s['zeta']:g}, {s['alpha']:g} | {cell} | {s['angular_z']:+g} | | | |")
                continue
            lines.append(
                f"| {m['label']} {s['window'][0]:g}–{s['window'][1]:g} s | {s['linear_x']:+g} "
                f"({s['clamped_linear_x']:+.3f}) | {s['zeta']:g}, {s['alpha']:g} | {s['speed_mps']:+.3f} | "
                f"{s['angular_z']:+g} ({s['clamped_angular_z']:+.3f}) | {s['turn_rate_deg_s']:+.1f} "
                f"({s['turn_rate_rad_s']:+.3f}) | {s['lateral_mps']:+.3f} | {stop} |")
            stop = ""
    return "\n".join(lines) + "\n"


def plot(runs: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
    for m in runs:
        for s in m.get("segments", []):
            if "speed_mps" not in s:
                continue
            if s["angular_z"] == 0:
                a1.plot(s["linear_x"], s["speed_mps"], "o", color="C0")
            else:
                a1.plot(s["linear_x"], s["speed_mps"], "s", color="C1")
                a2.plot(s["angular_z"], s["turn_rate_rad_s"], "s", color="C1")
            if s["angular_z"] == 0 and s["linear_x"] != 0:
                a2.plot(0.0, s["turn_rate_rad_s"], "o", color="C0")
    lim = max([abs(s["linear_x"]) for m in runs for s in m.get("segments", [])] + [0.1]) * 1.05
    a1.plot([-lim, lim], [-lim, lim], "k:", lw=0.8, label="actual = commanded")
    a1.set(xlabel="commanded linear.x (m/s)", ylabel="actual forward speed (m/s)",
           title="speed (o straight, s turning)")
    a1.legend(loc="upper left", fontsize=8)
    wl = max([abs(s["angular_z"]) for m in runs for s in m.get("segments", [])] + [0.1]) * 1.05
    a2.plot([-wl, wl], [-wl, wl], "k:", lw=0.8, label="actual = commanded")
    a2.set(xlabel="commanded angular.z (rad/s)", ylabel="actual turn rate (rad/s, stride mean)",
           title="turn rate")
    a2.legend(loc="upper left", fontsize=8)
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.axhline(0, color="k", lw=0.5)
        a.axvline(0, color="k", lw=0.5)
    fig.suptitle("/cmd_vel: commanded vs actual (in-process, ground truth base trajectory)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
