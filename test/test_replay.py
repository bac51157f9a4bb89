"""The in-process replay of the recorded gaits walks the simulated HOAP-2 (no ROS)."""

import json

import numpy as np
import pytest

from cpg_walker.cli.main import main
from cpg_walker.robot.gait_data import GaitPlayback, load_gait
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.pid import PidLaw
from cpg_walker.walker.loop import run_replay, summarize

# Forward-distance bounds: the recordings are walked at ~0.075 m/s (walk) and ~0.045 m/s (slow); a robot
# that shuffles in place or slides backwards stays far below these.
MIN_SPEED = {"walk": 0.05, "slow": 0.03}


def _replay(gait: str, duration: float):
    source = GaitPlayback(load_gait(gait))
    result = run_replay(Hoap2Sim(), source, PidLaw.from_config(), duration)
    return result, summarize(result, period_s=source.cycle.period)


@pytest.mark.slow
@pytest.mark.parametrize("gait", ["walk", "slow"])
def test_replay_walks_30_s_forward(gait):
    _, m = _replay(gait, 30.0)
    assert not m["fell"], m
    assert m["duration_s"] == pytest.approx(30.0, abs=0.02)
    assert m["distance_m"] > MIN_SPEED[gait] * 30.0, m
    assert abs(m["lateral_drift_m"]) < 0.3 * m["distance_m"], m
    assert abs(m["heading_change_deg"]) < 30.0, m
    # one right-foot touchdown per stride: the contact rhythm follows the recording's period
    assert m["right_touchdown_interval_s"] == pytest.approx(m["gait_period_s"], rel=0.05), m
    assert m["steps"] >= 2 * int(30.0 / m["gait_period_s"]) - 2, m


def test_replay_of_the_opening_moves_forward_without_falling():
    result, m = _replay("walk", 4.0)
    assert not m["fell"]
    assert m["distance_m"] > 0.1
    assert np.all(np.diff(result.t) > 0)


def test_a_limp_robot_falls_and_the_fall_is_reported():
    class Limp:
        names = PidLaw.from_config().names

        def targets(self, t):
            return np.zeros(25), np.zeros(25)

    pid = PidLaw(Limp.names, kp=0.0, ki=0.0, kd=0.0)
    result = run_replay(Hoap2Sim(), Limp(), pid, 5.0)
    assert result.fell and result.fall_time_s < 5.0
    assert summarize(result)["fall_time_s"] == pytest.approx(result.fall_time_s)


def test_cli_replay_writes_the_report(tmp_path, capsys):
    assert main(["replay", "--out", str(tmp_path), "--duration", "1.0", "--no-render"]) == 0
    report = json.loads((tmp_path / "replay.json").read_text())
    for key in ("fell", "fall_time_s", "duration_s", "distance_m", "lateral_drift_m", "heading_change_deg",
                "mean_speed_mps", "steps"):
        assert key in report
    assert report["fell"] is False and report["duration_s"] == pytest.approx(1.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,lleg_joint_4\n0.0,0.1\n0.001,oops\n")
    assert main(["replay", "--out", str(tmp_path), "--data", str(bad)]) == 2
    assert "bad.csv:3: not a number" in capsys.readouterr().err
