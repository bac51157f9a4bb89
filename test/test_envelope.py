"""`cpg-walker envelope` (experiments/envelope.py): the quick grid of short walks through the command line
(files, JSON structure, a known-walking and a known-falling cell), the per-ζ summary on made-up cells, and
bad configuration."""

from __future__ import annotations

import json

import pytest

from cpg_walker.cli.main import main
from cpg_walker.experiments.config_file import ConfigError
from cpg_walker.experiments.envelope import grid, load_config, summarize

CELL_KEYS = {"zeta", "alpha", "start", "status", "fell", "fall_time_s", "fall_after_s", "t_applied_s",
             "steady_speed_mps", "mean_speed_mps", "lateral_drift_m", "heading_change_deg", "duration_s"}


def test_quick_envelope_writes_the_map(tmp_path, capsys):
    out = tmp_path / "env"
    assert main(["envelope", "--out", str(out), "--quick", "--jobs", "1"]) == 0  # falls are data
    assert "8 cells" in capsys.readouterr().out
    rep = json.loads((out / "envelope.json").read_text())
    assert set(rep) >= {"provenance", "config", "grid", "cells", "summary", "t_applied_s", "quick"}
    assert rep["quick"] is True
    assert set(rep["provenance"]) >= {"command", "commit", "date", "load_average_start", "load_average_end"}
    assert rep["provenance"]["command"].startswith("cpg-walker envelope")
    g = rep["grid"]
    assert g == {"zeta": [1.0, 2.0], "alpha": [1.0, 2.0], "starts": ["standing", "at_10s"]}
    assert 6.0 < rep["t_applied_s"]["standing"] < 7.5 and rep["t_applied_s"]["at_10s"] == 10.0
    cells = {(c["start"], c["zeta"], c["alpha"]): c for c in rep["cells"]}
    assert len(cells) == len(rep["cells"]) == 8
    for c in cells.values():
        assert CELL_KEYS <= set(c), CELL_KEYS - set(c)
        assert c["status"] in ("walks", "stalls", "falls")
        assert c["fell"] is (c["status"] == "falls")
        assert (c["fall_time_s"] is None) is (not c["fell"])
        if c["fell"]:
            assert c["fall_after_s"] == pytest.approx(c["fall_time_s"] - c["t_applied_s"], abs=1e-3)
    for s in g["starts"]:
        ok = cells[(s, 1.0, 1.0)]  # the gait as taught: walks forward at ~0.09 m/s
        assert ok["status"] == "walks" and 0.05 < ok["steady_speed_mps"] < 0.15
        bad = cells[(s, 2.0, 2.0)]  # twice as fast, twice as long steps: falls within seconds
        assert bad["status"] == "falls" and 0 < bad["fall_after_s"] < 5.0
    summ = {(d["start"], d["zeta"]): d for d in rep["summary"]}
    assert summ[("standing", 1.0)]["walking_alpha"] == [1.0]
    md = (out / "envelope.md").read_text()
    assert "| ζ \\ α |" in md and "## standing" in md and "## at_10s" in md and "| +1 |" in md
    assert (out / "envelope.png").read_bytes()[:4] == b"\x89PNG"


def test_summary_ranges_gaps_and_edge_falls():
    g = {"zeta": [1.0], "alpha": [0.5, 1.0, 1.5, 2.0], "starts": ["standing"]}

    def c(a, status, after=None):
        return {"start": "standing", "zeta": 1.0, "alpha": a, "status": status, "fall_after_s": after}

    d = summarize([c(0.5, "falls", 3.0), c(1.0, "walks"), c(1.5, "stalls"), c(2.0, "falls", 1.2)], g)[0]
    assert d["walking_alpha"] == [1.0, 1.5] and d["contiguous"]
    assert d["edge_falls"] == [{"alpha": 0.5, "fall_after_s": 3.0}, {"alpha": 2.0, "fall_after_s": 1.2}]
    d = summarize([c(0.5, "walks"), c(1.0, "falls", 4.0), c(1.5, "walks"), c(2.0, "walks")], g)[0]
    assert not d["contiguous"] and d["edge_falls"] == []
    d = summarize([c(a, "falls", a) for a in g["alpha"]], g)[0]
    assert d["walking_alpha"] == [] and d["fall_after_s_range"] == [0.5, 2.0]


def test_default_grid_and_bad_configs(tmp_path):
    cfg = load_config()
    g = grid(cfg)
    assert 1.0 in g["zeta"] and -1.0 in g["zeta"] and 1.0 in g["alpha"]
    assert g["zeta"] == sorted(g["zeta"]) and cfg["variant"] == "ours"
    good = "\n".join(f"{k}: {json.dumps(v)}" for k, v in cfg.items())
    for bad, where in [("alpha: [-1.0]", "alpha"), ("starts: [walking]", "starts"),
                       ("duration_after_s: 0", "duration_after_s"), ("variant: off", "variant"),
                       ("zeta: {forward: [x]}", "zeta"), ("colour: red", "colour")]:
        p = tmp_path / "e.yaml"
        key = bad.split(":")[0]
        p.write_text("\n".join(line for line in good.splitlines() if not line.startswith(key + ":"))
                     + "\n" + bad + "\n")
        with pytest.raises(ConfigError, match=where):
            load_config(p)
