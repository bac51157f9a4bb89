"""The in-process replay of the recorded gaits walks the simulated HOAP-2 (no ROS)."""

import json

import numpy as np
import pytest

from cpg_walker.cli.main import main
from cpg_walker.paths import config_path
from cpg_walker.robot.gait_data import GaitPlayback, load_gait
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.joints import JOINT_NAMES, LEG_JOINTS
from cpg_walker.robot.pid import PidLaw, load_pid_config
from cpg_walker.walker import storage
from cpg_walker.walker.gait_source import CPGGaitSource
from cpg_walker.walker.loop import control_period, run_replay, summarize

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


def _reference_loop(sim, source, pid, duration, rate_hz, delay_s, log_dt=0.01):
    """run_replay's loop written plainly: one physics step per iteration, every state in a delay line,
    the checked `PidLaw.step` and `Hoap2Sim.step(torque)` at each tick. Returns the logged series."""
    from collections import deque

    sel = [JOINT_NAMES.index(n) for n in pid.names]
    dt = sim.dt
    per_tick = max(1, round(1.0 / (rate_hz * dt)))
    delay_steps = round(delay_s / dt)
    log_every = max(1, round(log_dt / dt))
    history = deque(maxlen=delay_steps + 1)
    tau_full = np.zeros(len(JOINT_NAMES))
    rows = []
    t0 = sim.time
    pid.reset()
    for k in range(round(duration / dt)):
        history.append((sim.joint_positions(), sim.joint_velocities()))
        if k % per_tick == 0:
            q, v = history[0]
            qt, vt = source.targets(sim.time - t0)
            tau_full[sel] = pid.step(qt, vt, q[sel], v[sel], per_tick * dt)
            sim.step(tau_full, 1)
        else:
            sim.step(None, 1)
        if (k + 1) % log_every == 0:
            pos, _ = sim.base_pose()
            rows.append([sim.time - t0, *pos, sim.heading(), *sim.sole_loads()])
    return np.array(rows)


def _logged(result) -> np.ndarray:
    return np.column_stack([result.t, result.base_xy, result.base_z, result.heading, result.loads])


@pytest.mark.parametrize("rate_hz, delay_s, joints, max_torque", [
    (500.0, 0.002, JOINT_NAMES, None), (500.0, 0.0, JOINT_NAMES, None), (1000.0, 0.003, JOINT_NAMES, None),
    (333.3, 0.005, JOINT_NAMES, None), (250.0, 0.001, LEG_JOINTS, None), (500.0, 0.002, JOINT_NAMES, 20.0)])
def test_lean_loop_equals_the_plain_loop(rate_hz, delay_s, joints, max_torque):
    """run_replay (lean PID, states kept only where a tick reads them, physics stepped between events)
    gives the plain loop's run to the last bit, for rates and delays that do and do not divide, and
    with a stiff law allowed more torque than the motors (20 vs 9 N*m: the sim's clamp acts)."""
    gait = load_gait("walk")
    cfg = load_pid_config()
    stiff = {} if max_torque is None else {"scale_kp": 20.0}
    if max_torque is not None:
        cfg["max_torque"] = max_torque
    runs = []
    for lean in (True, False):
        sim, pid = Hoap2Sim(), PidLaw.from_config(joints, config=cfg, **stiff)
        source = GaitPlayback(gait, names=joints, default=sim.joint_positions(joints))
        if lean:
            runs.append(_logged(run_replay(sim, source, pid, 0.4, rate_hz=rate_hz, delay_s=delay_s)))
        else:
            runs.append(_reference_loop(sim, source, pid, 0.4, rate_hz, delay_s))
        runs[-1] = (runs[-1], *(a.copy() for a in (sim.data.qpos, sim.data.qvel, sim.data.ctrl)))
    lean_run, ref_run = runs
    assert lean_run[0].shape == ref_run[0].shape == (40, 7)
    for lean_part, ref_part in zip(lean_run, ref_run, strict=True):  # logs, final qpos, qvel, held torque
        assert lean_part.tobytes() == ref_part.tobytes()


def test_lean_loop_equals_the_plain_loop_through_the_cpg_handover():
    """The same with the CPG source: recording, cross-fade, then the frozen network (kernels)."""
    cfg = load_pid_config()
    runs = []
    for lean in (True, False):
        ctrl = storage.load(config_path("cpg_humanoid.yaml"))
        source = CPGGaitSource(ctrl, handover_s=0.1, blend_s=0.2)
        sim, pid = Hoap2Sim(), PidLaw.from_config(config=cfg)
        if lean:
            runs.append(_logged(run_replay(sim, source, pid, 0.6)))  # the configured rate and delay
        else:
            period = control_period()
            runs.append(_reference_loop(sim, source, pid, 0.6, 1.0 / period, period))
    assert runs[0].shape == (60, 7) and runs[0].tobytes() == runs[1].tobytes()
