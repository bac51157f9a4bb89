"""`cpg-walker sweep` (experiments/sweep.py, walk_runs.py): its files and keys on a tiny grid of very short
walks, the window metrics on a known path, the fall-threshold summary, and bad configuration."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from cpg_walker.cli.main import main
from cpg_walker.experiments.config_file import ConfigError
from cpg_walker.experiments.sweep import fall_thresholds, load_config, run_sweep
from cpg_walker.experiments.walk_runs import WalkSpec, start_time, variant, window_metrics
from cpg_walker.walker.loop import ReplayResult, summarize

TINY = """\
duration_after_s: 1.0
transition: recording
variants: ['off', ours]
starts: [standing, at_1s]
zeta: {forward: [1.5], backward: [-1.0]}
alpha:
  zeta: 1.0
  start: at_1s
  values: [0.5]
  variants: [ours]
  stop_resume: {stop_at_s: 1.0, resume_at_s: 1.5, resume_alpha: 1.0, end_s: 2.0, settle_s: 0.1}
push: {zeta: 1.0, at_s: 0.5, after_s: 0.5, duration_s: 0.1, directions: [1.0], variants: [ours],
       max_impulse_Ns: 4.0, iterations: 1}
fig8: {zeta: 1.2, start: at_1s, after_s: 1.0, plot_from_s: 0.0, plot_periods: 1, variants: ['off', ours]}
transitions: {states: [[1.0, 1.0], [-1.0, 1.0]], phases: 2, from_s: 0.5, to_s: 1.0, after_s: 0.5}
paper:
  speed_points: [{zeta: 1.5, speed_mps: 0.12}]
  fall_threshold_without_feedback: 1.05
