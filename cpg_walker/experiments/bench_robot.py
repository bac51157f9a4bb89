"""Benchmark section "robot": physics step cost of the HOAP-2 model and the in-process replay's
real-time factor (PID torque law at the configured rate, no rendering). Baseline: a bare
``mujoco.mj_step`` loop on the same model (what Hoap2Sim.step adds: applying the torques, the loop)."""

from __future__ import annotations

import statistics
import time

import numpy as np

from cpg_walker.experiments.bench_validity import check_run
from cpg_walker.robot.gait_data import GaitPlayback, load_gait
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.pid import PidLaw
from cpg_walker.walker.loop import run_replay


def _step_cost_us(sim: Hoap2Sim, steps: int) -> float:
    sim.reset()
    posture = sim.joint_positions()
    pid = PidLaw.from_config()
    tau = pid.step(posture, np.zeros(25), posture, np.zeros(25), sim.dt)
    started = time.perf_counter()
    sim.step(tau, steps)  # standing on both feet: 8 sole contacts
    return (time.perf_counter() - started) / steps * 1e6


def _mj_step_cost_us(sim: Hoap2Sim, steps: int) -> float:
    """Baseline: bare ``mujoco.mj_step`` on the same model and data, from the same standing state with the
    same torques held."""
    import mujoco

    sim.reset()
    posture = sim.joint_positions()
    sim.step(PidLaw.from_config().step(posture, np.zeros(25), posture, np.zeros(25), sim.dt), 0)
    started = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(sim.model, sim.data)
    return (time.perf_counter() - started) / steps * 1e6


def run(quick: bool = False) -> dict:
    sim = Hoap2Sim()
    repeats = 3 if quick else 7
    steps = 1000 if quick else 5000
    pairs = [(_step_cost_us(sim, steps), _mj_step_cost_us(sim, steps)) for _ in range(repeats)]  # interleaved
    step_us = statistics.median(p[0] for p in pairs)
    mj_us = statistics.median(p[1] for p in pairs)
    duration = 5.0 if quick else 30.0
    runs = []
    for _ in range(1 if quick else 3):
        sim.reset()
        source = GaitPlayback(load_gait("walk"))
        pid = PidLaw.from_config()
        started = time.perf_counter()
        result = run_replay(sim, source, pid, duration)
        rtf = result.duration_s / (time.perf_counter() - started)
        fell, distance = bool(result.fell), result.metrics.get("distance_m")
        runs.append({**check_run(fell=fell, fall_time_s=result.fall_time_s,
                                 distance_m=distance, walking=True, figures={"real_time_factor": rtf}),
                     "real_time_factor": round(rtf, 2), "fell": fell, "distance_m": distance})
    valid = [r["real_time_factor"] for r in runs if r["valid"]]  # invalid replays give no figure
    return {
        "physics_timestep_s": sim.dt,
        "physics_step_us": round(step_us, 2),
        "bare_mj_step_us": round(mj_us, 2),
        "replay_sim_s": duration,
        "replay_real_time_factor": round(statistics.median(valid), 1) if valid else None,
        "replay_fell": any(r["fell"] for r in runs),
        "replay_runs": runs,
    }
