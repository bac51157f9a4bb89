"""Benchmark sections ``oscillators`` and ``robots``: how cost grows (registered in experiments/bench.py).

``oscillators``: the humanoid-shaped network 10×N for N = 1…12 oscillators per DOF, with bench_cpg's
case (the same teaching signal, learning at dt = 10 ms, playback at 1 kHz): µs per RK4 step of each
backend, learning speed, and the same equations under solve_ivp (RK45) over the same span (the ratio).

``robots``: R = 1…16 robots simulated at once, three ways, each beside its serial baseline:
  * vectorised CPGs: the packaged controller's 10×3 network copied R times and stacked into one network
    (`cpg.network.stack_networks`, one step for all) vs the R networks stepped one after the other;
    playback at the node's 2 ms and learning at 10 ms, both backends;
  * in-process walks (experiments/walk_runs: the sweep's runner): R short CPG walks in a pool of
    os.cpu_count() processes vs the same R walks one after the other in this process;
  * ROS graphs: R lockstep graphs (sim_node + pid_node + cpg_node), each in its own DDS domain, all
    started at once vs one after the other.
Ratios > 1 mean the batched/parallel way is faster. On a 2-core machine the parallel ones cannot exceed
~2 (plus overlapped start-up waits).
"""

from __future__ import annotations

import copy
import os
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from cpg_walker.experiments.bench import median_us
from cpg_walker.experiments.bench_cpg import BACKENDS, case
from cpg_walker.experiments.bench_validity import check_run, combine, numbers

#: Oscillators per DOF of the ``oscillators`` section (quick: a subset).
OSCILLATORS = tuple(range(1, 13))
OSCILLATORS_QUICK = (1, 3, 6)
#: Robots at once of the ``robots`` section (quick: a subset); ROS graphs up to 8 only: on a shared
#: 2-core machine 16 graphs one after the other take several minutes.
ROBOTS = (1, 2, 4, 8, 16)
ROBOTS_QUICK = (1, 2)
GRAPH_ROBOTS = (1, 2, 4, 8)


def _progress(msg: str) -> None:
    print(f"bench:   {msg}", file=sys.stderr, flush=True)


def run_oscillators(quick: bool = False) -> dict:
    """CPG step and learning cost of the 10×N network vs solve_ivp, N oscillators per DOF."""
    span, reps_n = (2.0, (3, 300)) if quick else (10.0, (5, 1000))
    out: dict = {}
    for n in OSCILLATORS_QUICK if quick else OSCILLATORS:
        _progress(f"oscillators: 10x{n}")
        entry = case((10, n), 2.5, 0.01, span, quick, reps_n)
        out[str(n)] = {**check_run(figures=numbers(entry)), **entry}
    return {"per_dof": out, "network": "10 CPGs x N oscillators (uncoupled CPGs, eq 8 inside each), "
            "teaching 3 harmonics of 2.5 rad/s; learning dt 10 ms, playback 1 kHz",
            "step_cost": f"median of {reps_n[0]} x {reps_n[1]} steps", "learning_span_s": span,
            "backends": list(BACKENDS)}


def _vectorised(R: int, quick: bool) -> dict:
    """R robots' CPG networks: one stacked step vs R separate steps, playback and learning."""
    from cpg_walker.cpg.network import CPGNetwork, stack_networks
    from cpg_walker.walker import storage
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    ctrl, _, _ = load_controller(cpg_defaults()["cpg_file"])
    learned = storage.to_dict(ctrl)
    n, reps = (100, 3) if quick else (400, 5)
    out: dict = {}
    for backend in BACKENDS:
        played = []
        for r in range(R):  # each robot at its own phase
            net = storage.from_dict(copy.deepcopy(learned)).net
            net.backend = backend
            net.step(0.002 * (r + 1))
            played.append(net)
        stack = stack_networks(played)
        w0 = np.tile(2.5 * np.arange(1, 4) * 0.97, (10, 1))
        learning = [CPGNetwork(w0, backend=backend) for _ in range(R)]
        lstack = stack_networks(learning)
        teach = np.sin(np.arange(3)[:, None] * 0.005 + np.arange(10)[None, :])
        tstack = np.tile(teach, (1, R))

        def loop_play(nets=played) -> None:
            for net in nets:
                net.step(0.002)

        def loop_learn(nets=learning, p=teach) -> None:
            for net in nets:
                net.step(0.01, p)

        def stack_play(s=stack) -> None:
            s.step(0.002)

        def stack_learn(s=lstack, p=tstack) -> None:
            s.step(0.01, p)

        for fn in (loop_play, stack_play, loop_learn, stack_learn):
            fn()  # warm-up (kernels compiled or loaded)
        play_loop, play_stack = median_us(loop_play, n, reps), median_us(stack_play, n, reps)
        learn_loop, learn_stack = median_us(loop_learn, n, reps), median_us(stack_learn, n, reps)
        out[backend] = {
            "playback_stacked_us": play_stack, "playback_loop_us": play_loop,
            "playback_speedup": play_loop / play_stack,
            "learning_stacked_us": learn_stack, "learning_loop_us": learn_loop,
            "learning_speedup": learn_loop / learn_stack,
        }
    return out


