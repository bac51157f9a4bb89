"""Foot contact of the HOAP-2: the floor's wrench on each sole plate, and touchdown events from sole loads.

One home for the contact hysteresis every consumer uses (the in-process loop's step counting, the graph
run's record, the feedback pathways' phase resetting): a foot is on the ground above ``CONTACT_ON_N``,
lifted below ``CONTACT_OFF_N``, and a touchdown counts as a step only after a lift of ``MIN_SWING_S``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cpg_walker.robot.hoap2 import SOLES, Hoap2Sim

CONTACT_ON_N = 10.0  # sole load above which a foot counts as on the ground (~15 % of the weight)
CONTACT_OFF_N = 3.0  # ... and below which it counts as lifted (hysteresis)
MIN_SWING_S = 0.25  # a touchdown is a step only after the foot was lifted this long (not a graze)
SIDES = ("left", "right")


class TouchdownDetector:
    """Left/right touchdowns from sole loads (N): load > ``on`` after the foot was lifted (< ``off``) for
    at least ``min_swing`` s. The first ``update`` only primes the contact state. Events are also kept in
    ``events`` ({"left": [t, ...], "right": [...]})."""

    def __init__(self, on_n: float = CONTACT_ON_N, off_n: float = CONTACT_OFF_N,
                 min_swing_s: float = MIN_SWING_S):
        if not (0 <= off_n <= on_n and min_swing_s >= 0):
            raise ValueError(f"contact thresholds need 0 <= off ({off_n}) <= on ({on_n}), min_swing >= 0")
        self.on, self.off, self.min_swing = float(on_n), float(off_n), float(min_swing_s)
        self.state: list[tuple[bool, float | None]] | None = None
        self.events: dict[str, list[float]] = {s: [] for s in SIDES}

    def update(self, t: float, loads: tuple[float, float]) -> tuple[bool, bool]:
        """(left, right) touchdown events at time ``t`` for the (left, right) sole loads."""
        if self.state is None:
            self.state = [(loads[0] > self.on, None), (loads[1] > self.on, None)]
            return False, False
        ev = [False, False]
        for i in range(2):
            down, lifted = self.state[i]
            if not down and loads[i] > self.on:
                ev[i] = lifted is not None and t - lifted >= self.min_swing
                if ev[i]:
                    self.events[SIDES[i]].append(t)
                self.state[i] = (True, None)
            elif down and loads[i] < self.off:
                self.state[i] = (False, t)
        return ev[0], ev[1]


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
