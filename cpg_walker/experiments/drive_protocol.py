"""``cpg-walker drive-check`` (``drive_check``: experiments/cmd_vel.py's drives, then the steering
protocol) — the protocol (in-process, through the follower as cpg_node applies
it): each command — forward, backward, sideways, turning in place — raised step by step, ``STEP_S`` sim s
per step, until the robot falls or the command ends; per step the achieved speed (or turn rate) over its
second half. Beside it: combined commands, commanded vs achieved, and the kid-size anchors of the issue
(Bestmann & Zhang 2022, walk engines in simulation: Darwin-OP2 and NAO) absolute and Froude-scaled
(v / √(g·l), l the leg length; a turn rate ω / √(g / l)).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cpg_walker.experiments.cmd_vel import (
    CmdVelLimits,
    Drive,
    SpeedMap,
    default_map_file,
    drive_set,
    markdown_table,
    plot,
    run_drive,
)
from cpg_walker.experiments.walk_runs import run_many

#: sim s per protocol step
STEP_S = 10.0
#: each axis: (the Twist field raised, its steps); backward's first step is longer (the reversal from the
#: forward walk the drive starts in takes ~20 s: stop, swap ζ, α ramp)
AXES: dict[str, tuple[str, tuple[float, ...]]] = {
    "forward": ("linear_x", (0.03, 0.06, 0.09, 0.12, 0.15, 0.18)),
    "backward": ("linear_x", (-0.03, -0.06, -0.09, -0.12, -0.15)),
    "sideways": ("linear_y", (0.01, 0.02, 0.03, 0.04, 0.05, 0.06)),
    "turn in place": ("angular_z", (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)),
}
FIRST_STEP_S = {"backward": 30.0}
#: combined commands (linear.x, linear.y, angular.z), 30 s each, measured over the last 60 %
COMBINED: tuple[tuple[float, float, float], ...] = (
    (0.08, 0.0, 0.3), (0.08, 0.0, -0.3), (0.05, 0.0, 0.2), (-0.08, 0.0, 0.3), (0.05, 0.02, 0.0),
    (0.0, 0.02, 0.2))
COMBINED_S = 30.0
#: the must-show's turn in place (0.5 rad/s for 10 s) from the walk at each of these instants (sim s,
#: 0.1 s apart: the gait's phase at the command varies as it does between realtime runs), without the ankle
#: pathway as cpg_node in realtime
TURN_STARTS = tuple(round(8.0 + 0.1 * k, 1) for k in range(20))
TURN_RATE, TURN_S = 0.5, 10.0
G = 9.81
#: (robot, height m, leg length m, forward, backward, sideways m/s, turn rad/s). Speeds: Bestmann & Zhang
#: 2022 (the issue's anchors). Leg lengths: hip pitch axis to sole, from the makers' kinematics (Darwin-OP:
#: thigh 93 + calf 93 + ankle 33.5 mm; NAO: thigh 100 + tibia 102.9 + foot height 45.19 mm).
ANCHORS = (("Darwin-OP2", 0.455, 0.2195, 0.29, 0.29, 0.12, 2.47),
           ("NAO", 0.574, 0.2481, 0.58, 0.43, 0.25, 0.85))


def leg_length() -> float:
    """HOAP-2's leg length (m): the left hip pitch axis to the left sole in the zero posture (the MJCF)."""
    import mujoco
    import numpy as np

    from cpg_walker.robot.hoap2 import Hoap2Sim

    m = Hoap2Sim().model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    return float(np.linalg.norm(d.xanchor[m.joint("lleg_joint_3").id] - d.xpos[m.body("lleg_sole").id]))


def axis_drive(name: str) -> Drive:
    """The staircase of one axis as a Drive (segments of (until, linear.x, angular.z, linear.y))."""
    field, steps = AXES[name]
    t, segs = 10.0, []
    for k, v in enumerate(steps):
        t += FIRST_STEP_S.get(name, STEP_S) if k == 0 else STEP_S
        vx, wz, vy = (v if field == f else 0.0 for f in ("linear_x", "angular_z", "linear_y"))
        segs.append((t, vx, wz, vy))
    return Drive(f"protocol {name}", tuple(segs), windows=tuple((u - STEP_S / 2, u) for u, *_ in segs))


