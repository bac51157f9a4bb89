"""The benchmark section "loop" (experiments/bench_loop.py) reports the in-process walk's time split."""

import json

import pytest

from cpg_walker.experiments.bench import run_benchmarks


@pytest.mark.slow
def test_loop_section_reports_loop_and_physics_time(tmp_path):
    run_benchmarks(tmp_path, only=["loop"], quick=True)
    r = json.loads((tmp_path / "bench.json").read_text())["loop"]["cpg_walk_20s"]
    assert r["mj_step_calls"] == 20000  # every physics step of the 20 s walk went through the timer
    assert 0 < r["mj_step_s"] < r["loop_wall_s"]  # the loop's wall time contains its physics
    assert r["loop_to_physics_time_ratio"] == pytest.approx(r["loop_wall_s"] / r["mj_step_s"], rel=0.02)
    assert r["walk"]["fell"] is False and r["walk"]["distance_m"] > 1.0  # the walk that cpg-walk does
    assert "loop_to_physics_time_ratio" in (tmp_path / "bench.md").read_text()
