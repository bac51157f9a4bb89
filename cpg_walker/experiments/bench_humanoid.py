"""Benchmark of the humanoid CPG (walker/controller.py): µs per controller step, learning wall time.

* step: one `HumanoidCPG.step(0.002)` + `joint_targets()` (RK4 of the frozen 10×N network, the ζ/α
  filter idle), the node's per-tick cost at 500 Hz; for N = 3 (default) and N = 10.
* step_modulating: the same while a ζ command is being filtered (set_frequency_scale every step).
* learn: wall time of `HumanoidCPG.learn` with the configured settings (N = 3; quick: a fixed
  20-stride budget so the number is comparable between runs), strides done, µs per learning RK4 step.
Baseline in the same run: one RK4 step of a bare CPGNetwork of the same shape (no coupling, no targets).
"""

from __future__ import annotations

import time

from cpg_walker.cpg.network import CPGNetwork
from cpg_walker.experiments.bench import median_us
from cpg_walker.walker.controller import HumanoidCPG
from cpg_walker.walker.learning import learning_settings


def _controller(N: int, strides: int) -> HumanoidCPG:
    settings, params = learning_settings(N)
    from dataclasses import replace

    ctrl, _ = HumanoidCPG.learn("walk", replace(settings, max_strides=strides), params)
    return ctrl


def run(quick: bool = False) -> dict:
    reps, n = (3, 500) if quick else (7, 3000)
    out: dict = {}
    for N in (3, 10):
        ctrl = _controller(N, 10)  # a short learning is enough to time playback
        ctrl.set_modulation_state(1.0, 1.0)

        def tick(c=ctrl) -> None:
            c.step(0.002)
            c.joint_targets()

        bare = CPGNetwork(ctrl.net.omega.copy(), ctrl.net.params, time_scale=ctrl.net.time_scale)
        bare.freeze()
        out[f"n{N}"] = {
            "step_us": median_us(tick, n, reps),
            "bare_network_step_us": median_us(lambda b=bare: b.step(0.002), n, reps),
        }
        def tick_mod(c=ctrl) -> None:
            if c.zeta == c.zeta_command:  # filter settled: command the other speed
                c.set_zeta(0.8 if c.zeta_command != 0.8 else 1.2)
            c.step(0.002)
            c.joint_targets()

        out[f"n{N}"]["step_modulating_us"] = median_us(tick_mod, n, reps)
    settings, params = learning_settings(3)
    if quick:
        from dataclasses import replace

        settings = replace(settings, max_strides=20)
    t0 = time.perf_counter()
    _, rep = HumanoidCPG.learn("walk", settings, params)
    wall = time.perf_counter() - t0
    steps = rep.strides * round(rep.learn_time_s / rep.strides / rep.dt)
    out["learn_n3"] = {
        "wall_s": wall, "strides": rep.strides, "converged": rep.converged,
        "learning_step_us": rep.wall_time_s / steps * 1e6,
        "teaching_seconds_per_wall_second": rep.learn_time_s / rep.wall_time_s,
    }
    from cpg_walker.experiments.bench_validity import check_run, numbers

    return {k: {**check_run(figures=numbers(v)), **v} for k, v in out.items()}


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=2))
