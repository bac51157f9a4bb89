"""Smoke test of the benchmark's scaling sections and its generated summary (experiments/bench_scaling.py,
bench_report.py): structure and finite values only — timings are the benchmark's business, not a test's."""

import json
import math

import pytest

from cpg_walker.experiments import bench_report, bench_scaling
from cpg_walker.experiments.bench import run_benchmarks


def _finite_positive(d: dict) -> bool:
    return all(isinstance(v, float) and math.isfinite(v) and v > 0 for v in d.values())


@pytest.mark.slow
def test_oscillators_section_writes_json_table_plot_and_readme_block(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{bench_report.BEGIN}\nold table\n{bench_report.END}\nrest\n")
    run_benchmarks(tmp_path, only=["oscillators"], quick=True, readme=readme)
    res = json.loads((tmp_path / "bench.json").read_text())
    assert set(res["machine"]["load_start"]) == {"1min", "5min", "15min"} and res["machine"]["wall_s"] > 0
    per = res["oscillators"]["per_dof"]
    assert list(per) == [str(n) for n in bench_scaling.OSCILLATORS_QUICK]
    for r in per.values():
        for backend in res["oscillators"]["backends"]:
            timings = {k: v for k, v in r[backend].items() if k != "max_state_difference_vs_solve_ivp"}
            assert _finite_positive(timings)
        assert r["solve_ivp_rk45_sim_s_per_wall_s"] > 0
    table = (tmp_path / "bench_table.md").read_text()
    assert "| 6 |" in table and "solve_ivp" in table
    assert (tmp_path / "bench_oscillators.png").stat().st_size > 10_000
    text = readme.read_text()
    assert "old table" not in text and "| 3 |" in text
    assert text.startswith("intro\n") and text.endswith("rest\n")


def test_vectorised_robots_report_both_ways_finite():
    out = bench_scaling._vectorised(2, quick=True)
    for r in out.values():
        assert set(r) == {"playback_stacked_us", "playback_loop_us", "playback_speedup",
                          "learning_stacked_us", "learning_loop_us", "learning_speedup"}
        assert _finite_positive(r)


def test_summary_skips_sections_that_did_not_run_and_readme_needs_markers(tmp_path):
    lines = bench_report.table({"machine": {}, "quick": True})
    assert lines[2:] == ["| figure | value | baseline (same run) | ratio |", "|---|---|---|---|"]
    (tmp_path / "README.md").write_text("no markers\n")
    with pytest.raises(ValueError, match="bench-table:begin"):
        bench_report.update_readme(tmp_path / "README.md", lines)