def _walk_spec(duration: float):
    from cpg_walker.experiments.walk_runs import WalkSpec

    return WalkSpec(duration_after_s=duration, variant="off")


def _walks(counts: tuple[int, ...], duration: float) -> dict:
    """R in-process walks for each R in ``counts``: in a process pool (the sweep's runner) vs serially
    in this process (the serial wall for R is that of the first R of max(counts) walks timed one by one)."""
    from cpg_walker.experiments.walk_runs import run_many, run_walk

    jobs = os.cpu_count() or 1
    spec = _walk_spec(duration)
    run_walk(spec)  # warm-up: controller, gait data and kernels loaded, as in the pool's workers later
    serial, errors, serial_runs = [], [], []
    for k in range(max(counts)):
        _progress(f"robots: in-process walk {k + 1}/{max(counts)} serially")
        t0 = time.perf_counter()
        done = run_many(run_walk, [spec], jobs=1)
        serial.append(time.perf_counter() - t0)
        errors += [r["error"] for r in done if "error" in r]
        serial_runs += [_walk_record(r) for r in done]
    out: dict = {}
    for R in counts:
        _progress(f"robots: {R} in-process walks in {min(jobs, R)} processes")
        t0 = time.perf_counter()
        done = run_many(run_walk, [spec] * R, jobs=jobs)
        parallel_s = time.perf_counter() - t0
        errors += [r["error"] for r in done if "error" in r]
        serial_s = sum(serial[:R])
        runs = {"serial": serial_runs[:R], "parallel": [_walk_record(r) for r in done]}
        out[str(R)] = {**combine(runs["serial"] + runs["parallel"]), "runs": runs,
                       "serial_wall_s": serial_s, "parallel_wall_s": parallel_s,
                       "speedup": serial_s / parallel_s, "processes": min(jobs, R) if R > 1 else 0,
                       "sim_s_per_wall_s_serial": R * duration / serial_s,
                       "sim_s_per_wall_s_parallel": R * duration / parallel_s}
    out["errors"] = errors[:3]
    return out


def _walk_record(m: dict) -> dict:
    """One in-process walk of the section (walk_runs.run_walk's metrics) with its validity."""
    return {**check_run(fell=m.get("fell"), fall_time_s=m.get("fall_time_s"), distance_m=m.get("distance_m"),
                        walking=True, error=m.get("error")),
            **{k: m.get(k) for k in ("fell", "fall_time_s", "distance_m")}}


def _distinct_domains(R: int) -> list[int]:
    """R different DDS domains on which no other node is seen (other graphs may share the machine)."""
    from cpg_walker.graph.processes import domain_is_quiet, random_domain_id

    chosen: list[int] = []
    tries = 0
    while len(chosen) < R:
        d = random_domain_id()
        tries += 1
        if d not in chosen and (tries > 10 * R or domain_is_quiet(d, wait=0.2)):
            chosen.append(d)
    return chosen


