"""Driving by /cmd_vel through the ROS graph (``cpg-walker drive-check --graph --out DIR``): start the graph
exactly as ``cpg-walker graph`` does (that command, in a subprocess, lockstep pacing, on a free DDS domain),
or attach to one already running (``--attach --domain-id N``), then from this process publish
geometry_msgs/Twist on /cmd_vel at 10 Hz of sim time (forward, forward + left, forward + right, then
nothing: the timeout) and measure from /odom/ground_truth: the forward speed (displacement along the
stride-mean heading, 1 s pieces), the turn rates (a line fitted to the unwrapped yaw over each window: the
within-stride sway averages out) and the stop after the last command (when the base moves < 1 cm in 1 s);
cpg_node's /diagnostics give the time its cmd_vel state turned ``timed_out``, the sim's latched /sim/fallen
whether and about when (the newest odometry then) the robot fell. DIR/drive_graph.json, .md.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.experiments.cmd_vel import moved
from cpg_walker.nodes import interface as ifc

#: (name, duration s, linear.x, angular.z, settle s[, linear.y]) after the start, then ``STOP_S`` without
#: commands; each window's first ``settle`` s are left out of the rates (the gait changes first); the
#: turned angle and the sideways displacement are over the whole window.
PLAN = (("forward", 12.0, 0.085, 0.0, 4.0), ("left", 20.0, 0.085, 0.1, 8.0),
        ("right", 20.0, 0.085, -0.1, 8.0))
#: Steering like a walking base: turn in place, side-step, then forward at (or clamped to) 0.15 m/s.
STEER_PLAN = (("turn in place", 10.0, 0.0, 0.5, 3.0), ("side step", 20.0, 0.0, 0.0, 6.0, 0.05),
              ("forward", 20.0, 0.15, 0.0, 13.0))
PLANS = {"drive": PLAN, "steer": STEER_PLAN}
STOP_S = 8.0
#: A fresh graph: the first Twist at this sim time (the CPG has taken over the recording at ~6.6 s).
START_S = 8.0
RATE_HZ = 10.0
#: wall s without /odom/ground_truth after which the drive gives up (the graph is not there or stopped)
NO_ODOM_S = 30.0


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def drive_graph(out: str | Path, domain_id: int | None = None, attach: bool = False,
                wall_limit_s: float = 1800.0, plan: str = "drive", pacing: str = "lockstep",
                params: list[str] | None = None) -> dict:
    """Run a plan (``PLANS``: "drive" the module docstring's, "steer" STEER_PLAN) against a graph started
    with ``pacing`` and the ``cpg-walker graph -p`` ``params`` (or attached to); write and return the
    measurements."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from std_msgs.msg import Bool

    from cpg_walker.graph.probe import Probe
    from cpg_walker.graph.processes import env_domain_id, interrupt_group, isolated_env, quiet_domain_id
    from cpg_walker.graph.runner import resolve_domain

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if attach and domain_id is None:
        env = env_domain_id()
        domain_id = 0 if env is None else env
    domain = quiet_domain_id() if domain_id is None else resolve_domain(int(domain_id))[0]  # 0..232
    if plan not in PLANS:
        raise InputError(f"unknown drive plan {plan!r}; choose from {sorted(PLANS)}")
    steps = PLANS[plan]
    total = sum(p[1] for p in steps) + STOP_S
    proc = None
    if not attach:
        cmd = [sys.executable, "-m", "cpg_walker.cli.main", "graph", "--pacing", pacing, "--duration",
               str(START_S + total), "--domain-id", str(domain), "--log-dir", str(out / "logs"),
               *(a for p in params or () for a in ("-p", p))]
        proc = subprocess.Popen(cmd, env=isolated_env(domain), stdout=open(out / "graph.log", "w"),
                                stderr=subprocess.STDOUT, start_new_session=True)
    probe = Probe(domain, "drive_check", parameter_services=False)
    odom: list[tuple[float, float, float, float]] = []
    cmd_state: list[tuple[float, str]] = []
    applied: list[tuple] = []  # (sim s, cmd_vel state, applied ζ, applied α, turn rate commanded)
    fallen: list[float] = []  # sim s (the newest odometry) when /sim/fallen said true

    def on_fallen(m: Bool) -> None:
        if m.data and not fallen:
            fallen.append(odom[-1][0] if odom else float("nan"))

    from cpg_walker.experiments.odometry import OdomWatcher

    est = OdomWatcher()  # /odom (odom_node's estimate) beside the truth, by stamp

    def on_odom(m: Odometry) -> None:
        est.on_truth(m)
        p = m.pose.pose
        odom.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, p.position.x, p.position.y,
                     _yaw(p.orientation)))

    def on_diag(m: DiagnosticArray) -> None:
        for s in m.status:
            if s.name == "cpg_walker/cpg":
                v = {kv.key: kv.value for kv in s.values}
                if "cmd_vel" in v:
                    ts = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                    cmd_state.append((ts, v["cmd_vel"]))
                    applied.append((round(ts, 3), v["cmd_vel"], *(float(v.get(k, "nan")) for k in (
                        "zeta", "alpha", "cmd_vel_turn_rate"))))

    probe.subscribe(ifc.ODOM_GROUND_TRUTH, Odometry, on_odom, 200)
    probe.subscribe(ifc.ODOM, Odometry, est.on_estimate, 200)
    probe.subscribe(ifc.DIAGNOSTICS, DiagnosticArray, on_diag, 50)
    probe.subscribe(ifc.SIM_FALLEN, Bool, on_fallen, ifc.latched_qos())
    pub = probe.node.create_publisher(Twist, ifc.CMD_VEL, 10)
    executor = probe.executor
    sent: list[tuple[float, float, float]] = []
    t0 = None
    end_wall = time.monotonic() + wall_limit_s
    seen, stalled = [0, time.monotonic()], False  # [odometry messages, wall time the count last grew]
    next_pub = 0.0
    last_report = 0.0
    try:
        while time.monotonic() < end_wall:
            executor.spin_once(timeout_sec=0.01)
            for _ in range(50):  # the backlog too: the sim time seen here is the newest odometry's
                executor.spin_once(timeout_sec=0.0)
            if proc is not None and proc.poll() is not None:
                break
            if len(odom) != seen[0]:
                seen[:] = [len(odom), time.monotonic()]
            elif time.monotonic() - seen[1] > NO_ODOM_S:  # the graph is gone (or was never there)
                stalled = True
                break
            if not odom:
                continue
            t = odom[-1][0]
            if t0 is None:
                t0 = max(START_S, t + 1.0) if not attach else t + 1.0
                next_pub = t0
            if t >= t0 + total:
                break
            if t >= next_pub:
                seg = _segment(steps, t - t0)
                if seg is not None:
                    msg = Twist()
                    msg.linear.x, msg.angular.z = seg[2], seg[3]
                    msg.linear.y = seg[5] if len(seg) > 5 else 0.0
                    pub.publish(msg)
                    sent.append((round(t, 3), seg[2], seg[3], msg.linear.y))
                next_pub += 1.0 / RATE_HZ
            if time.monotonic() - last_report > 5.0:
                print(f"drive-check --graph: sim {t:.1f} / {t0 + total:.1f} s", file=sys.stderr, flush=True)
                last_report = time.monotonic()
    finally:
        probe.close()
        if proc is not None:
            interrupt_group(proc)
    where = f"see {out}/graph.log" if proc is not None else "is a graph running there?"
    if t0 is None or not sent:
        raise ValueError(f"no /odom/ground_truth from a graph on DDS domain {domain} ({where})")
    if stalled:
        raise InputError(f"/odom/ground_truth on DDS domain {domain} stopped for {NO_ODOM_S:g} s at sim "
                         f"{odom[-1][0]:.1f} s, before the plan's end ({where})")
    res = measure(np.array(odom), t0, sent, cmd_state, steps)
    res["fell"] = bool(fallen)
    res["fell_at_s"] = round(fallen[0], 2) if fallen else None
    res["odometry"] = odometry_error(est)
    res["applied"] = [list(a) for a in applied]  # cpg_node's /diagnostics, every 0.1 sim s
    res.update(domain_id=domain, attached=attach, plan_name=plan, plan=[list(p) for p in steps],
               stop_s=STOP_S, first_command_s=t0, pacing=None if attach else pacing,
               params=None if attach else list(params or ()))
    (out / "drive_graph.json").write_text(json.dumps(res, indent=2) + "\n")
    (out / "drive_graph.md").write_text(markdown(res))
    return res


