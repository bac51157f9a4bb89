"""The exit-status rule (cli/outcome.py) on real walks: a walk that falls exits 1 with the fall on the last
stderr line; the same command through the governor (the default) walks and exits 0; bad input exits 2."""

from __future__ import annotations

import json

from cpg_walker.cli.main import main

FAST_FALL = ["--duration", "12", "--zeta", "2.0", "--alpha", "2.0", "--feedback", "off", "--no-render"]


def test_a_walk_that_falls_exits_1_with_the_fall_on_the_last_line(tmp_path, capsys):
    status = main(["cpg-walk", *FAST_FALL, "--governor", "off", "--out", str(tmp_path / "raw")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and err[-1].startswith("cpg-walker cpg-walk: FELL at "), err[-3:]
    walk = json.loads((tmp_path / "raw" / "walk.json").read_text())
    assert walk["fell"] and walk["fall_time_s"] is not None and walk["governed"] is False


def test_the_same_command_through_the_governor_walks_and_exits_0(tmp_path, capsys):
    status = main(["cpg-walk", *FAST_FALL, "--out", str(tmp_path / "governed")])
    walk = json.loads((tmp_path / "governed" / "walk.json").read_text())
    assert status == 0 and not walk["fell"] and "governed" not in walk, capsys.readouterr().err[-500:]


def test_bad_input_exits_2(tmp_path, capsys):
    assert main(["cpg-walk", "--governor", "sideways", "--out", str(tmp_path / "x")]) == 2
    assert "argument --governor" in capsys.readouterr().err
