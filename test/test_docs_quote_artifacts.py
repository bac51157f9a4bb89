"""The README's generated tables are their committed artifacts' (README "Results"): the benchmark block
from docs/bench/bench.json (experiments/bench_report.table), the headline walks' block from
docs/results/headline/headline.json (test_headline.py); a figure edited by hand, or an artifact
regenerated without its block, fails here. Every artifact `cpg-walker results` knows is committed."""

from __future__ import annotations

import json
from pathlib import Path

from cpg_walker.experiments.artifacts import ARTIFACTS, PLACES
from cpg_walker.experiments.readme_blocks import read_block

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text(encoding="utf-8")


def test_the_readme_benchmark_tables_are_bench_json_s():
    from cpg_walker.experiments.bench_report import table

    block = read_block(README, "bench-table")
    assert block is not None, "README.md has no bench-table block"
    results = json.loads((REPO / "docs" / "bench" / "bench.json").read_text())
    assert block == "\n".join(table(results)) + "\n"


def test_every_artifact_results_regenerates_is_committed():
    root = REPO / "docs" / "results"
    for art in ARTIFACTS:
        folder = (root / PLACES.get(art.name, art.name)).resolve()
        missing = [f for f in art.files if not (folder / f).is_file()]
        # faults.md beside faults.json is new with `cpg-walker results`; the rest must all be there
        assert not [f for f in missing if f.endswith(".json")], (art.name, folder, missing)

