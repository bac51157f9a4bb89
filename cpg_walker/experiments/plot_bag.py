"""``cpg-walker plot BAG --out DIR``: the plots people look at, from a recording (nodes/recording.py).

Read with rosbags; every time axis is the bag time (sim s). Written when the topics they need are there:

- ``targets_vs_states.png``: /joint_targets against /joint_states for the CPG's joints (the DOF names in
  /cpg/state's layout; without cpg_node, e.g. the recorded gait's player: the 10 joints whose targets
  move the most);
- ``tilt.png``: the torso's lateral roll and sagittal pitch from /imu's orientation
  (robot.hoap2.tilt_from_quat);
- ``sole_loads.png``: /foot_load/{left,right} force.z with the touchdowns of robot/contact.py's
  TouchdownDetector;
- ``modulation.png``: forward speed and heading (from /odom/ground_truth: the twist, in the base frame,
  rotated into the world; the yaw of the pose), and zeta/alpha: the parameter's value (``parameter_steps``:
  declared, then every change on /parameter_events) and the values the oscillators use (/diagnostics
  ``zeta``/``alpha``: cpg_node applies a command once it walks, smoothed);
- ``cpg_phases.png``: from /cpg/state (cpg_node's oscillator states, every monitor_period): each DOF's
  first oscillator's phase (mod 2 pi) and frequency. The phases stand still while cpg_node plays the
  recording's opening steps, and run from the hand-over to the CPG on.

The speed's average is over one gait cycle: 1 / the first oscillators' frequency at the start (ζ = 1),
or 1 s without /cpg/state.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.recording import read_topics

CPG_NODE = "/cpg"


def _t(samples: list) -> np.ndarray:
    return np.array([ns for ns, _ in samples], dtype=float) / 1e9


def _joints(samples: list, field: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(times, {joint: values}) of JointState messages' ``field`` (one entry per distinct stamp)."""
    seen: dict[int, Any] = {}
    for ns, m in samples:
        if len(getattr(m, field)):
            seen[ns] = m  # a re-sent state (lockstep) replaces the first, the same values
    t = np.array(sorted(seen), dtype=float) / 1e9
    names = list(seen[min(seen)].name) if seen else []
    values = {n: np.array([getattr(seen[k], field)[i] for k in sorted(seen)]) for i, n in enumerate(names)}
    return t, values


def cpg_dofs(state: list) -> list[str]:
    """The DOF names of /cpg/state's layout (``dof:a,b,...``), or [] without it."""
    for _, m in state:
        label = m.layout.dim[0].label if m.layout.dim else ""
        if label.startswith("dof:"):
            return label[4:].split(",")
    return []


def parameter_steps(events: list, diagnostics: list, name: str) -> list[tuple[float, float]]:
    """(sim s, value) of cpg_node's parameter ``name``: its declared value and each change on
    /parameter_events; when its declaration is not in the recording (the node started before the
    recorder was matched), the first ``<name>_command`` cpg_node reported on /diagnostics comes first."""
    out = []
    declared = False
    for ns, ev in events:
        if ev.node != CPG_NODE:
            continue
        for p in ev.new_parameters:
            if p.name == name and p.value.type == 3:  # PARAMETER_DOUBLE
                out.append((ns / 1e9, float(p.value.double_value)))
                declared = True
        for p in ev.changed_parameters:
            if p.name == name and p.value.type == 3:
                out.append((ns / 1e9, float(p.value.double_value)))
    reported = _diag_values(diagnostics, f"{name}_command")
    if not declared and reported:
        out.insert(0, reported[0])
    return sorted(out, key=lambda x: x[0])


def _diag_values(diagnostics: list, key: str, status: str = "cpg_walker/cpg") -> list[tuple[float, float]]:
    out = []
    for ns, arr in diagnostics:
        for st in arr.status:
            if st.name != status:
                continue
            for kv in st.values:
                if kv.key == key:
                    try:
                        out.append((ns / 1e9, float(kv.value)))
                    except ValueError:
                        pass
    return out


