"""Pushes on any body of the simulated HOAP-2 (the sim node's ~/push service, perturbation experiments)."""

from __future__ import annotations

import mujoco
import numpy as np

from cpg_walker.robot.hoap2 import Hoap2Sim


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