"""
RUN_KEYS = {"zeta", "alpha", "feedback", "start", "fell", "fall_time_s", "duration_s", "distance_m",
            "mean_speed_mps", "lateral_drift_m", "heading_change_deg", "variant"}


def test_sweep_writes_json_markdown_and_pngs(tmp_path):
    cfg = tmp_path / "sweep.yaml"
    cfg.write_text(TINY)
    run_sweep(tmp_path / "out", jobs=1, config=str(cfg), progress_enabled=False)
    out = tmp_path / "out"
    report = json.loads((out / "sweep.json").read_text())
    runs = report["runs"]
    assert len(runs) == 2 * 2 * 2  # zetas x variants x starts
    for r in runs:
        assert RUN_KEYS <= set(r), RUN_KEYS - set(r)
        assert r["start"] in ("standing", "at_1s")
        assert r["feedback"] is (r["variant"] != "off")
        assert isinstance(r["fell"], bool)
        assert r["fall_time_s"] is None or r["fell"]
        assert r["duration_s"] == pytest.approx(start_time(r["start"]) + 1.0, abs=0.02) or r["fell"]
    assert {(r["zeta"], r["variant"], r["start"]) for r in runs} == {
        (z, v, s) for z in (1.5, -1.0) for v in ("off", "ours") for s in ("standing", "at_1s")}
    assert [p["variant"] for p in report["push"]] == ["ours"]
    assert len(report["push"][0]["tried"]) == 1
    assert report["push"][0]["tried"][0]["impulse_Ns"] == 2.0  # the bracket's midpoint
    labels = sorted(r["spec"]["label"] for r in report["alpha"])
    assert labels == ["alpha", "stop_resume"]
    sr = next(r for r in report["alpha"] if r["spec"]["label"] == "stop_resume")
    assert len(sr["segments"]) == 3 and isinstance(sr["stops_and_resumes"], bool)
    fig8 = report["fig8"]["runs"]
    assert [r["variant"] for r in fig8] == ["off", "ours"]
    assert len(fig8[0]["targets"]["names"]) == 10 and len(fig8[0]["targets"]["rows"]) > 50
    md = (out / "sweep.md").read_text()
    assert "| +1.5 |" in md and "| -1 |" in md and "standing: off" in md and "at_1s: ours" in md
    tr = json.loads((out / "transitions.json").read_text())
    assert len(tr["runs"]) == 2 * 2 and {(tuple(r["from"]), tuple(r["to"])) for r in tr["runs"]} == {
        ((1.0, 1.0), (-1.0, 1.0)), ((-1.0, 1.0), (1.0, 1.0))}
    assert len(tr["survived_fraction"]) == 2 and tr["survived_fraction"][0][0] is None
    for png in ("speed_vs_zeta", "fall_map", "heading", "alpha", "fig8", "transitions"):
        assert (out / f"{png}.png").read_bytes()[:4] == b"\x89PNG"


def _result(xy: np.ndarray, heading: np.ndarray, t: np.ndarray, touch: dict) -> ReplayResult:
    return ReplayResult(t=t, base_xy=xy, base_z=np.full(len(t), 0.3), heading=heading,
                        loads=np.zeros((len(t), 2)), touchdowns=touch, fell=False, fall_time_s=None,
                        duration_s=float(t[-1]))


def test_window_metrics_on_a_known_path():
    """Along +x at 0.1 m/s for 10 s, then turned 90° left walking along +y: a window is measured in the
    frame of the pose at its start."""
    t = np.arange(1, 2001) * 0.01
    xy = np.where(t[:, None] <= 10, np.c_[0.1 * t, 0 * t], np.c_[np.full_like(t, 1.0), 0.1 * (t - 10)])
    heading = np.where(t <= 10, 0.0, math.pi / 2)
    touch = {"left": [2.0, 11.0, 13.0], "right": [3.0, 12.0, 14.0, 16.0, 18.0]}
    m = window_metrics(_result(xy, heading, t, touch), 0.0, 10.0)
    assert m["distance_m"] == pytest.approx(1.0, abs=0.002)
    assert m["lateral_drift_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["steps"] == 2 and m["step_length_m"] == pytest.approx(0.5, abs=0.01)
    m = window_metrics(_result(xy, heading, t, touch), 10.5)
    assert m["distance_m"] == pytest.approx(0.95, abs=0.002)  # along the new heading (+y)
    assert m["lateral_drift_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["steady_speed_mps"] == pytest.approx(0.1, abs=1e-3)
    assert m["heading_change_deg"] == 0.0
    assert m["steps"] == 6
    m = window_metrics(_result(xy, heading, t, touch), 5.0)  # across the turn: 0.5 m on, 1 m to the left
    assert (m["distance_m"], m["lateral_drift_m"], m["heading_change_deg"]) == pytest.approx((0.5, 1.0, 90.0),
                                                                                             abs=0.002)


def test_heading_change_is_measured_over_whole_strides_not_one_sample_of_the_sway():
    """A straight walk whose torso yaws ±6° within each 2.5 s stride has no heading change, wherever the
    window starts or ends in the stride; a real turn of 10° on top of the sway is measured as 10°."""
    t = np.arange(1, 6001) * 0.01
    sway = np.where(t >= 1.0, math.radians(6.0) * np.sin(2 * math.pi * (t - 1.0) / 2.5), 0.0)  # stands 1 s
    xy = np.c_[0.08 * t, 0 * t]
    touch = {"left": [], "right": list(np.arange(1.0, 60.0, 2.5))}
    for t0 in (10.0, 10.6, 11.2):
        m = window_metrics(_result(xy, sway, t, touch), t0, 57.3)
        assert m["heading_change_deg"] == pytest.approx(0.0, abs=0.1), (t0, m)
    turned = sway + np.where(t > 30.0, math.radians(10.0), 0.0)
    m = window_metrics(_result(xy, turned, t, touch), 10.6, 57.3)
    assert m["heading_change_deg"] == pytest.approx(10.0, abs=0.1)
    r = _result(xy, sway, t, touch)
    s = summarize(r)
    assert s["heading_change_deg"] == pytest.approx(0.0, abs=0.1)
    assert s["yaw_change_final_sample_deg"] == pytest.approx(math.degrees(sway[-1]), abs=0.01)


def test_fall_thresholds_are_the_smallest_zeta_that_fell():
    def run(z, fell, v="off", s="standing"):
        return {"zeta": z, "fell": fell, "variant": v, "start": s}

    runs = [run(1.0, False), run(1.2, True), run(1.1, True), run(1.5, True), run(-1.0, False),
            run(-1.3, True), run(1.5, False, "ours"), run(-1.0, False, "ours")]
    th = fall_thresholds(runs)
    assert th["off/standing"] == {"first_fall_forward": 1.1, "first_fall_backward": -1.3,
                                  "walked_+1.5": False, "walked_-1": True}
    assert th["ours/standing"]["first_fall_forward"] is None and th["ours/standing"]["walked_+1.5"]


def test_variants_and_starts():
    assert variant("off") == (None, {})
    assert variant("paper")[0] == ("lateral", "pendulum", "reset")
    assert start_time("at_12.5s") == 12.5 and start_time("standing") == 0.0
    with pytest.raises(ValueError, match="start 'later'"):
        start_time("later")
    with pytest.raises(ValueError, match="variant 'all'"):
        WalkSpec(variant="all").feedback()


def test_packaged_config_is_valid_and_quick_is_smaller():
    full, quick = load_config(), load_config(quick=True)
    assert len(quick["zeta"]["forward"]) < len(full["zeta"]["forward"])
    assert quick["duration_after_s"] < full["duration_after_s"]
    assert min(full["zeta"]["forward"]) == 0.6 and max(full["zeta"]["forward"]) == 1.8
    assert max(full["zeta"]["backward"]) == -0.6 and min(full["zeta"]["backward"]) == -1.5


@pytest.mark.parametrize("text, needle", [
    ("speed: 3\n" + TINY, "sweep.yaml:1 speed: unknown key"),
    (TINY.replace("variants: ['off', ours]", "variants: [off, ours]"),
     "sweep.yaml:3 variants: write 'off' in quotes"),
    (TINY.replace("[standing, at_1s]", "[standing, soon]"), "sweep.yaml:4 starts: start 'soon'"),
    (TINY.replace("duration_after_s: 1.0", "duration_after_s: -1.0"),
     "sweep.yaml:1 duration_after_s: must be"),
])
def test_bad_config_is_one_error_naming_the_line(tmp_path, text, needle):
    cfg = tmp_path / "sweep.yaml"
    cfg.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(needle)):
        load_config(cfg)


def test_cli_reports_a_bad_config_as_one_line(tmp_path, capsys):
    cfg = tmp_path / "sweep.yaml"
    cfg.write_text(TINY.replace("variants: ['off', ours]", "variants: ['off', best]"))
    assert main(["sweep", "--out", str(tmp_path / "o"), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sweep.yaml:3 variants" in err[0] and "'best'" in err[0]


def test_run_many_keeps_order_and_reports_a_crashed_item():
    import math as m

    from cpg_walker.experiments.walk_runs import run_many

    class Count:
        n = 0

        def update(self, k):
            self.n = k

    for jobs in (1, 2):
        c = Count()
        out = run_many(m.sqrt, [16.0, 4.0, -1.0, 9.0], jobs=jobs, progress=c)
        assert out[:2] == [4.0, 2.0] and out[3] == 3.0, jobs
        assert out[2] == {"error": "ValueError: math domain error"}
        assert c.n == 4
    with pytest.raises(ValueError, match="--jobs must be >= 1"):
        run_many(m.sqrt, [1.0, 2.0], jobs=0)
