"""A run's samples through the ROS graph (the sim node's record): what the in-process loop logs (base
pose, heading, sole loads every ``log_dt``) plus the joint angles, so a graph run is summarised by the same
code (walker/loop.py) and two lockstep runs can be compared sample by sample."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from cpg_walker.robot.hoap2 import Hoap2Sim


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
    fall_xy: list | None = None  # the base's (x, y) in the world frame when the fall was detected
    stats: dict = field(default_factory=dict)

    def sample(self, t: float, sim: Hoap2Sim) -> None:
        pos, _ = sim.base_pose()
        self.t.append(t)
        self.base_xy.append(pos[:2].tolist())
        self.base_z.append(float(pos[2]))
        self.heading.append(sim.heading())
        self.loads.append(list(sim.sole_loads()))
        self.q.append(sim.joint_positions().tolist())

    def mark_fall(self, t: float, sim: Hoap2Sim) -> None:
        """The fall, detected at sim time ``t``: its time and the base's position then (once)."""
        if not self.fell:
            self.fell, self.fall_time_s = True, t
            self.fall_xy = sim.base_pose()[0][:2].tolist()

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.__dict__) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> RunRecord:
        raw = json.loads(Path(path).read_text())
        rec = cls(log_dt=raw.pop("log_dt"))
        for k, v in raw.items():
            setattr(rec, k, v)
        return rec
