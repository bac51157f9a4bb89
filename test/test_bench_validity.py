"""Benchmarks check their own runs (experiments/bench_validity.py): a walk that fell, got no controller
ticks or did not move is invalid, kept in bench.json with its reason, left out of the tables, and fails
`cpg-walker bench` when a headline figure stands on it. Records shaped as the sections write them."""

import copy
import json

from cpg_walker.cli.main import main
from cpg_walker.experiments.bench_graph import check_graph_run
from cpg_walker.experiments.bench_validity import (
    HEADLINE,
    MIN_WALK_DISTANCE_M,
    check_run,
    combine,
    headline_problems,
    invalid_runs,
)

#: cpg_node's exit stats as timing.TickStats writes them (abridged), and pid_node's (ActivityStats).
CPG_STATS = {"messages": 10000, "tick": {"ticks": 10000, "repeated_clock": 6, "overruns": 360,
                                         "work_ms": {"p50": 0.47, "p99": 3.2, "max": 54.6}}}
PID_STATS = {"messages": 10001, "active_wall_s": 63.2, "active_cpu_s": 9.3, "cpu_fraction": 0.148}


def graph_run(fell=False, distance=1.5672, rtf=0.3162, p50=1.26, **extra) -> dict:
    """A graph run as bench_graph.graph_run records it (before its validity is added)."""
    return {"real_time_factor": rtf, "sim_s": 20.0, "wall_s": 20.0 / rtf, "control_hz": 500,
            "latency_ms": {"count": 9998, "p50_ms": p50, "p99_ms": 21.7, "max_ms": 63.7},
            "late_commands": 0, "torque_age_mean_ms": 0.5,
            "cpu_core_fraction": {"sim_node": 0.5, "pid_node": 0.3}, "fell": fell, "distance_m": distance,
            **extra}


def test_a_good_walk_is_valid():
    run = graph_run(cpg_tick=CPG_STATS["tick"])
    assert check_graph_run(run, {"pid_node": PID_STATS, "cpg_node": CPG_STATS}, None, walking=True) == {
        "valid": True}


def test_a_fall_is_invalid_with_its_time():
    # the realtime section's subscribers_1 run of the 2026-12-02 benchmark
    run = graph_run(fell=True, distance=0.306)
    v = check_graph_run(run, {"pid_node": PID_STATS, "cpg_node": CPG_STATS}, 7.204, walking=True)
    assert v == {"valid": False, "invalid_reason": "fell at 7.2 s"}


def test_the_stalled_realtime_walk_is_invalid_no_ticks_and_no_movement():
    # graph.realtime_cpg_walk of the 2026-12-02 benchmark: cpg_node logged no stats, the robot stood
    run = graph_run(distance=0.0003, rtf=0.9626, cpg_tick={})
    v = check_graph_run(run, {"pid_node": PID_STATS, "cpg_node": {}}, None, walking=True)
    assert v["valid"] is False
    assert "no controller ticks (cpg_node reported no stats at exit)" in v["invalid_reason"]
    assert f"moved 0.0003 m (< {MIN_WALK_DISTANCE_M} m)" in v["invalid_reason"]


def test_zero_ticks_and_no_movement_each_invalidate():
    zero = copy.deepcopy(CPG_STATS)
    zero["tick"]["ticks"] = 0
    v = check_graph_run(graph_run(), {"pid_node": PID_STATS, "cpg_node": zero}, None, walking=True)
    assert v == {"valid": False, "invalid_reason": "no controller ticks (cpg_node)"}
    assert check_run(distance_m=0.04, walking=True)["valid"] is False
    assert check_run(distance_m=None, walking=True)["invalid_reason"] == "distance not recorded"
    assert check_run(distance_m=-1.0, walking=True)["valid"] is False  # backwards is not forward
    assert check_run(distance_m=0.06, walking=True) == {"valid": True}


def test_standing_runs_need_no_movement_but_ticks():
    # sim + PID standing (graph.realtime / fast / lockstep): 0.3 mm is right for them
    assert check_graph_run(graph_run(distance=0.0003), {"pid_node": PID_STATS}, None, walking=False) == {
        "valid": True}
    v = check_graph_run(graph_run(distance=0.0003), {"pid_node": {"messages": 0}}, None, walking=False)
    assert v == {"valid": False, "invalid_reason": "no controller ticks (pid_node)"}


