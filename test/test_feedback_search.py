"""`cpg-walker feedback-search` (experiments/feedback_search.py): bad configuration is one error naming
the line and field, the objective's order (survive first), resume continues the same seeded search,
and the files (trials.jsonl, best.yaml, holdout.json/.md) on a tiny search of very short walks."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from cpg_walker.cli.main import main
from cpg_walker.experiments.config_file import ConfigError
from cpg_walker.experiments.feedback_search import Space, holdout, load_config, scenario_cost, search
from cpg_walker.walker.feedback import FeedbackConfig

TINY = """\
pathways: default
fields:
  gain_scale: [0.0, 0.02]
  reset_strength: [0.1, 1.0]
cma: {sigma0: 0.3, popsize: 3, generations: 2}
transition: recording
objective: {fall_penalty: 1000.0, speed_weight: 10.0, min_speed_mps: 0.02, heading_weight: 1.0,
            heading_deg_per_min: 5.0, drift_weight: 1.0, drift_m_per_min: 0.2, torque_weight: 0.5,
            torque_Nm: 1.0}
reference: {zeta: 1.0, start: standing, duration_after_s: 1.5}
scenarios:
  - {name: fast, zeta: 1.5, start: standing, duration_after_s: 0.6}
holdout:
  - {name: slippery, zeta: 1.3, start: standing, duration_after_s: 0.6, friction_scale: 0.7}
