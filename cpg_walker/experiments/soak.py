"""Soak: the graph walking for minutes of sim time with a change every ``period`` s (``cpg-walker soak``).

sim_node (realtime pacing, or lockstep), pid_node and cpg_node as processes (experiments/faults.py's
FaultGraph); every ``period`` sim s the next change of PLAN: zeta/alpha through /cpg/set_parameters, or
a /cmd_vel (10 Hz for the window; after a ``stop`` the node's timeout makes the robot stand, and the next
parameter change, which holds until the next Twist, walks it on). Per window: the change, the speed over the
window (/odom/ground_truth), each node's resident memory (VmRSS from /proc), the sim's late commands and
cpg_node's overruns (their /diagnostics counters); at the end whether the robot fell, memory from the
first window to the last and the overruns' rate in the first and last third.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.nodes import interface as ifc

#: The changes, cycled: ("param", zeta, alpha) or ("cmd_vel", linear.x m/s, angular.z rad/s) or ("stop",).
PLAN: tuple[tuple, ...] = (
    ("param", 1.0, 1.0), ("param", 1.15, 1.0), ("param", 1.15, 0.8), ("param", 0.85, 1.0),
    ("cmd_vel", 0.085, 0.0), ("cmd_vel", 0.07, 0.08), ("cmd_vel", 0.07, -0.08), ("stop",),
)
NODES = ("sim_node", "pid_node", "cpg_node")
CMD_VEL_HZ = 10.0


def rss_mib(pid: int) -> float | None:
    """Resident memory of process ``pid`` in MiB (None if it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def describe(change: tuple) -> str:
    if change[0] == "param":
        return f"zeta {change[1]:g}, alpha {change[2]:g}"
    if change[0] == "cmd_vel":
        return f"/cmd_vel {change[1]:g} m/s, {change[2]:g} rad/s"
    return "/cmd_vel stops (timeout: stand)"


class Counters:
    """The newest /diagnostics values of the sim and cpg_node that the soak follows."""

    def __init__(self) -> None:
        self.late = 0
        self.overruns = 0

    def on_diagnostics(self, msg) -> None:
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if st.name == "cpg_walker/sim" and "late_commands" in values:
                self.late = int(values["late_commands"])
            elif st.name == "cpg_walker/cpg" and "overruns" in values:
                self.overruns = int(values["overruns"])


def _trend(series: list[float]) -> dict:
    """Per-window increments of a counter: their mean over the first and the last third."""
    inc = [b - a for a, b in itertools.pairwise(series)]
    n = max(1, len(inc) // 3)
    first, last = inc[:n], inc[-n:]
    return {"per_window_first_third": round(sum(first) / len(first), 2) if first else None,
            "per_window_last_third": round(sum(last) / len(last), 2) if last else None}


def run_soak(out_dir: str | Path, minutes: float = 10.0, period: float = 20.0, pacing: str = "realtime",
             say=print) -> dict:
    """Walk ``minutes`` of sim time with a change every ``period`` s (the sim's ``pacing``); write
    DIR/soak.json; return it."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from cpg_walker.experiments.faults import FaultGraph

    if not (minutes > 0 and period > 0 and math.isfinite(minutes * period)):
        raise InputError(f"minutes and period must be positive, got {minutes}, {period}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n_windows = max(1, round(minutes * 60.0 / period))
    windows: list[dict] = []
    wall0 = time.monotonic()
    with FaultGraph(out, zeta=1.0, say=say, pacing=pacing) as g:
        g.start()
        node = g._node
        counters = Counters()
        node.create_subscription(DiagnosticArray, ifc.DIAGNOSTICS, counters.on_diagnostics, 50)
        cmd_pub = node.create_publisher(Twist, ifc.CMD_VEL, 10)
        client = node.create_client(SetParameters, "/cpg/set_parameters")
        g.wait(lambda: client.service_is_ready(), 600.0, "/cpg/set_parameters")
        g.wait_sim(period, 600.0)  # the start-up (the recording's opening steps, the hand-over)

        def set_params(zeta: float, alpha: float) -> str:
            req = SetParameters.Request(parameters=[
                Parameter(name=n, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v))
                for n, v in (("zeta", zeta), ("alpha", alpha))])
            fut = client.call_async(req)
            g.wait(fut.done, 60.0, "/cpg/set_parameters answer")
            bad = [r.reason for r in fut.result().results if not r.successful]
            return "; ".join(bad)

        for k in range(n_windows):
            change = PLAN[k % len(PLAN)]
            t0 = g.odom.t
            refused = set_params(change[1], change[2]) if change[0] == "param" else ""
            end = t0 + period
            if change[0] == "cmd_vel":
                msg = Twist()
                msg.linear.x, msg.angular.z = float(change[1]), float(change[2])
                next_send = 0.0
                while g.odom.t < end and g.odom.fell_at is None:
                    if time.monotonic() >= next_send:
                        cmd_pub.publish(msg)
                        next_send = time.monotonic() + 1.0 / CMD_VEL_HZ
                    g.spin(0.02)
            else:
                g.wait(lambda end=end: g.odom.t >= end or g.odom.fell_at is not None, 600.0 + 10 * period,
                       f"sim time {end:.1f} s")
            speed = g.odom.speed(period * 0.5)
            row = {"window": k, "from_s": round(t0, 2), "change": describe(change),
                   "speed_mps": None if speed is None else round(speed, 4),
                   "rss_mib": {n: (None if (r := rss_mib(g.graph.procs[n].pid)) is None else round(r, 1))
                               for n in NODES},
                   "late_commands": counters.late, "cpg_overruns": counters.overruns,
                   "fell": g.odom.fell_at is not None, "wall_s": round(time.monotonic() - wall0, 1)}
            if refused:
                row["refused"] = refused
            windows.append(row)
            say(f"[{k + 1}/{n_windows}] sim {g.odom.t:.1f} s: {row['change']}; speed {row['speed_mps']} m/s; "
                f"RSS {row['rss_mib']} MiB; late {counters.late}, overruns {counters.overruns}")
            if g.odom.fell_at is not None:
                say(f"fell at {g.odom.fell_at:.2f} s")
                break
        fell_at = g.odom.fell_at
    first, last = windows[0], windows[-1]
    report = {
        "minutes": minutes, "period_s": period, "pacing": pacing, "windows_run": len(windows),
        "fell": fell_at is not None,
        "fell_at_s": fell_at, "wall_s": round(time.monotonic() - wall0, 1),
        "rss_mib": {n: {"first_window": first["rss_mib"][n], "last_window": last["rss_mib"][n],
                        "max": max((w["rss_mib"][n] or 0.0) for w in windows)} for n in NODES},
        "late_commands": _trend([w["late_commands"] for w in windows]),
        "cpg_overruns": _trend([w["cpg_overruns"] for w in windows]),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "windows": windows,
    }
    (out / "soak.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def markdown(report: dict) -> str:
    """The soak's summary table (docs/soak.md)."""
    rows = ["| node | RSS first window (MiB) | RSS last window (MiB) | max |", "|---|---|---|---|"]
    for n, r in report["rss_mib"].items():
        rows.append(f"| {n} | {r['first_window']} | {r['last_window']} | {r['max']} |")
    lc, ov = report["late_commands"], report["cpg_overruns"]
    fell = f"at {report['fell_at_s']:.2f} s" if report["fell"] else "no"
    rows += ["", f"{report['windows_run']} windows of {report['period_s']:g} s, fell: {fell}; "
             "late commands per window "
             f"{lc['per_window_first_third']} (first third) -> {lc['per_window_last_third']} (last third); "
             f"cpg overruns per window {ov['per_window_first_third']} -> {ov['per_window_last_third']}."]
    return "\n".join(rows) + "\n"
