"""Pure parts of the sim node (MuJoCo, no rclpy): sole contact wrenches, body pushes, the run recorder.

The recorder logs what the in-process replay logs (base pose, heading, sole loads every ``log_dt``) plus
the joint angles, so a run through the ROS graph is summarised by the same code (experiments/replay.py)
and two lockstep runs can be compared sample by sample.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from cpg_walker.robot.hoap2 import SOLES, Hoap2Sim


def sole_wrenches(sim: Hoap2Sim) -> list[tuple[np.ndarray, np.ndarray]]:
    """(force N, torque N*m) the floor exerts on each sole plate (left, right), summed over its contacts,
    expressed in the sole's frame with the torque about the sole plate's centre."""
    m, d = sim.model, sim.data
    out = []
    f6 = np.zeros(6)
    for name in SOLES:
        g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
        force, torque = np.zeros(3), np.zeros(3)
        centre = d.geom_xpos[g]
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 != g and c.geom2 != g:
                continue
            mujoco.mj_contactForce(m, d, i, f6)
            frame = c.frame.reshape(3, 3)  # rows: normal (geom1 -> geom2), tangent 1, tangent 2
            fw = frame.T @ f6[:3]  # force on geom2, world frame
            if c.geom1 == g:
                fw = -fw
            force += fw
            r = c.pos - centre
            torque += (r[1] * fw[2] - r[2] * fw[1], r[2] * fw[0] - r[0] * fw[2], r[0] * fw[1] - r[1] * fw[0])
        R = d.geom_xmat[g].reshape(3, 3)
        out.append((R.T @ force, R.T @ torque))
    return out


class Pusher:
    """Pushes on any body: a world-frame force at the body's CoM for a duration of sim time (the torso via
    Hoap2Sim.apply_push, with physics-step resolution; other bodies cleared at control-period ends)."""

    def __init__(self, sim: Hoap2Sim):
        self.sim = sim
        self._active: dict[int, float] = {}

    def body_id(self, body: str) -> int:
        b = mujoco.mj_name2id(self.sim.model, mujoco.mjtObj.mjOBJ_BODY, body)
        if b <= 0:
            raise ValueError(f"unknown body {body!r}")
        return b

    def push(self, body: str, force: np.ndarray, duration: float) -> None:
        f = np.asarray(force, dtype=float)
        if f.shape != (3,) or not np.all(np.isfinite(f)) or not (duration > 0):
            raise ValueError("push: need a finite 3-vector force and a positive duration")
        b = self.body_id(body)
        if body == "torso":
            self.sim.apply_push(f, duration)
            return
        self.sim.data.xfrc_applied[b, :3] = f
        self._active[b] = self.sim.time + float(duration)

    def update(self) -> None:
        """Clear expired pushes (call once per control period)."""
        for b, until in list(self._active.items()):
            if self.sim.time >= until - 1e-12:
                self.sim.data.xfrc_applied[b, :] = 0.0
                del self._active[b]

    def clear(self) -> None:
        for b in self._active:
            self.sim.data.xfrc_applied[b, :] = 0.0
        self._active.clear()


@dataclass
class RunRecord:
    """Samples of one run every ``log_dt`` of sim time, plus the run's timing statistics."""

    log_dt: float
    t: list = field(default_factory=list)
    base_xy: list = field(default_factory=list)
    base_z: list = field(default_factory=list)
    heading: list = field(default_factory=list)
    loads: list = field(default_factory=list)
    q: list = field(default_factory=list)
    fell: bool = False
    fall_time_s: float | None = None
    stats: dict = field(default_factory=dict)

    def sample(self, t: float, sim: Hoap2Sim) -> None:
        pos, _ = sim.base_pose()
        self.t.append(t)
        self.base_xy.append(pos[:2].tolist())
        self.base_z.append(float(pos[2]))
        self.heading.append(sim.heading())
        self.loads.append(list(sim.sole_loads()))
        self.q.append(sim.joint_positions().tolist())

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.__dict__) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> RunRecord:
        raw = json.loads(Path(path).read_text())
        rec = cls(log_dt=raw.pop("log_dt"))
        for k, v in raw.items():
            setattr(rec, k, v)
        return rec


def latency_summary(samples_s: list[float]) -> dict:
    """p50/p99/max of latencies (s) in milliseconds, with the count."""
    if not samples_s:
        return {"count": 0}
    a = np.asarray(samples_s) * 1e3
    return {"count": int(a.size), "p50_ms": round(float(np.percentile(a, 50)), 4),
            "p99_ms": round(float(np.percentile(a, 99)), 4), "max_ms": round(float(a.max()), 4)}
