"""The leg odometry (robot/odometry.py) measured against ground truth, in-process: walks driven through
/cmd_vel as cpg_node follows it (experiments/cmd_vel.py's Drive and DrivenSource, walker/loop.py
run_replay, the real MuJoCo model), the estimator fed at every control tick what odom_node gets from the
graph — the joint angles, the IMU's orientation and gyro, the sole loads — without changing the walk.

Reported per walk: the planar position error (final and largest) as % of the distance walked, the yaw
error (final and largest) in degrees and as % of the angle turned, the height error. Distance walked and
angle turned are the ground truth's, summed stride by stride (from one left touchdown to the next: the
torso's sway within a stride, a few cm and degrees each way, is not walking or turning).
``measure(DIR)`` writes DIR/odometry.json and DIR/odometry.md (``python -c "from
cpg_walker.experiments.odometry import measure; measure('DIR', jobs=2)"``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cpg_walker.experiments.cmd_vel import Drive, drive_duration, driven_source
from cpg_walker.robot.odometry import CONFIG_KEYS, LegOdometry, OdometryConfig

#: s between the samples compared with the truth.
SAMPLE_S = 0.01


def drives(duration_s: float = 60.0) -> list[Drive]:
    """Straight forward and backward at 0.085 m/s, and forward with alternating ±0.15 rad/s turns of 10 s,
    each commanded from 10 s to ``duration_s`` (the walk ends 8 s later, the timeout's stop)."""
    turns = tuple((min(t + 10.0, duration_s), 0.085, 0.15 if k % 2 == 0 else -0.15)
                  for k, t in enumerate(np.arange(10.0, duration_s, 10.0)))
    return [Drive("forward", ((duration_s, 0.085, 0.0),)),
            Drive("backward", ((duration_s, -0.085, 0.0),)),
            Drive("turns", turns)]


class OdometryProbe:
    """Wraps a target source: at each control tick (before the source's ``observe``) feeds ``odom`` the
    sim's joint angles, IMU and sole loads of that instant (what sim_node publishes together), and keeps
    the estimate beside the truth every ``SAMPLE_S``. Targets pass through unchanged."""

    def __init__(self, source, sim, odom: LegOdometry):
        self.src, self.sim, self.odom = source, sim, odom
        self.names = source.names
        self._inner = getattr(source, "observe", None)
        self.rows: list[list[float]] = []  # t, true x y z yaw, estimated x y z yaw
        self._next = 0.0

    def observe(self, t, quat_wxyz, gyro, loads) -> None:
        sim = self.sim
        self.odom.update(t, sim.joint_names, sim.data.qpos[sim._qadr], quat_wxyz, gyro, loads)
        if t >= self._next - 1e-9:
            est = self.odom.estimate()
            pos, _ = sim.base_pose()
            self.rows.append([t, *pos, sim.heading(), *est.position, self.odom.yaw])
            self._next = t + SAMPLE_S
        if self._inner is not None:
            self._inner(t, quat_wxyz, gyro, loads)

    def targets(self, t):
        return self.src.targets(t)


def drift(rows: np.ndarray, strides: list[float]) -> dict:
    """The estimate's error against the truth over ``rows`` (OdometryProbe.rows as an array); distance
    and turn summed between the times ``strides`` (e.g. the left touchdowns), the start and the end."""
    t, true_xy, true_z, est_xy, est_z = rows[:, 0], rows[:, 1:3], rows[:, 3], rows[:, 5:7], rows[:, 7]
    true_yaw, est_yaw = np.unwrap(rows[:, 4]), np.unwrap(rows[:, 8])
    idx = np.searchsorted(t, np.asarray(strides, dtype=float))
    idx = np.unique(np.concatenate([[0], np.minimum(idx, len(t) - 1), [len(t) - 1]]))
    walked = float(np.sum(np.linalg.norm(np.diff(true_xy[idx], axis=0), axis=1)))
    turned = float(np.sum(np.abs(np.diff(true_yaw[idx]))))
    pos_err = np.linalg.norm(est_xy - true_xy, axis=1)
    yaw_err = np.degrees(est_yaw - true_yaw)

    def pct(x: float, d: float) -> float | None:
        return round(100.0 * x / d, 2) if d > 1e-9 else None

    return {
        "duration_s": round(float(t[-1] - t[0]), 2), "distance_m": round(walked, 4),
        "net_displacement_m": round(float(np.linalg.norm(true_xy[-1] - true_xy[0])), 4),
        "turned_deg": round(math.degrees(turned), 2),
        "net_heading_change_deg": round(math.degrees(true_yaw[-1] - true_yaw[0]), 2),
        "position_error_final_m": round(float(pos_err[-1]), 4),
        "position_error_max_m": round(float(pos_err.max()), 4),
        "position_error_final_pct": pct(float(pos_err[-1]), walked),
        "position_error_max_pct": pct(float(pos_err.max()), walked),
        "yaw_error_final_deg": round(float(yaw_err[-1]), 3),
        "yaw_error_max_deg": round(float(np.abs(yaw_err).max()), 3),
        "yaw_error_final_pct": pct(abs(float(yaw_err[-1])), math.degrees(turned)),
        "yaw_error_max_pct": pct(float(np.abs(yaw_err).max()), math.degrees(turned)),
        "yaw_error_deg_per_m": round(abs(float(yaw_err[-1])) / walked, 3) if walked > 1e-9 else None,
        "z_error_final_m": round(float(est_z[-1] - true_z[-1]), 4),
        "z_error_max_m": round(float(np.abs(est_z - true_z).max()), 4),
    }


def run_odometry(drive: Drive, config: OdometryConfig | None = None, map_file: str | None = None) -> dict:
    """One drive in-process with the estimator beside it: ``drift`` of the estimate, the fall if any."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.loop import run_replay

    source, _, _ = driven_source(drive, map_file)
    duration = drive_duration(drive)
    sim = Hoap2Sim()
    sim.reset()
    probe = OdometryProbe(source, sim, LegOdometry(config))
    r = run_replay(sim, probe, PidLaw.from_config(), duration)
    out = {"label": drive.label, "segments": [list(s) for s in drive.segments], "fell": bool(r.fell),
           "fall_time_s": None if r.fall_time_s is None else round(float(r.fall_time_s), 3)}
    out.update(drift(np.array(probe.rows), r.touchdowns["left"]))
    out["steps"] = len(r.touchdowns["left"]) + len(r.touchdowns["right"])
    return out


def measure(out: str | Path | None = None, duration_s: float = 60.0, jobs: int = 1,
            config: OdometryConfig | None = None) -> dict:
    """Every drive of ``drives(duration_s)``; with ``out``: DIR/odometry.json and DIR/odometry.md."""
    from functools import partial

    from cpg_walker.experiments.walk_runs import run_many

    cfg = OdometryConfig.load() if config is None else config
    runs = run_many(partial(run_odometry, config=cfg), drives(duration_s), jobs=jobs)
    report = {"command": f"cpg_walker.experiments.odometry.measure(DIR, duration_s={duration_s:g})",
              "target_pct": 5.0, "config": {k: getattr(cfg, k) for k in CONFIG_KEYS}, "runs": runs}
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "odometry.json").write_text(json.dumps(report, indent=2) + "\n")
        (out / "odometry.md").write_text(markdown(report))
    return report


def markdown(report: dict) -> str:
    """The runs as a table."""
    lines = ["| walk | distance m | turned deg | pos err final (% dist) | pos err max (% dist) | "
             "yaw err final deg (% turned) | yaw err max deg (% turned) | z err final m |",
             "|---|---|---|---|---|---|---|---|"]
    for r in report["runs"]:
        fell = f" (FELL at {r['fall_time_s']} s)" if r["fell"] else ""
        lines.append(f"| {r['label']}{fell} | {r['distance_m']} | {r['turned_deg']} | "
                     f"{r['position_error_final_m']} ({r['position_error_final_pct']} %) | "
                     f"{r['position_error_max_m']} ({r['position_error_max_pct']} %) | "
                     f"{r['yaw_error_final_deg']} ({r['yaw_error_final_pct']} %) | "
                     f"{r['yaw_error_max_deg']} ({r['yaw_error_max_pct']} %) | {r['z_error_final_m']} |")
    return "\n".join(lines) + "\n"



class OdomWatcher:
    """Follows a running graph (experiments/walk_graph.py ``run_graph_walk``'s ``watchers``): records /odom
    (odom_node's estimate) and /odom/ground_truth by stamp, from a thread with its own probe."""

    def __init__(self) -> None:
        import threading

        self.est: dict[int, tuple[float, ...]] = {}  # stamp ns -> x, y, z, yaw
        self.truth: dict[int, tuple[float, ...]] = {}
        self.covariance: list[float] | None = None  # the last /odom's pose covariance
        self.frames: tuple[str, str] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, domain_id: int) -> None:
        import threading

        self._thread = threading.Thread(target=self._run, args=(domain_id,), name="odom-watch", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)

    def _keep(self, into: dict, msg) -> None:
        s, p, q = msg.header.stamp, msg.pose.pose.position, msg.pose.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        into[s.sec * 1_000_000_000 + s.nanosec] = (p.x, p.y, p.z, yaw)
        if into is self.est:
            self.covariance = list(msg.pose.covariance)
            self.frames = (msg.header.frame_id, msg.child_frame_id)

    def on_estimate(self, msg) -> None:
        """Keep an /odom message (a subscription callback)."""
        self._keep(self.est, msg)

    def on_truth(self, msg) -> None:
        """Keep an /odom/ground_truth message (a subscription callback)."""
        self._keep(self.truth, msg)

    def _run(self, domain_id: int) -> None:
        from nav_msgs.msg import Odometry

        from cpg_walker.graph.probe import Probe
        from cpg_walker.nodes import interface as ifc

        probe = Probe(domain_id, "odom_watch", parameter_services=False)
        try:
            probe.subscribe(ifc.ODOM, Odometry, self.on_estimate, 200)
            probe.subscribe(ifc.ODOM_GROUND_TRUTH, Odometry, self.on_truth, 200)
            while not self._stop.is_set():
                probe.executor.spin_once(timeout_sec=0.01)
        finally:
            probe.close()

    def rows(self) -> np.ndarray:
        """OdometryProbe.rows' layout over the stamps both topics have, the truth moved so that it starts
        where the estimate does (the estimate's odom origin is where odom_node's first sample put it)."""
        common = sorted(set(self.est) & set(self.truth))
        if not common:
            raise ValueError("no stamp with both /odom and /odom/ground_truth")
        rows = np.array([[k / 1e9, *self.truth[k], *self.est[k]] for k in common])
        rows[:, 1:5] += rows[0, 5:9] - rows[0, 1:5]
        return rows

    def compare(self, strides: list[float]) -> dict:
        """``drift`` of the recorded estimate, plus the offset between the first samples of each."""
        common = sorted(set(self.est) & set(self.truth))
        out = drift(self.rows(), strides)
        k = common[0]
        out.update(samples=len(common), first_s=round(k / 1e9, 3), odom_messages=len(self.est),
                   start_offset_m=round(float(np.linalg.norm(np.subtract(self.est[k][:2],
                                                                         self.truth[k][:2]))), 4))
        return out
