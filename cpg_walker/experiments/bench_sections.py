"""The benchmark's sections: name -> the function that runs it. experiments/bench.py runs them;
bench_report.py and the command line check a bench.json against the names."""

from __future__ import annotations

# name -> "module:function". Each later issue adds its own section here.
SECTIONS: dict[str, str] = {
    "cpg": "cpg_walker.experiments.bench_cpg:run",
    "robot": "cpg_walker.experiments.bench_robot:run",
    "humanoid": "cpg_walker.experiments.bench_humanoid:run",
    "loop": "cpg_walker.experiments.bench_loop:run",
    "graph": "cpg_walker.experiments.bench_graph:run",
    "realtime": "cpg_walker.experiments.bench_realtime:run",
    "oscillators": "cpg_walker.experiments.bench_scaling:run_oscillators",
    "robots": "cpg_walker.experiments.bench_scaling:run_robots",
    "studies": "cpg_walker.experiments.bench_studies:run",
}