"""
OBJ = yaml.safe_load(TINY)["objective"]


@pytest.mark.parametrize("text, needle", [
    (TINY.replace("  reset_strength:", "  reset_strenght:"), "feedback_search.yaml:4 fields.reset_strenght: "
                                                              "unknown FeedbackConfig field"),
    (TINY.replace("[0.0, 0.02]", "[0.02, 0.02]"),
     "feedback_search.yaml:3 fields.gain_scale: low must be < high"),
    (TINY.replace("  reset_strength: [0.1, 1.0]", "  lateral_mode: [0, 1]"),
     "feedback_search.yaml:4 fields.lateral_mode: not a numeric field"),
    (TINY.replace("friction_scale: 0.7", "friction: 0.7"),
     "feedback_search.yaml:14 holdout.0: unknown scenario"),
])
def test_bad_config_is_one_error_naming_the_line(tmp_path, text, needle):
    cfg = tmp_path / "feedback_search.yaml"
    cfg.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(needle)):
        load_config(cfg)


def test_cli_reports_a_bad_field_as_one_line(tmp_path, capsys):
    cfg = tmp_path / "feedback_search.yaml"
    cfg.write_text(TINY.replace("[0.1, 1.0]", "[1.0, 0.1]"))
    assert main(["feedback-search", "--out", str(tmp_path / "o"), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "feedback_search.yaml:4 fields.reset_strength: low must be < high" in err[0]


def test_packaged_config_names_real_fields():
    cfg, quick = load_config(), load_config(quick=True)
    assert set(cfg["fields"]) <= set(FeedbackConfig.load().__dict__)
    assert quick["cma"]["popsize"] * len(quick["scenarios"]) < cfg["cma"]["popsize"] * len(cfg["scenarios"])
    assert {s["name"] for s in cfg["scenarios"]}.isdisjoint(s["name"] for s in cfg["holdout"])


def _m(**kw):
    m = {"fell": False, "fall_time_s": None, "t_cmd_s": 10.0, "window_s": 60.0, "zeta": 1.5, "alpha": 1.0,
         "steady_speed_mps": 0.12, "heading_change_deg": 0.0, "lateral_drift_m": 0.0,
         "mean_abs_torque_Nm": 0.0}
    return {**m, **kw}


def test_objective_survival_first_then_speed_straightness_torque():
    v1 = 0.08
    assert scenario_cost(_m(), v1, OBJ) == pytest.approx(0.0)
    worst_walk = scenario_cost(_m(steady_speed_mps=-0.2, heading_change_deg=90.0, lateral_drift_m=2.0,
                                  mean_abs_torque_Nm=5.0), v1, OBJ)
    late_fall = scenario_cost(_m(fell=True, fall_time_s=69.0), v1, OBJ)
    early_fall = scenario_cost(_m(fell=True, fall_time_s=11.0), v1, OBJ)
    assert worst_walk < late_fall < early_fall
    assert late_fall == pytest.approx(1000.0 - 59.0)
    assert scenario_cost(_m(steady_speed_mps=0.09), v1, OBJ) == pytest.approx(10 * 0.03 / 0.12)
    assert scenario_cost(_m(heading_change_deg=-5.0), v1, OBJ) == pytest.approx(1.0)  # 5° per minute
    assert scenario_cost(_m(lateral_drift_m=0.2), v1, OBJ) == pytest.approx(1.0)
    assert scenario_cost(_m(mean_abs_torque_Nm=2.0), v1, OBJ) == pytest.approx(1.0)


def test_space_maps_the_unit_cube_to_the_ranges():
    s = Space({"a": [-2.0, 2.0], "b": [0.0, 0.5]})
    assert s.values(np.array([0.5, 1.0])) == {"a": 0.0, "b": 0.5}
    assert s.values(np.array([-1.0, 2.0])) == {"a": -2.0, "b": 0.5}  # clipped
    assert s.normalise({"a": 1.0, "b": 0.25}) == pytest.approx([0.75, 0.5])


def _trials(d):
    return [json.loads(x) for x in (d / "trials.jsonl").read_text().splitlines()]


def test_search_resumes_with_the_same_candidates_and_writes_its_files(tmp_path):
    cfg = tmp_path / "fs.yaml"
    cfg.write_text(TINY)
    quiet = {"jobs": 1, "config": str(cfg), "log": lambda s: None}
    once, twice = tmp_path / "once", tmp_path / "twice"
    search(once, generations=2, seed=7, **quiet)
    search(twice, generations=1, seed=7, **quiet)
    assert len(_trials(twice)) == 3
    with pytest.raises(ValueError, match="already holds a search"):
        search(twice, generations=2, seed=7, **quiet)
    with pytest.raises(ValueError, match=r"differs in \['seed'\]"):
        search(twice, generations=2, seed=8, resume=True, **quiet)
    search(twice, generations=2, seed=7, resume=True, **quiet)
    a, b = _trials(once), _trials(twice)
    assert [t["generation"] for t in b] == [0, 0, 0, 1, 1, 1]
    assert [t["params"] for t in a] == [t["params"] for t in b]  # generation 1 too: the state was restored
    assert len({json.dumps(t["params"]) for t in a}) == 6
    for t in a:
        assert set(t["params"]) == {"gain_scale", "reset_strength"}
        assert set(t["scenarios"]) == {"fast"}
        assert {"fell", "steady_speed_mps", "heading_change_deg", "cost"} <= set(t["scenarios"]["fast"])
        assert t["objective"] == pytest.approx(t["scenarios"]["fast"]["cost"], abs=1e-3)
    best = yaml.safe_load((once / "best.yaml").read_text())
    lowest = min(a, key=lambda t: t["objective"])
    assert best == pytest.approx({k: round(v, 6) for k, v in lowest["params"].items()})
    FeedbackConfig.load(**best)  # a valid feedback.yaml fragment

    r = holdout(once, jobs=1, config=str(cfg))
    sets = [(row["scenario"], row["set"]) for row in r["rows"]]
    assert sets == [("fast", "searched"), ("slippery", "held-out")]
    for row in r["rows"]:
        assert {"off", "default", "best"} <= set(row)
    assert set(r["objective_best"]) == {"searched", "held-out"}
    md = (once / "holdout.md").read_text()
    assert "| fast | searched |" in md and "| slippery | held-out |" in md
