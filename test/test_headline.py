"""The README's locomotion results as regression tests: every headline walk (experiments/headline.py: zeta 1
for 60 s, zeta 1.5 and -1.2 from standing and changed at run time, a reversal, alpha 0 -> 1, the demo's
schedule; in-process, the default feedback pathways) is walked again and must not fall, and its speed,
heading change, lateral drift and segment speeds must stay within ``MARGINS`` of the committed artifact
(docs/results/headline/headline.json, written by ``cpg-walker results``); the README's results table must
be that artifact's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cpg_walker.experiments.headline import MARGINS, SCENARIOS, differences, markdown, run_all, speed_bound
from cpg_walker.experiments.readme_blocks import block_file, read_block

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
ARTIFACT = REPO / "docs" / "results" / "headline" / "headline.json"
README = block_file("results-table", REPO)  # README.md (readme_blocks.BLOCKS)


@pytest.fixture(scope="module")
def committed() -> dict:
    return json.loads(ARTIFACT.read_text())


@pytest.fixture(scope="module")
def fresh() -> dict:
    """Every headline walk, once for the module (two processes)."""
    return {r["name"]: r for r in run_all(jobs=2)}


def test_the_artifact_holds_every_scenario_as_specified_now(committed):
    """A scenario added or changed since the artifact was written: regenerate it (`cpg-walker results`)."""
    runs = {r["name"]: r for r in committed["runs"]}
    assert set(runs) == {s.name for s in SCENARIOS}
    for sc in SCENARIOS:
        spec = runs[sc.name]["spec"]
        assert (spec["zeta"], spec["alpha"], spec["start"], spec["duration_after_s"], spec["variant"]) == (
            sc.spec.zeta, sc.spec.alpha, sc.spec.start, sc.spec.duration_after_s, sc.spec.variant), sc.name
        assert [tuple(x) for x in spec["schedule"]] == [tuple(x) for x in sc.spec.schedule], sc.name
        assert not runs[sc.name]["fell"], f"the committed {sc.name} fell: no headline result"
    made = committed["provenance"]
    assert made["commit"] and made["command"].startswith("cpg-walker results"), made


@pytest.mark.parametrize("name", [s.name for s in SCENARIOS])
def test_the_headline_walk_walks_as_committed(name, committed, fresh):
    """No fall; speed, heading and drift (and each segment's speed) within MARGINS of the artifact."""
    mine = next(r for r in committed["runs"] if r["name"] == name)
    assert differences(mine, fresh[name]) == []


def test_the_margins_catch_a_changed_walk(committed):
    """The comparison fails a walk that fell, slowed by more than the margin or turned (so the tests above
    can fail)."""
    base = next(r for r in committed["runs"] if r["name"] == "zeta1_60s")
    assert differences(base, dict(base)) == []
    bound = speed_bound(base["steady_speed_mps"])
    slower = dict(base, steady_speed_mps=base["steady_speed_mps"] - 1.01 * bound)
    turned = dict(base, heading_change_deg=base["heading_change_deg"] + MARGINS["heading_deg"] + 0.1)
    fell = dict(base, fell=True, fall_time_s=30.0)
    for changed, word in ((slower, "steady_speed_mps"), (turned, "heading_change_deg"), (fell, "fell")):
        found = differences(base, changed)
        assert len(found) == 1 and word in found[0], found
    demo = next(r for r in committed["runs"] if r["name"] == "demo_schedule")
    backwards = [dict(s) for s in demo["segments"]]
    backwards[-1]["speed_mps"] = -backwards[-1]["speed_mps"]
    assert "backwards" in differences(demo, dict(demo, segments=backwards))[0]


def test_the_readme_quotes_the_artifact(committed):
    """The README's results table is generated from the artifact (`cpg-walker results --only headline
    --docs`)."""
    block = read_block(README.read_text(encoding="utf-8"), "results-table")
    assert block is not None, f"{README.name} has no results-table block"
    assert block == markdown(committed)