def _yaw(q: Any) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def odometry_series(odom: list) -> dict[str, np.ndarray]:
    """t, forward speed (m/s, the world-frame horizontal velocity along the heading), heading (rad,
    unwrapped), x, y from /odom/ground_truth."""
    t = _t(odom)
    heading = np.unwrap([_yaw(m.pose.pose.orientation) for _, m in odom])
    speed, xy = [], []
    for (_, m), h in zip(odom, heading, strict=True):
        q, v = m.pose.pose.orientation, m.twist.twist.linear
        w, x, y, z = q.w, q.x, q.y, q.z
        vx = (1 - 2 * (y * y + z * z)) * v.x + 2 * (x * y - w * z) * v.y + 2 * (x * z + w * y) * v.z
        vy = 2 * (x * y + w * z) * v.x + (1 - 2 * (x * x + z * z)) * v.y + 2 * (y * z - w * x) * v.z
        speed.append(vx * math.cos(h) + vy * math.sin(h))
        xy.append((m.pose.pose.position.x, m.pose.pose.position.y))
    xy_a = np.array(xy).reshape(-1, 2)
    return {"t": t, "speed": np.array(speed), "heading": heading, "x": xy_a[:, 0], "y": xy_a[:, 1]}


def _moving_average(t: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    if len(t) < 2:
        return x
    n = min(len(x), max(1, round(window_s / float(np.median(np.diff(t))))))  # a window at most the run
    kernel = np.ones(n)
    return np.convolve(x, kernel, mode="same") / np.convolve(np.ones_like(x), kernel, mode="same")


def _step_line(ax: Any, steps: list[tuple[float, float]], t_end: float, **kw: Any) -> None:
    if steps:
        ts = [s[0] for s in steps] + [t_end]
        vs = [s[1] for s in steps] + [steps[-1][1]]
        ax.step(ts, vs, where="post", **kw)


def plot_bag(bag: str | Path, out_dir: str | Path) -> dict:
    """Write the module's PNGs of recording ``bag`` into ``out_dir``; return a summary (files, topics'
    message counts, what was not plotted and why)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpg_walker.robot.contact import SIDES, TouchdownDetector
    from cpg_walker.robot.hoap2 import tilt_from_quat

    data = read_topics(bag)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[str] = []
    skipped: dict[str, str] = {}
    t_end = max((ns for v in data.values() for ns, _ in v), default=0) / 1e9

    def save(fig: Any, name: str) -> None:
        fig.tight_layout()
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        written.append(name)

    def need(name: str, *topics: str) -> bool:
        missing = [t for t in topics if not data.get(t)]
        if missing:
            skipped[name] = f"no messages on {', '.join(missing)}"
        return not missing

    if need("targets_vs_states.png", ifc.JOINT_TARGETS, ifc.JOINT_STATES):
        tt, targets = _joints(data[ifc.JOINT_TARGETS], "position")
        ts, states = _joints(data[ifc.JOINT_STATES], "position")
        dofs = [d for d in cpg_dofs(data.get(ifc.CPG_STATE, [])) if d in targets and d in states]
        if not dofs:
            moving = sorted((n for n in targets if n in states), key=lambda n: -np.ptp(targets[n]))
            dofs = moving[:10]
        rows = math.ceil(len(dofs) / 2)
        fig, axes = plt.subplots(rows, 2, figsize=(12, 1.9 * rows + 0.8), sharex=True, squeeze=False)
        for ax, name in zip(axes.T.ravel(), dofs, strict=False):
            ax.plot(tt, np.degrees(targets[name]), lw=1.0, label="target (/joint_targets)")
            ax.plot(ts, np.degrees(states[name]), lw=1.0, ls="--", label="state (/joint_states)")
            ax.set_ylabel(f"{name}\n(deg)", fontsize=8)
        axes[0, 0].legend(fontsize=7, loc="upper right")
        for ax in axes[-1]:
            ax.set_xlabel("sim time (s)")
        fig.suptitle("CPG joints: targets vs joint states")
        save(fig, "targets_vs_states.png")

    if need("tilt.png", ifc.IMU):
        imu = data[ifc.IMU]
        tilt = np.degrees([tilt_from_quat((o.w, o.x, o.y, o.z)) for o in (m.orientation for _, m in imu)])
        fig, ax = plt.subplots(figsize=(10, 3.5))
        ax.plot(_t(imu), tilt[:, 0], lw=1.0, label="lateral roll (> 0: leaning right)")
        ax.plot(_t(imu), tilt[:, 1], lw=1.0, label="sagittal pitch (> 0: leaning forward)")
        ax.set_xlabel("sim time (s)")
        ax.set_ylabel("torso tilt (deg)")
        ax.legend(fontsize=8)
        ax.set_title("Torso tilt from /imu orientation")
        save(fig, "tilt.png")

    touchdowns: dict[str, list[float]] = {}
    if need("sole_loads.png", ifc.FOOT_LOAD_LEFT, ifc.FOOT_LOAD_RIGHT):
        loads = {}
        for side in SIDES:
            seen = {ns: m.wrench.force.z for ns, m in data[ifc.foot_load_topic(side)]}
            loads[side] = seen
        stamps = sorted(set(loads["left"]) & set(loads["right"]))
        t = np.array(stamps, dtype=float) / 1e9
        detector = TouchdownDetector()
        for ns, ti in zip(stamps, t, strict=True):
            detector.update(float(ti), (loads["left"][ns], loads["right"][ns]))
        touchdowns = detector.events
        fig, ax = plt.subplots(figsize=(10, 3.5))
        for side, color in zip(SIDES, ("tab:blue", "tab:orange"), strict=True):
            ax.plot(t, [loads[side][ns] for ns in stamps], lw=1.0, color=color, label=f"{side} sole")
            for i, td in enumerate(touchdowns[side]):
                ax.axvline(td, color=color, ls=":", lw=1.0,
                           label=f"{side} touchdowns ({len(touchdowns[side])})" if i == 0 else None)
        ax.set_xlabel("sim time (s)")
        ax.set_ylabel("sole load (N)")
        ax.legend(fontsize=8, loc="upper right")
        ax.set_title("Sole loads (/foot_load/*) and touchdowns (robot/contact.py TouchdownDetector)")
        save(fig, "sole_loads.png")

    state = data.get(ifc.CPG_STATE, [])
    dofs = cpg_dofs(state)
    if need("modulation.png", ifc.ODOM_GROUND_TRUTH):
        od = odometry_series(data[ifc.ODOM_GROUND_TRUTH])
        cycle_s = 1.0
        if dofs:
            first = np.asarray(state[0][1].data).reshape(len(dofs), state[0][1].layout.dim[1].size, 3)
            cycle_s = float(1.0 / np.median(first[:, 0, 1]))
        events, diags = data.get(ifc.PARAMETER_EVENTS, []), data.get(ifc.DIAGNOSTICS, [])
        fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
        axes[0].plot(od["t"], od["speed"], lw=0.6, alpha=0.5, label="forward speed")
        axes[0].plot(od["t"], _moving_average(od["t"], od["speed"], cycle_s), lw=1.5,
                     label=f"average over {cycle_s:.2f} s (a gait cycle)" if dofs else "1 s average")
        axes[0].set_ylabel("speed (m/s)")
        axes[0].legend(fontsize=8)
        for ax, name in ((axes[1], "zeta"), (axes[2], "alpha")):
            _step_line(ax, parameter_steps(events, diags, name), t_end, lw=1.5,
                       label="parameter (/parameter_events)")
            applied = _diag_values(diags, name)
            if applied:
                ax.plot(*zip(*applied, strict=True), "o-", ms=2, lw=0.8, label="in use (/diagnostics)")
            ax.set_ylabel(name)
            ax.legend(fontsize=8)
        axes[3].plot(od["t"], np.degrees(od["heading"]), lw=1.0)
        axes[3].set_ylabel("heading (deg)")
        axes[3].set_xlabel("sim time (s)")
        fig.suptitle("Speed, zeta, alpha and heading")
        save(fig, "modulation.png")

    if not dofs:
        skipped["cpg_phases.png"] = "no /cpg/state (cpg_node's oscillator states) in the recording"
    else:
        dims = state[0][1].layout.dim
        m = dims[1].size
        t = _t(state)
        arr = np.array([np.asarray(msg.data).reshape(len(dofs), m, 3) for _, msg in state])
        fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
        for i, name in enumerate(dofs):
            axes[0].plot(t, np.mod(arr[:, i, 0, 0], 2 * math.pi), ".", ms=3, label=name)
            axes[1].plot(t, arr[:, i, 0, 1], lw=1.0, label=name)
        axes[0].set_ylabel("phase of oscillator 0 (rad, mod 2pi)")
        axes[1].set_ylabel("frequency of oscillator 0 (Hz)")
        axes[1].set_xlabel("sim time (s)")
        axes[0].legend(fontsize=6, ncol=5, loc="upper right")
        fig.suptitle("CPG oscillators (/cpg/state)")
        save(fig, "cpg_phases.png")

    summary = {"bag": str(bag), "files": written, "not_plotted": skipped,
               "counts": {k: len(v) for k, v in sorted(data.items())},
               "touchdowns": {k: len(v) for k, v in touchdowns.items()}}
    (out / "plot.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
