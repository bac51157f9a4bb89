"""Benchmark section "loop": the closed in-process loop (walker/loop.py) at physics speed?

A 20 s CPG walk from standing, set up as `cpg-walker cpg-walk` sets it up (the packaged CPG, the
"recording" start-up transition, the configured PID at its rate and delay, no rendering), timed in parts:

* set-up: loading the CPG, building the target source (recording, steady cycle), the sim and the PID,
  for the section's first walk (``setup_first_walk_s``: the caches of gait data and steady cycle
  filled unless an earlier section did, kernels loaded) and for later ones (``setup_s``).
* loop: wall time of `run_replay` alone, and the time spent inside `mujoco.mj_step` during it, timed
  by a wrapper around mj_step that only this benchmark installs (its own cost, ~0.2 µs a step, counts
  as loop time). ``loop_to_physics_time_ratio`` = loop wall / mj_step time (1 = nothing but physics).
* the same walk without the wrapper (``loop_wall_uninstrumented_s``), to show what the wrapper costs.
"""

from __future__ import annotations

import statistics
import time
from contextlib import contextmanager

import mujoco

import cpg_walker.robot.hoap2 as hoap2_module
from cpg_walker.experiments.bench_validity import check_run

WALK_S = 20.0


class _TimedMujoco:
    """The mujoco module with ``mj_step`` timed (everything else passed through)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.calls = 0

    def __getattr__(self, name: str):
        return getattr(mujoco, name)

    def mj_step(self, model, data) -> None:
        t0 = time.perf_counter()
        mujoco.mj_step(model, data)
        self.seconds += time.perf_counter() - t0
        self.calls += 1


@contextmanager
def _timed_physics():
    timed = _TimedMujoco()
    hoap2_module.mujoco = timed
    try:
        yield timed
    finally:
        hoap2_module.mujoco = mujoco


def _setup():
    """What `experiments.cpg_walk.walk` builds before its loop (defaults of `cpg-walker cpg-walk`)."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw, load_pid_config
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import cpg_defaults, load_controller
    from cpg_walker.walker.loop import control_period

    ctrl, _, _ = load_controller(cpg_defaults()["cpg_file"])
    source = CPGGaitSource(ctrl)
    cfg = load_pid_config()
    sim = Hoap2Sim()
    sim.reset()
    pid = PidLaw.from_config(config=cfg)
    period = control_period()  # what run_replay uses by default: config/sim.yaml's, one period of delay
    return sim, source, pid, 1.0 / period, period


def _walk(instrument: bool) -> dict:
    from cpg_walker.walker.loop import run_replay

    t0 = time.perf_counter()
    sim, source, pid, rate, delay = _setup()
    setup_s = time.perf_counter() - t0
    if instrument:
        with _timed_physics() as timed:
            t0 = time.perf_counter()
            result = run_replay(sim, source, pid, WALK_S, rate_hz=rate, delay_s=delay)
            loop_s = time.perf_counter() - t0
        physics_s, steps = timed.seconds, timed.calls
    else:
        t0 = time.perf_counter()
        result = run_replay(sim, source, pid, WALK_S, rate_hz=rate, delay_s=delay)
        loop_s = time.perf_counter() - t0
        physics_s, steps = float("nan"), 0
    m = result.metrics
    return {**check_run(fell=m["fell"], fall_time_s=m.get("fall_time_s"), distance_m=m.get("distance_m"),
                        walking=True),
            "instrumented": instrument, "setup_s": setup_s, "loop_s": loop_s, "physics_s": physics_s,
            "steps": steps, "metrics": m}


def run(quick: bool = False) -> dict:
    repeats = 1 if quick else 3
    first = _walk(instrument=True)  # the process's first walk: caches filled, kernels loaded
    every = [first] + [_walk(instrument=True) for _ in range(repeats)]
    every += [_walk(instrument=False) for _ in range(repeats)]
    record = [{k: r[k] for k in ("valid", "invalid_reason", "instrumented") if k in r}
              | {"loop_s": round(r["loop_s"], 3)}
              | {k: r["metrics"][k] for k in ("fell", "distance_m", "steps")} for r in every]
    # the figures from the valid walks only (bench_validity): a fallen or stalled walk times nothing
    runs = [r for r in every[1:] if r["valid"] and r["instrumented"]]
    plain = [r for r in every[1:] if r["valid"] and not r["instrumented"]]
    if not runs or not plain or not first["valid"]:
        return {"cpg_walk_20s": {"sim_s": WALK_S, "runs": record}}
    med = statistics.median
    loop_s, physics_s = med(r["loop_s"] for r in runs), med(r["physics_s"] for r in runs)
    steps = runs[0]["steps"]
    m = runs[0]["metrics"]
    return {
        "cpg_walk_20s": {
            "runs": record,
            "sim_s": WALK_S,
            "setup_first_walk_s": round(first["setup_s"], 3),
            "setup_s": round(med(r["setup_s"] for r in runs), 3),
            "loop_wall_s": round(loop_s, 3),
            "mj_step_s": round(physics_s, 3),
            "mj_step_calls": steps,
            "mj_step_us": round(physics_s / steps * 1e6, 2),
            "loop_overhead_us_per_physics_step": round((loop_s - physics_s) / steps * 1e6, 2),
            "loop_wall_uninstrumented_s": round(med(r["loop_s"] for r in plain), 3),
            "loop_to_physics_time_ratio": round(med(r["loop_s"] / r["physics_s"] for r in runs), 3),
            "real_time_factor": round(WALK_S / loop_s, 2),
            "walk": {k: m[k] for k in ("fell", "distance_m", "steps")},
        }
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=2))
