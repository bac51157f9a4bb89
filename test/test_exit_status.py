"""The exit-status rule (cli/outcome.py) on real walks: a walk that falls exits 1 with the fall on the last
stderr line; the same command through the governor (on by default with feedback; `--feedback off` is the
paper's open-loop controller without it) refuses a step length longer than any that walked (exit 2) and
walks the speed at the step length that walks (exit 0); bad input exits 2."""

from __future__ import annotations

import json

from cpg_walker.cli.main import main

FAST_FALL = ["--duration", "12", "--zeta", "2.0", "--alpha", "2.0", "--feedback", "off", "--no-render"]


def test_a_walk_that_falls_exits_1_with_the_fall_on_the_last_line(tmp_path, capsys):
    status = main(["cpg-walk", *FAST_FALL, "--out", str(tmp_path / "raw")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and err[-1].startswith("cpg-walker cpg-walk: FELL at "), err[-3:]
    walk = json.loads((tmp_path / "raw" / "walk.json").read_text())
    assert walk["fell"] and walk["fall_time_s"] is not None and walk["governed"] is False


def test_through_the_governor_the_step_length_is_refused_and_the_walkable_part_walks(tmp_path, capsys):
    status = main(["cpg-walk", *FAST_FALL, "--governor", "on", "--out", str(tmp_path / "refused")])
    err = capsys.readouterr().err.strip().splitlines()
    from cpg_walker.walker.governor import GovernorConfig

    top = GovernorConfig.load().alpha_limit  # the envelopes' longest step (1.4, with the ankle pathway)
    assert status == 2 and len(err) == 1 and f"--alpha: alpha must be in [0, {top:g}], got 2.0" in err[0], err
    assert "longer steps fell at every zeta" in err[0]
    k = FAST_FALL.index("--alpha") + 1
    fast = [*FAST_FALL[:k], "1.0", *FAST_FALL[k + 1:]]
    status = main(["cpg-walk", *fast, "--governor", "on", "--out", str(tmp_path / "governed")])
    walk = json.loads((tmp_path / "governed" / "walk.json").read_text())
    assert status == 0 and not walk["fell"] and "governed" not in walk, capsys.readouterr().err[-500:]


def test_the_governor_defaults_to_on_with_feedback_and_off_with_the_open_loop():
    from cpg_walker.cli.cpg_walk import governed

    assert [governed(None, f) for f in ("on", None, "off")] == [True, True, False]
    assert [governed(g, "off") for g in ("on", "off")] == [True, False]
    assert [governed(g, "on") for g in ("on", "off")] == [True, False]


def test_bad_input_exits_2(tmp_path, capsys):
    assert main(["cpg-walk", "--governor", "sideways", "--out", str(tmp_path / "x")]) == 2
    assert "argument --governor" in capsys.readouterr().err
