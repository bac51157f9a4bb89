"""Foot contact of the HOAP-2: the floor's wrench on each sole plate, and touchdown events from sole loads.

One home for the contact hysteresis every consumer uses (the in-process loop's step counting, the graph
run's record, the feedback pathways' phase resetting): a foot is on the ground above ``CONTACT_ON_N``,
lifted below ``CONTACT_OFF_N``, and a touchdown counts as a step only after a lift of ``MIN_SWING_S``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cpg_walker.robot.hoap2 import Hoap2Sim

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
    expressed in the sole's frame with the torque about the sole plate's centre.

    Runs every control period in sim_node, so the per-contact part is plain float arithmetic on lists read
    once from MuJoCo's contact arrays (numpy calls on 3-vectors cost a microsecond each); MuJoCo's
    ``mj_contactForce`` gives each contact's force in its frame. Per contact: the force rotated to the world
    (the frame's rows are normal geom1 -> geom2, tangent 1, tangent 2: f_world = frame^T f, summed in row
    order), negated when the sole is geom1, torque r x f about the sole centre, summed from zero in contact
    order. test/test_ros_units.py checks the values equal the numpy computation's on a walk's contacts."""
    m, d = sim.model, sim.data
    soles = sim._sole_geoms
    con = d.contact
    g1, g2 = con.geom1.tolist(), con.geom2.tolist()
    sums = {g: [0.0] * 6 for g in soles}  # force x, y, z, torque x, y, z (world frame)
    centres = {g: d.geom_xpos[g].tolist() for g in soles}
    frames = pos = None
    f6 = np.empty(6)
    for i, (a, b) in enumerate(zip(g1, g2, strict=True)):
        if a not in sums and b not in sums:
            continue
        if frames is None:
            frames, pos = con.frame.tolist(), con.pos.tolist()
        mujoco.mj_contactForce(m, d, i, f6)
        n0, n1, n2, t0, t1, t2, u0, u1, u2 = frames[i]
        c0, c1, c2 = f6[:3].tolist()
        fx, fy, fz = n0 * c0 + t0 * c1 + u0 * c2, n1 * c0 + t1 * c1 + u1 * c2, n2 * c0 + t2 * c1 + u2 * c2
        for g, sign in ((a, -1.0), (b, 1.0)):  # geom2 receives +f; geom1 (if a sole) -f
            acc = sums.get(g)
            if acc is None:
                continue
            wx, wy, wz = (fx, fy, fz) if sign > 0 else (-fx, -fy, -fz)
            p, o = pos[i], centres[g]
            rx, ry, rz = p[0] - o[0], p[1] - o[1], p[2] - o[2]
            acc[0] += wx
            acc[1] += wy
            acc[2] += wz
            acc[3] += ry * wz - rz * wy
            acc[4] += rz * wx - rx * wz
            acc[5] += rx * wy - ry * wx
    out = []
    for g in soles:
        R = d.geom_xmat[g].reshape(3, 3)
        w = np.array(sums[g])
        out.append((R.T @ w[:3], R.T @ w[3:]))
    return out
