"""Benchmark section "robot": physics step cost of the HOAP-2 model and the in-process replay's
real-time factor (PID torque law at the configured rate, no rendering)."""

from __future__ import annotations

import statistics
import time

import numpy as np

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


def run(quick: bool = False) -> dict:
    sim = Hoap2Sim()
    repeats = 3 if quick else 7
    steps = 1000 if quick else 5000
    step_us = statistics.median(_step_cost_us(sim, steps) for _ in range(repeats))
    duration = 5.0 if quick else 30.0
    rtf = []
    for _ in range(1 if quick else 3):
        sim.reset()
        source = GaitPlayback(load_gait("walk"))
        pid = PidLaw.from_config()
        started = time.perf_counter()
        result = run_replay(sim, source, pid, duration)
        rtf.append(result.duration_s / (time.perf_counter() - started))
    return {
        "physics_timestep_s": sim.dt,
        "physics_step_us": round(step_us, 2),
        "replay_sim_s": duration,
        "replay_real_time_factor": round(statistics.median(rtf), 1),
        "replay_fell": bool(result.fell),
    }