def combined_drive(cmd: tuple[float, float, float]) -> Drive:
    vx, vy, wz = cmd
    t0 = 10.0 if vx >= 0 else 30.0  # backward: after the reversal
    return Drive(f"combined x {vx:+g} y {vy:+g} z {wz:+g}", ((t0 + COMBINED_S, vx, wz, vy),), t0=t0)


def protocol_drives() -> list[Drive]:
    return [axis_drive(n) for n in AXES] + [combined_drive(c) for c in COMBINED]


def turn_drives() -> list[Drive]:
    """The turn in place from each of TURN_STARTS."""
    return [Drive(f"turn in place from {t:g} s", ((t + TURN_S, 0.0, TURN_RATE),), t0=t, tail_s=2.0,
                  ankle=False) for t in TURN_STARTS]


def turn_summary(runs: list[dict]) -> dict:
    """The angle each turn in place turned in its TURN_S (None where it fell), the least, the mean."""
    turned = [None if r["fell"] else r["segments"][0]["whole"]["turned_rad"] for r in runs]
    done = [x for x in turned if x is not None]
    return {"rate_rad_s": TURN_RATE, "duration_s": TURN_S, "starts_s": list(TURN_STARTS),
            "turned_rad": turned, "fell": sum(x is None for x in turned),
            "least_rad": min(done) if done else None,
            "mean_rad": round(sum(done) / len(done), 3) if done else None}


def froude(v: float, leg_m: float) -> float:
    return v / math.sqrt(G * leg_m)


def turn_scaled(w: float, leg_m: float) -> float:
    return w / math.sqrt(G / leg_m)


def summarize(runs: list[dict], leg_m: float) -> dict:
    """Per axis: each step's command and achieved value (the axis's own: speed, lateral speed or turn
    rate), the best achieved and where the robot fell; the combined commands; HOAP-2 beside the anchors."""
    key = {"linear_x": "speed_mps", "linear_y": "lateral_mps", "angular_z": "turn_rate_rad_s"}
    axes = {}
    for name, run in zip(AXES, runs, strict=False):
        field = AXES[name][0]
        steps = [{"command": s[field], "clamped": s.get(f"clamped_{field}"),
                  "achieved": s.get(key[field])} for s in run["segments"]]
        done = [s["achieved"] for s in steps if s["achieved"] is not None]
        best = max(done, key=abs) if done else None
        axes[name] = {"field": field, "steps": steps, "best": best, "fell": run["fell"],
                      "fall_time_s": run["fall_time_s"]}
    combined = []
    for run in runs[len(AXES):]:
        s = run["segments"][0]
        combined.append({"linear_x": s["linear_x"], "linear_y": s["linear_y"], "angular_z": s["angular_z"],
                         "fell": run["fell"], **{k: s.get(k) for k in ("speed_mps", "lateral_mps",
                                                                       "turn_rate_rad_s", "zeta", "alpha")}})
    ours = [("HOAP-2 (ours)", 0.4975, leg_m, *(abs(axes[n]["best"] or 0.0) for n in AXES))]
    table = []
    for robot, h, leg, f, b, s, w in (*ours, *ANCHORS):
        table.append({"robot": robot, "height_m": h, "leg_m": round(leg, 4), "forward_mps": round(f, 4),
                      "backward_mps": round(b, 4), "sideways_mps": round(s, 4), "turn_rad_s": round(w, 3),
                      "froude": {k: round(froude(v, leg), 3) for k, v in
                                 (("forward", f), ("backward", b), ("sideways", s))},
                      "turn_scaled": round(turn_scaled(w, leg), 3)})
    return {"step_s": STEP_S, "axes": axes, "combined": combined, "anchors": table}