#: sim s between the points the distance walked is summed over (about a stride: not the within-stride sway)
DISTANCE_STEP_S = 2.0


def odometry_error(est) -> dict | None:
    """/odom against /odom/ground_truth over the drive (experiments/odometry.py ``drift``; distance summed
    over DISTANCE_STEP_S pieces); None without /odom (no odom_node in the graph)."""
    if not est.est or not (set(est.est) & set(est.truth)):
        return None
    t = sorted(est.truth)
    return est.compare(list(np.arange(t[0] / 1e9, t[-1] / 1e9, DISTANCE_STEP_S)))


def _segment(steps: tuple, dt: float):
    t = 0.0
    for p in steps:
        if t <= dt < t + p[1]:
            return p
        t += p[1]
    return None


def _at(t: np.ndarray, v: np.ndarray, s: float):
    return v[min(int(np.searchsorted(t, s)), len(t) - 1)]


def measure(odom: np.ndarray, t0: float, sent: list, cmd_state: list, steps: tuple = PLAN) -> dict:
    """Per plan window: forward and sideways speed and turn rate after its settle time, the angle turned
    and the sideways displacement over all of it; the stop after the last command."""
    t, xy, yaw = odom[:, 0], odom[:, 1:3], np.unwrap(odom[:, 3])
    rows = []
    start = t0
    for name, dur, vx, wz, settle, *more in steps:
        vy = more[0] if more else 0.0
        whole = moved(t, xy, yaw, start, start + dur)
        turned = float(_at(t, yaw, start + dur) - _at(t, yaw, start))
        a, b = start + settle, start + dur
        sel = (t >= a) & (t <= b)
        rate = float(np.polyfit(t[sel], yaw[sel], 1)[0]) if sel.sum() > 10 else float("nan")
        fwd, side = moved(t, xy, yaw, a, b)
        span = b - a
        rows.append({"window": name, "from_s": round(a, 2), "to_s": round(b, 2), "linear_x": vx,
                     "linear_y": vy, "angular_z": wz, "speed_mps": round(fwd / span, 4),
                     "lateral_mps": round(side / span, 4), "turn_rate_rad_s": round(rate, 4),
                     "turn_rate_deg_s": round(math.degrees(rate), 2),
                     "whole": {"from_s": round(start, 2), "to_s": round(start + dur, 2),
                               "turned_rad": round(turned, 3), "forward_m": round(whole[0], 3),
                               "sideways_m": round(whole[1], 3)}})
        start += dur
    t_last = sent[-1][0]
    stopped = None
    for s in np.arange(t_last, t[-1] - 1.0, 0.1):
        i0, i1 = np.searchsorted(t, s), min(np.searchsorted(t, s + 1.0), len(t) - 1)
        if float(np.linalg.norm(xy[i1] - xy[i0])) < 0.01:
            stopped = float(s)
            break
    timed_out = next((ts for ts, st in cmd_state if ts > t_last and st == "timed_out"), None)
    return {"windows": rows, "last_command_s": t_last, "commands_sent": len(sent),
            "stopped_after_s": None if stopped is None else round(stopped - t_last, 2),
            "timed_out_after_s": None if timed_out is None else round(timed_out - t_last, 3),
            "end_s": round(float(t[-1]), 2)}


