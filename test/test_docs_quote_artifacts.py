"""The docs' generated tables are their committed artifacts' (each block in the doc that
readme_blocks.BLOCKS names): the benchmark block of docs/benchmarks.md from docs/bench/bench.json
(experiments/bench_report.table), the README's headline walks' block from
docs/results/headline/headline.json (test_headline.py); a figure edited by hand, or an artifact
regenerated without its block, fails here. Every artifact `cpg-walker results` knows is committed."""

from __future__ import annotations

import json
from pathlib import Path

from cpg_walker.experiments.artifacts import ARTIFACTS, PLACES
from cpg_walker.experiments.readme_blocks import BLOCKS, block_file, read_block

REPO = Path(__file__).resolve().parents[1]


def test_the_benchmark_tables_are_bench_json_s():
    from cpg_walker.experiments.bench_report import table

    doc = block_file("bench-table", REPO)
    block = read_block(doc.read_text(encoding="utf-8"), "bench-table")
    assert block is not None, f"{doc.relative_to(REPO)} has no bench-table block"
    results = json.loads((REPO / "docs" / "bench" / "bench.json").read_text())
    assert block == "\n".join(table(results)) + "\n"


def test_every_artifact_results_regenerates_is_committed():
    root = REPO / "docs" / "results"
    for art in ARTIFACTS:
        folder = (root / PLACES.get(art.name, art.name)).resolve()
        missing = [f for f in art.files if not (folder / f).is_file()]
        # faults.md beside faults.json is new with `cpg-walker results`; the rest must all be there
        assert not [f for f in missing if f.endswith(".json")], (art.name, folder, missing)



def test_each_generated_block_is_in_its_doc_and_only_there():
    """readme_blocks.BLOCKS is where the commands write each block: it must be there, and no other doc may
    keep a stale copy of it (a moved block left behind would no longer be regenerated)."""
    docs = [REPO / "README.md", REPO / "CHANGELOG.md", *sorted((REPO / "docs").glob("*.md"))]
    for name, rel in BLOCKS.items():
        holders = [d.relative_to(REPO).as_posix() for d in docs if d.is_file()
                   and read_block(d.read_text(encoding="utf-8"), name) is not None]
        assert holders == [rel], (name, holders)