def markdown(p: dict) -> str:
    lines = ["Protocol (in-process, each command raised every "
             f"{p['step_s']:g} sim s; achieved over each step's second half):", "",
             "| command | steps: commanded (clamped) → achieved | best | fell |", "|---|---|---|---|"]
    for name, a in p["axes"].items():
        cells = ", ".join(f"{s['command']:+g}" + (f" ({s['clamped']:+g})" if s["clamped"] not in
                                                   (None, s["command"]) else "")
                          + f" → {'fell' if s['achieved'] is None else format(s['achieved'], '+.3f')}"
                          for s in a["steps"])
        fell = f"at {a['fall_time_s']:g} s" if a["fell"] else "no"
        best = "—" if a["best"] is None else f"{a['best']:+.3f}"
        lines.append(f"| {name} ({a['field']}) | {cells} | {best} | {fell} |")
    lines += ["", "| robot | height m | leg m | forward m/s (Fr) | backward m/s (Fr) | sideways m/s (Fr) | "
              "turn rad/s (ω/√(g/l)) |", "|---|---|---|---|---|---|---|"]
    for r in p["anchors"]:
        fr = r["froude"]
        lines.append(f"| {r['robot']} | {r['height_m']:g} | {r['leg_m']:g} | {r['forward_mps']:.3f} "
                     f"({fr['forward']:.3f}) | {r['backward_mps']:.3f} ({fr['backward']:.3f}) | "
                     f"{r['sideways_mps']:.3f} ({fr['sideways']:.3f}) | {r['turn_rad_s']:.3f} "
                     f"({r['turn_scaled']:.3f}) |")
    lines += ["", "| combined: linear.x, linear.y, angular.z | ζ, α | achieved: forward m/s, sideways m/s, "
              "turn rad/s | fell |", "|---|---|---|---|"]
    for c in p["combined"]:
        got = ("—" if c["speed_mps"] is None else
               f"{c['speed_mps']:+.3f}, {c['lateral_mps']:+.3f}, {c['turn_rate_rad_s']:+.3f}")
        lines.append(f"| {c['linear_x']:+g}, {c['linear_y']:+g}, {c['angular_z']:+g} | {c['zeta']:g}, "
                     f"{c['alpha']:.3g} | {got} | {'yes' if c['fell'] else 'no'} |")
    return "\n".join(lines) + "\n"


def drive_check(out: str | Path, jobs: int = 2, quick: bool = False, map_file: str | None = None,
                progress=None) -> dict:
    """Run experiments/cmd_vel.py's ``drive_set`` and (not ``quick``) the steering protocol and the turn in
    place from TURN_STARTS; write DIR/drive_check.json (``runs``, ``protocol``, ``turn_in_place``),
    drive_check.md and drive_check.png."""
    from functools import partial

    drives = drive_set(quick)
    extra = [] if quick else protocol_drives()
    turns = [] if quick else turn_drives()
    runs = run_many(partial(run_drive, map_file=map_file), drives + extra + turns, jobs=jobs,
                    progress=progress)
    runs, proto_runs, turn_runs = (runs[:len(drives)], runs[len(drives):len(drives) + len(extra)],
                                   runs[len(drives) + len(extra):])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    res = {"limits": CmdVelLimits.load().as_dict(),
           "map_file": SpeedMap.load(map_file or default_map_file()).origin, "runs": runs}
    text = markdown_table(runs)
    if proto_runs:
        res["protocol"] = {**summarize(proto_runs, leg_length()), "runs": proto_runs}
        text += "\n" + markdown(res["protocol"])
    if turn_runs:
        t = res["turn_in_place"] = turn_summary(turn_runs)
        text += (f"\nTurn in place at {t['rate_rad_s']:g} rad/s for {t['duration_s']:g} s from the walk at "
                 f"{len(t['starts_s'])} instants {t['starts_s'][0]:g}–{t['starts_s'][-1]:g} s (without the "
                 f"ankle pathway, as cpg_node in realtime): turned {t['least_rad']} rad at least, "
                 f"{t['mean_rad']} on average; fell in {t['fell']}.\n")
    (out / "drive_check.json").write_text(json.dumps(res, indent=1) + "\n")
    (out / "drive_check.md").write_text(text)
    plot(runs, out / "drive_check.png")
    return res