def test_measurement_figures_and_combined_runs():
    assert check_run(figures={"step_us": 8.9, "diff": 0.0}) == {"valid": True}
    assert check_run(figures={"step_us": float("nan")})["invalid_reason"] == "step_us is nan"
    assert check_run(error="RuntimeError: sim_node exited")["valid"] is False
    bad = check_run(fell=True, fall_time_s=1.3)
    assert combine([{"valid": True}, bad, bad]) == {
        "valid": False, "invalid_reason": "2 of 3 runs invalid: fell at 1.3 s"}
    assert combine([])["valid"] is False


def bench_json(realtime_cpg_walk_valid: bool = True) -> dict:
    """A bench.json with the graph section only, every run checked as the section checks it."""
    both = {"pid_node": PID_STATS, "cpg_node": CPG_STATS}
    graph: dict = {
        "setup": {"control_period_s": 0.002},
        "baseline_inprocess": {"valid": True, "real_time_factor": 7.87, "cpu_s_per_sim_s": 0.09},
        "pingpong_baseline": {m: {"valid": True, "samples": 1000, "lost": 0, "p50_ms": p, "p99_ms": 9.8}
                              for m, p in (("executor", 1.6), ("hotpath", 0.61))},
    }
    for key, rtf in (("realtime", 0.99), ("fast", 0.51), ("lockstep", 0.61)):
        run = graph_run(distance=0.0003, rtf=rtf)
        graph[key] = {**run, **check_graph_run(run, {"pid_node": PID_STATS}, None, walking=False)}
    run = graph_run(cpg_tick=CPG_STATS["tick"])
    graph["lockstep_cpg_walk"] = {**run, **check_graph_run(run, both, None, walking=True)}
    if realtime_cpg_walk_valid:
        run = graph_run(rtf=0.97, distance=1.55, cpg_tick=CPG_STATS["tick"])
        stats = both
    else:
        run = graph_run(rtf=0.9626, distance=0.0003, cpg_tick={})
        stats = {"pid_node": PID_STATS, "cpg_node": {}}
    graph["realtime_cpg_walk"] = {**run, **check_graph_run(run, stats, None, walking=True)}
    return {"machine": {"cpus": 2, "date_utc": "2026-12-04T00:00:00Z"}, "quick": False, "graph": graph}


def test_headline_problems_name_the_invalid_headline_run():
    assert headline_problems(bench_json()) == []
    problems = headline_problems(bench_json(realtime_cpg_walk_valid=False))
    assert len(problems) == 1 and problems[0].startswith("graph.realtime_cpg_walk: no controller ticks")
    assert [p for p, _ in invalid_runs(bench_json(False))] == ["graph.realtime_cpg_walk"]
    assert all(isinstance(h, str) and "." in h for h in HEADLINE)


def test_headline_run_missing_its_check_fails():
    results = bench_json()
    del results["graph"]["lockstep"]["valid"]  # a bench.json from before runs were checked
    assert any(p.startswith("graph.lockstep: ") for p in headline_problems(results))


def test_from_json_with_an_invalid_headline_run_exits_1_and_the_tables_leave_it_out(tmp_path, capsys):
    results = bench_json(realtime_cpg_walk_valid=False)
    results["graph"]["lockstep"].update(check_run(fell=True, fall_time_s=7.8))  # also a table row's run
    src = tmp_path / "bench.json"
    src.write_text(json.dumps(results))
    assert main(["bench", "--out", str(tmp_path / "out"), "--from-json", str(src)]) == 1
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("cpg-walker bench: headline run invalid") and "fell at 7.8 s" in last
    table = (tmp_path / "out" / "bench_table.md").read_text()
    assert "ROS graph sim + PID, lockstep, × real time" not in table  # the fallen run's rows are gone
    assert "torque latency p50 (lockstep)" not in table
    assert "ROS graph sim + PID, fast pacing, × real time | 0.51×" in table  # a valid run's row stays
    assert "2 of " in table and "`graph.lockstep`: fell at 7.8 s" in table
    assert "`graph.realtime_cpg_walk`: no controller ticks" in table


def test_from_json_with_valid_headline_runs_exits_0(tmp_path):
    src = tmp_path / "bench.json"
    src.write_text(json.dumps(bench_json()))
    assert main(["bench", "--out", str(tmp_path / "out"), "--from-json", str(src)]) == 0
    table = (tmp_path / "out" / "bench_table.md").read_text()
    assert "ROS graph sim + PID, lockstep, × real time | 0.61×" in table
    assert "ROS graph 3-node CPG walk, lockstep, × real time | 0.32×" in table