def _graphs(counts: tuple[int, ...], parallel_counts: tuple[int, ...], duration: float, work: Path) -> dict:
    """Lockstep CPG-walk graphs, each in its own domain: R = max(counts) run one after the other (each
    timed: the serial wall for R is that of the first R), then R at once for each R in ``parallel_counts``."""
    from cpg_walker.experiments.bench_graph import controller_ticks
    from cpg_walker.experiments.replay_graph import run_graph

    errors: list[str] = []

    def one(k: int, domain: int, mode: str) -> tuple[float, float, dict]:
        t0 = time.perf_counter()
        try:
            run = run_graph(work, "cpg_node", duration=duration, pacing="lockstep",
                            timeout=120 + 30 * duration, tag=f"{mode}_{k}", domain_id=domain)
            rtf = float(run.record.stats["real_time_factor"])
            rec = run.record
            stats = {n: st for n, st in run.stats.items() if n != "sim_node"}
            distance = round(float(rec.base_xy[-1][0] - rec.base_xy[0][0]), 4) if rec.base_xy else None
            # walking=False: these runs are 1 sim s of the recorded opening steps, which move the base
            # only millimetres; they time start-up and throughput, so fall and ticks are what must hold
            record = {**check_run(fell=bool(rec.fell), fall_time_s=rec.fall_time_s,
                                  ticks=controller_ticks(stats)),
                      "fell": bool(rec.fell), "distance_m": distance, "real_time_factor": rtf}
        except Exception as exc:  # a failed run is reported (its wall time still counts), not fatal
            errors.append(f"{mode}_{k}: {type(exc).__name__}: {str(exc)[:200]}")
            rtf = float("nan")
            record = check_run(error=errors[-1])
        return time.perf_counter() - t0, rtf, record

    domains = _distinct_domains(max(counts))
    serial = []
    for k, d in enumerate(domains):
        _progress(f"robots: ROS graph {k + 1}/{len(domains)} serially (domain {d})")
        serial.append(one(k, d, "serial"))
    out: dict = {"domains": domains}
    for R in parallel_counts:
        _progress(f"robots: {R} ROS graphs at once")
        t0 = time.perf_counter()
        with ThreadPoolExecutor(R) as pool:  # the nodes are processes; threads only wait for them
            runs = list(pool.map(one, range(R), domains[:R], [f"parallel{R}"] * R))
        parallel_s = time.perf_counter() - t0
        serial_s = sum(w for w, _, _ in serial[:R])
        records = {"serial": [r for _, _, r in serial[:R]], "parallel": [r for _, _, r in runs]}
        out[str(R)] = {**combine(records["serial"] + records["parallel"]), "runs": records,
                       "serial_wall_s": serial_s, "parallel_wall_s": parallel_s,
                       "speedup": serial_s / parallel_s,
                       "sim_rtf_serial_median": float(np.median([r for _, r, _ in serial[:R]])),
                       "sim_rtf_parallel_median": float(np.median([r for _, r, _ in runs]))}
    out["errors"] = errors
    return out


def run_robots(quick: bool = False) -> dict:
    """R robots at once: vectorised CPGs, in-process walks in processes, ROS graphs in domains."""
    counts = ROBOTS_QUICK if quick else ROBOTS
    walk_s, graph_s = (3.0, 1.0) if quick else (4.0, 1.0)  # from standing: 1 s moves 5 mm, 3 s 0.17 m
    work = Path(tempfile.mkdtemp(prefix="bench_robots_"))
    out: dict = {"setup": {"robots": list(counts), "graph_robots": list(counts if quick else GRAPH_ROBOTS),
                           "walk_sim_s": walk_s, "graph_sim_s": graph_s,
                           "cpus": os.cpu_count(),
                           "graph": "sim_node + pid_node + cpg_node, lockstep, one DDS domain per robot",
                           "walk": "in-process CPG walk from standing (walk_runs.run_walk, feedback off)",
                           "serial": "max(R) runs one after the other, each timed; serial wall for R = "
                                     "the first R of them"},
                 "vectorised_cpg": {}}
    for R in counts:
        _progress(f"robots: R={R} vectorised CPG")
        entry = _vectorised(R, quick)
        out["vectorised_cpg"][str(R)] = {**check_run(figures=numbers(entry)), **entry}
    out["inprocess_walks"] = _walks(counts, walk_s)
    graphs = counts if quick else GRAPH_ROBOTS
    out["ros_graphs"] = _graphs(graphs, graphs[-1:] if quick else graphs, graph_s, work)
    return out