def markdown(res: dict) -> str:
    lines = ["| window (sim s) | linear.x | linear.y | angular.z | forward m/s | sideways m/s | turn rate "
             "rad/s (°/s) | whole window: turned rad, forward m, sideways m |",
             "|---|---|---|---|---|---|---|---|"]
    for w in res["windows"]:
        wh = w.get("whole", {})
        lines.append(f"| {w['window']} {w['from_s']:g}–{w['to_s']:g} | {w['linear_x']:+g} | "
                     f"{w.get('linear_y', 0.0):+g} | {w['angular_z']:+g} | {w['speed_mps']:+.3f} | "
                     f"{w.get('lateral_mps', 0.0):+.3f} | {w['turn_rate_rad_s']:+.3f} "
                     f"({w['turn_rate_deg_s']:+.1f}) | {wh.get('turned_rad', 0):+.2f}, "
                     f"{wh.get('forward_m', 0):+.2f}, {wh.get('sideways_m', 0):+.2f} |")
    lines.append("")
    lines.append(f"Last command at sim {res['last_command_s']:.2f} s; cpg_node timed out "
                 f"{res['timed_out_after_s']} s after it; the base moved < 1 cm/s from "
                 f"{res['stopped_after_s']} s after it.")
    od = res.get("odometry")
    if od:
        lines.append(f"/odom against /odom/ground_truth: {od['distance_m']:.2f} m walked and "
                     f"{od['turned_deg']:.0f}° turned over {od['duration_s']:.0f} s; position error "
                     f"{od['position_error_final_m']:.3f} m at the end ({od['position_error_final_pct']} % "
                     f"of the distance; max {od['position_error_max_pct']} %), yaw error "
                     f"{od['yaw_error_final_deg']:+.2f}°.")
    else:
        lines.append("No /odom (odom_node not in the graph).")
    if res.get("fell"):
        at = res["fell_at_s"]
        lines.append(f"The robot FELL (/sim/fallen): reported at about sim {at} s "
                     f"({at - res['last_command_s']:+.2f} s from the last command).")
    else:
        lines.append("No fall (/sim/fallen stayed false).")
    return "\n".join(lines) + "\n"
