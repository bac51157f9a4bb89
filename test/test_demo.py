"""`cpg-walker demo`: its schedule and summary (in-process), and the real command end to end - a short run
writes the recording, the plots, the video and summary.json, exits 0 and leaves no process behind; SIGINT
mid-run stops every node and still writes what was recorded (multi-process, marker ``ros``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from types import SimpleNamespace

import pytest
from ros_helpers import START_S, node_pids, sim_deadline

from cpg_walker.experiments.demo import (
    DEMO_SCHEDULE,
    FULL_DEMO_S,
    MIN_WALK_S,
    GraphStatus,
    demo_schedule,
    segments,
    walk_start_s,
)
from cpg_walker.nodes import interface as ifc

NS = SimpleNamespace  # a message's fields
#: Sim s of the end-to-end run: the recorded opening steps (~6.6 s), walking forward, the "faster" segment
#: (11.75-17.75 s) whole, and the start of "shorter steps".
SHORT_S = 20.0
#: Sim s a segment must last for its speed (over its second half) to be compared with the in-process run.
COMPARED_SEGMENT_S = 4.0
#: Post-processing (reading the bag, plots, ~150 video frames rendered on the CPU), a hang guard (wall s).
AFTER_S = 900.0


def test_schedule_is_fixed_in_sim_time_and_reverses_from_forward_walking():
    start = walk_start_s()
    assert 5.0 < start < 8.0  # the recorded opening steps, then the hand-over to the CPG
    times = [t for t, _, _, _ in DEMO_SCHEDULE]
    assert times == sorted(times) and start < times[0] and FULL_DEMO_S <= 60.0  # the default shows all
    for duration in (start + MIN_WALK_S, SHORT_S, 30.0, 60.0, 120.0):
        assert demo_schedule(duration, start) == [(t, z, a) for t, z, a, _ in DEMO_SCHEDULE if t < duration]
    zetas = [1.0] + [z for _, z, _, _ in DEMO_SCHEDULE]
    first_back = next(i for i, z in enumerate(zetas) if z < 0)
    assert first_back > 1 and max(zetas[:first_back]) > 1.0  # walks forward (faster too) before reversing
    alphas = [1.0] + [a for _, _, a, _ in DEMO_SCHEDULE]
    # from forward walking at zeta = alpha = 1: 1.5 -> -1, and (1, 0) -> (-1, 1), were measured to fall
    assert (zetas[first_back - 1], alphas[first_back - 1]) == (1.0, 1.0)
    with pytest.raises(ValueError, match="too short"):
        demo_schedule(start + MIN_WALK_S - 0.1, start)


def test_segments_start_when_cpg_node_applied_the_change():
    sent = [{"t_s": 8.0, "zeta": 1.4, "alpha": 1.0, "accepted": True, "applied_after_sim_s": 8.3},
            {"t_s": 9.0, "zeta": 1.0, "alpha": 0.5, "accepted": False},
            {"t_s": 10.0, "zeta": 1.0, "alpha": 0.0, "accepted": True}]
    segs = segments(sent, 12.0)
    assert [(s["from_s"], s["to_s"], s["zeta"], s["alpha"]) for s in segs] == [
        (0.0, 8.3, 1.0, 1.0), (8.3, 10.0, 1.4, 1.0), (10.0, 12.0, 1.0, 0.0)]
    assert segs[1]["label"] and segs[2]["label"]
    assert [s["from_s"] for s in segments([(5.0, 1.4, 1.0), (20.0, 1.0, 0.5)], 12.0)] == [0.0, 5.0]


def test_status_line_from_messages():
    status = GraphStatus(lambda line, t: None)
    assert "sim    0.0 s" in status.line() and "speed - m/s" in status.line()
    stamp = lambda t: NS(sec=int(t), nanosec=round((t % 1) * 1e9))  # noqa: E731
    quarter = NS(w=0.9238795325112867, x=0.0, y=0.0, z=0.3826834323650898)  # yaw 45 deg
    for t in (1.0, 2.0):
        status._on_clock(NS(clock=stamp(t)))
        status._on_odom(NS(header=NS(stamp=stamp(t)), pose=NS(pose=NS(
            position=NS(x=0.1 * t, y=0.1 * t, z=0.3), orientation=quarter))))
    status._on_diagnostics(NS(status=[NS(name="cpg_walker/cpg", values=[
        NS(key="zeta", value="1.4"), NS(key="alpha", value="0.5"), NS(key="state", value="walking")])]))
    status.fallen = True
    line = status.line()
    assert "sim    2.0 s" in line and "speed +0.141 m/s" in line and "heading +45 deg" in line
    assert "zeta +1.40 alpha 0.50" in line and "cpg walking" in line and "FALLEN" in line


def test_status_off_a_terminal_is_plain_lines():
    import io

    from cpg_walker.experiments.demo import StatusDisplay

    buf = io.StringIO()  # not a terminal: no progress bar, no control characters
    with StatusDisplay(10.0, plain_every_s=0.0, stream=buf) as show:
        for line, t in (("sim 0.0 s", 0.0), ("sim 0.0 s", 0.5), ("sim 1.0 s", 1.0)):
            show(line, t)
    assert buf.getvalue() == "sim 0.0 s\nsim 1.0 s\n"


# ------------------------------------------------------------------------------------- end to end

def _demo(out, ros_domain, duration: float) -> subprocess.Popen:
    from cpg_walker.graph.processes import isolated_env

    return subprocess.Popen(
        [sys.executable, "-m", "cpg_walker.cli.main", "demo", "--duration", str(duration), "--out", str(out)],
        env=isolated_env(ros_domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        stdin=subprocess.DEVNULL, start_new_session=True)


def _finish(p: subprocess.Popen, timeout: float) -> str:
    try:
        out, _ = p.communicate(timeout=timeout)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return out


def _check_outputs(out, summary: dict) -> None:
    from cpg_walker.nodes.recording import read_topics

    files = summary["files"]
    assert "recording.mcap" in files and "walk.mp4" in files and "summary.json" in files
    assert {"targets_vs_states.png", "modulation.png"} <= set(files)
    for name in files:
        assert (out / name).stat().st_size > 0, name
    topics = read_topics(out / "recording.mcap", [ifc.JOINT_STATES, ifc.IMU, ifc.TF, ifc.ROBOT_DESCRIPTION,
                                                  ifc.JOINT_TARGETS, ifc.ODOM_GROUND_TRUTH])
    sim_s = summary["duration_s"]
    assert len(topics[ifc.ROBOT_DESCRIPTION]) == 1
    assert len(topics[ifc.ODOM_GROUND_TRUTH]) >= 0.9 * sim_s / 0.01  # odom_period 0.01 sim s
    for name in (ifc.JOINT_STATES, ifc.IMU, ifc.JOINT_TARGETS):  # every 0.002 sim s control period
        assert len(topics[name]) >= 0.9 * sim_s / 0.002, name
    assert len(topics[ifc.TF]) >= 0.9 * len(topics[ifc.ODOM_GROUND_TRUTH])
    import imageio.v2 as imageio

    with imageio.get_reader(out / "walk.mp4") as video:
        assert video.count_frames() >= 0.9 * sim_s * 12.5  # sim speed, 12.5 frames per sim s


@pytest.mark.ros
@pytest.mark.slow
def test_short_demo_writes_everything_and_leaves_nothing(tmp_path, ros_domain):
    out = tmp_path / "demo"
    p = _demo(out, ros_domain, SHORT_S)
    log = _finish(p, sim_deadline(SHORT_S) + AFTER_S)
    left = node_pids(ros_domain)
    assert p.returncode == 0, log[-3000:]
    assert not left and subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True).returncode == 1
    assert "\x1b" not in log and "\r" not in log  # not a terminal: plain status lines
    assert "sim " in log and "| RTF " in log and "zeta " in log
    summary = json.loads((out / "summary.json").read_text())
    _check_outputs(out, summary)
    assert summary["interrupted"] is False and summary["duration_s"] == pytest.approx(SHORT_S, abs=0.05)
    segs = summary["segments"]
    assert [(s["zeta"], s["alpha"]) for s in segs] == [(1.0, 1.0)] + [(z, a) for t, z, a, _ in DEMO_SCHEDULE
                                                                      if t < SHORT_S]
    walk = json.loads((out / "walk.json").read_text())
    assert [s["applied_after_sim_s"] for s in walk["schedule"]] == [s["from_s"] for s in segs[1:]]
    assert summary["fell"] is False and walk["fell"] is False
    # each segment's speed: the first (from t = 0, the recorded opening steps in it) walks forward; the
    # others that last long enough within the margin of the same schedule walked in-process (the
    # committed docs/results/headline/headline.json, test_headline.py)
    from pathlib import Path

    from cpg_walker.experiments.headline import RESULTS_NAME, speed_bound

    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    artifact = results / RESULTS_NAME / f"{RESULTS_NAME}.json"
    inproc = {s["label"]: s for r in json.loads(artifact.read_text())["runs"] if r["name"] == "demo_schedule"
              for s in r["segments"]}
    assert segs[0]["speed_mps"] > 0.5 * inproc[segs[0]["label"]]["speed_mps"], segs[0]
    compared = [s for s in segs[1:] if s["to_s"] - s["from_s"] >= COMPARED_SEGMENT_S]
    assert compared, segs
    for seg in compared:
        want = inproc[seg["label"]]["speed_mps"]
        assert abs(seg["speed_mps"] - want) <= speed_bound(want), (seg, want)


@pytest.mark.ros
@pytest.mark.slow
def test_sigint_stops_every_node_and_still_writes_the_outputs(tmp_path, ros_domain):
    from ros_helpers import Probe
    from rosgraph_msgs.msg import Clock

    out = tmp_path / "demo"
    p = _demo(out, ros_domain, 40.0)
    probe = Probe(ros_domain)
    try:
        probe.listen(ifc.CLOCK, Clock, 1)
        sim_s = lambda: probe.received[ifc.CLOCK][-1][1].clock.sec if probe.received[ifc.CLOCK] else 0  # noqa: E731
        probe.wait(lambda: sim_s() >= 3, "the demo's sim to reach 3 s", sim_deadline(3.0))
    finally:
        probe.close()
    assert node_pids(ros_domain), "the demo's nodes should be running"
    p.send_signal(signal.SIGINT)
    log = _finish(p, AFTER_S + START_S)
    left = node_pids(ros_domain)
    assert p.returncode == 130, log[-3000:]
    assert not left and subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True).returncode == 1
    assert "SIGINT: stopping the graph" in log and "interrupted" in log
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 3.0 <= summary["duration_s"] < 40.0
    _check_outputs(out, summary)

