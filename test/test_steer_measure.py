"""The steering check's measurements on known trajectories (experiments/cmd_vel_graph.py ``measure``,
experiments/drive_protocol.py ``summarize``): a base turning in place, then stepping sideways, then walking
forward, sampled as /odom/ground_truth would be; the protocol's Froude scaling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpg_walker.experiments.cmd_vel_graph import STEER_PLAN, measure
from cpg_walker.experiments.drive_protocol import (
    AXES,
    TURN_STARTS,
    froude,
    summarize,
    turn_drives,
    turn_scaled,
    turn_summary,
)


def _odom(t0: float) -> np.ndarray:
    """10 s turning at 0.4 rad/s in place, 20 s sideways (left of the heading) at 0.03 m/s, 20 s forward
    at 0.1 m/s, then 8 s still; 100 Hz."""
    rows, x, y, yaw = [], 0.0, 0.0, 0.0
    for k in range(int(58.0 / 0.01) + 1):
        t = k * 0.01
        if t < 10.0:
            yaw += 0.4 * 0.01
        elif t < 30.0:
            x, y = x - 0.03 * 0.01 * math.sin(yaw), y + 0.03 * 0.01 * math.cos(yaw)
        elif t < 50.0:
            x, y = x + 0.1 * 0.01 * math.cos(yaw), y + 0.1 * 0.01 * math.sin(yaw)
        rows.append((t0 + t, x, y, math.atan2(math.sin(yaw), math.cos(yaw))))
    return np.array(rows)


def test_measure_reports_the_turn_the_side_step_and_the_forward_walk():
    t0 = 8.0
    sent = [(t0 + 49.9, 0.15, 0.0, 0.0)]
    res = measure(_odom(t0), t0, sent, [], STEER_PLAN)
    turn, side, fwd = res["windows"]
    assert turn["whole"]["turned_rad"] == pytest.approx(4.0, abs=0.01)
    assert turn["turn_rate_rad_s"] == pytest.approx(0.4, abs=1e-3)
    assert side["whole"]["sideways_m"] == pytest.approx(0.6, abs=0.01)
    assert side["lateral_mps"] == pytest.approx(0.03, abs=1e-3) and abs(side["speed_mps"]) < 1e-3
    assert fwd["speed_mps"] == pytest.approx(0.1, abs=1e-3) and abs(fwd["whole"]["sideways_m"]) < 0.01
    assert res["stopped_after_s"] is not None and res["stopped_after_s"] <= 0.2


def test_protocol_summary_picks_the_best_step_and_scales_by_froude():
    def run(field: str, values: list[float | None], fell: bool = False) -> dict:
        key = {"linear_x": "speed_mps", "linear_y": "lateral_mps", "angular_z": "turn_rate_rad_s"}[field]
        return {"fell": fell, "fall_time_s": 70.0 if fell else None,
                "segments": [{field: 0.1 * (k + 1), f"clamped_{field}": 0.1 * (k + 1), key: v}
                             for k, v in enumerate(values)]}

    runs = [run(AXES[n][0], vals, fell) for n, vals, fell in (
        ("forward", [0.03, 0.09, 0.08], False), ("backward", [-0.03, -0.1, None], True),
        ("sideways", [0.01, 0.02], False), ("turn in place", [0.2, 0.5], False))]
    p = summarize(runs, 0.25)
    assert p["axes"]["forward"]["best"] == 0.09 and p["axes"]["backward"]["best"] == -0.1
    assert p["axes"]["backward"]["fell"] and p["axes"]["turn in place"]["best"] == 0.5
    ours = p["anchors"][0]
    assert ours["froude"]["forward"] == pytest.approx(0.09 / math.sqrt(9.81 * 0.25), abs=1e-3)
    assert ours["turn_scaled"] == pytest.approx(0.5 * math.sqrt(0.25 / 9.81), abs=1e-3)
    assert froude(0.29, 0.2195) == pytest.approx(0.198, abs=1e-3)
    assert turn_scaled(2.47, 0.2195) == pytest.approx(0.369, abs=1e-3)


def test_turn_in_place_from_each_instant_counts_falls_and_the_least_turned():
    drives = turn_drives()
    assert [d.t0 for d in drives] == list(TURN_STARTS) and len(set(TURN_STARTS)) == len(TURN_STARTS)
    assert all(d.segments == ((d.t0 + 10.0, 0.0, 0.5),) and not d.ankle for d in drives)
    runs = [{"fell": False, "segments": [{"whole": {"turned_rad": x}}]} for x in (4.2, 5.0, 4.6)]
    runs.append({"fell": True, "segments": [{}]})
    t = turn_summary(runs)
    assert t["turned_rad"] == [4.2, 5.0, 4.6, None] and t["fell"] == 1
    assert t["least_rad"] == 4.2 and t["mean_rad"] == pytest.approx(4.6)
