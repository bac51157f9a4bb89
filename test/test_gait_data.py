"""The packaged recordings, the loader's errors, resampling and the steady-cycle finder."""

import hashlib

import numpy as np
import pytest

from cpg_walker.robot.gait_data import (
    DATA_DIR,
    Gait,
    GaitPlayback,
    _parse_gait,
    _search_steady_cycle,
    estimate_period,
    find_steady_cycle,
    load_gait,
)
from cpg_walker.robot.joints import RECORDED_JOINTS

SHA256 = {
    "walk.csv": "a260a26cf066c82ad6434673e1bfaec7e658f8e750656b5598b5bc8b966fe1a2",
    "slow_walk.csv": "5dea9937c681c457ec552bb5eab0e4c4b80fc6085004ff83e089c59d761efda9",
}


@pytest.mark.parametrize("name", sorted(SHA256))
def test_packaged_data_is_unchanged(name):
    assert hashlib.sha256((DATA_DIR / name).read_bytes()).hexdigest() == SHA256[name]
    assert "Apache License" in (DATA_DIR / "README.md").read_text()


def test_walk_by_joint_name():
    g = load_gait("walk")
    assert g.names == RECORDED_JOINTS and g.q.shape == (8233, 21)
    assert g.dt == pytest.approx(0.001) and g.duration == pytest.approx(8.232)
    assert g.column("lleg_joint_3")[0] == pytest.approx(-0.349066)  # hip pitch -20 deg
    assert g.column("rleg_joint_4")[0] == pytest.approx(0.697881)  # knee +40 deg
    with pytest.raises(KeyError):
        g.column("head_joint_1")


def test_resample_interpolates():
    g = load_gait("slow")
    r = g.resample(0.01)
    assert r.dt == pytest.approx(0.01) and len(r.t) == 965
    np.testing.assert_allclose(r.q[100], g.q[1000], atol=1e-12)
    np.testing.assert_allclose(g.at(0.0005), 0.5 * (g.q[0] + g.q[1]))
    with pytest.raises(ValueError):
        g.resample(0.0)


@pytest.mark.parametrize("gait, period", [("walk", 2.51), ("slow", 2.56)])
def test_steady_cycle(gait, period):
    g = load_gait(gait)
    assert estimate_period(g) == pytest.approx(period, abs=0.03)
    c = find_steady_cycle(g)
    assert c.period == pytest.approx(period, abs=0.05)
    assert c.end <= g.duration and c.start > 2.0
    assert c.mismatch_rad < 0.005  # the seam joins without a visible jump
    pb = GaitPlayback(g, cycle=c)
    assert pb.recording_time(c.end + 0.3) == pytest.approx(c.start + 0.3)
    q_before, _ = pb.targets(c.end - 0.001)
    q_after, _ = pb.targets(c.end + 0.001)
    assert np.abs(q_after - q_before).max() < 0.01


def _write(tmp_path, text):
    p = tmp_path / "g.csv"
    p.write_text(text)
    return p


HEAD = "time_s,lleg_joint_4,rleg_joint_4\n"


@pytest.mark.parametrize(
    "body, line, what",
    [
        ("0.000,0.1,0.2\n0.001,0.1\n", 3, "2 fields"),
        ("0.000,0.1,0.2\n0.001,abc,0.2\n", 3, "not a number"),
        ("0.000,0.1,0.2\n0.001,nan,0.2\n", 3, "non-finite"),
        ("0.000,0.1,0.2\n0.001,0.1,0.2\n0.001,0.1,0.2\n", 4, "does not increase"),
        ("0.000,0.1,0.2\n0.001,0.1,0.2\n0.005,0.1,0.2\n0.006,0.1,0.2\n", 4, "non-uniform"),
        ("0.000,0.1,0.2\n\n0.002,0.1,0.2\n", 3, "blank line"),
    ],
)
def test_loader_errors_name_the_line(tmp_path, body, line, what):
    p = _write(tmp_path, HEAD + body)
    with pytest.raises(ValueError, match=f"g.csv:{line}: .*{what}"):
        load_gait(p)


def test_loader_header_errors(tmp_path):
    with pytest.raises(ValueError, match=r"g.csv:1: .*unknown joint 'knee'"):
        load_gait(_write(tmp_path, "time_s,knee\n0,0\n0.001,0\n"))
    with pytest.raises(ValueError, match=r"g.csv:1: .*duplicate"):
        load_gait(_write(tmp_path, "time_s,lleg_joint_4,lleg_joint_4\n0,0,0\n0.001,0,0\n"))
    with pytest.raises(ValueError, match=r"g.csv:1: .*time_s"):
        load_gait(_write(tmp_path, "t,lleg_joint_4\n0,0\n0.001,0\n"))
    with pytest.raises(ValueError, match=r"g.csv:1: empty"):
        load_gait(_write(tmp_path, ""))
    with pytest.raises(ValueError, match="only 1 data row"):
        load_gait(_write(tmp_path, HEAD + "0,0,0\n"))
    with pytest.raises(FileNotFoundError, match=r"nowhere\.csv"):
        load_gait(tmp_path / "nowhere.csv")
    g = load_gait(_write(tmp_path, HEAD + "0.0,0.1,0.2\n0.002,0.3,0.4\n\n\n"))  # trailing blank lines ok
    assert g.names == ("lleg_joint_4", "rleg_joint_4") and g.dt == pytest.approx(0.002)


def test_loads_are_cached_by_content(tmp_path):
    g = load_gait("walk")
    assert load_gait("walk") is g  # parsed once per process
    fresh = _parse_gait((DATA_DIR / "walk.csv").read_bytes(), DATA_DIR / "walk.csv", "walk", 2)
    assert fresh.names == g.names and fresh.source == g.source and fresh.name == g.name
    assert fresh.t.tobytes() == g.t.tobytes() and fresh.q.tobytes() == g.q.tobytes()
    with pytest.raises(ValueError, match="read-only"):
        g.q[0, 0] = 1.0  # a shared Gait cannot be changed under another caller
    p = _write(tmp_path, HEAD + "0.0,0.1,0.2\n0.002,0.3,0.4\n")
    first = load_gait(p)
    assert load_gait(p) is first
    p.write_text(HEAD + "0.0,0.1,0.2\n0.002,0.3,0.5\n")  # same size, maybe the same mtime: new content
    second = load_gait(p)
    assert second.q[1, 1] == 0.5 and first.q[1, 1] == 0.4


def test_steady_cycle_is_cached_by_content():
    g = load_gait("walk")
    c = find_steady_cycle(g)
    assert find_steady_cycle(g) is c and c == _search_steady_cycle(g, 0.8, 0.15, 0.03, 1.5, 4.0)
    # another recording with the same source name but other samples gets its own search
    shorter = Gait(g.name, g.names, g.t[:-400].copy(), g.q[:-400].copy(), g.source)
    c2 = find_steady_cycle(shorter)
    assert c2.end <= shorter.duration < c.end and find_steady_cycle(shorter) is c2


@pytest.mark.parametrize("gait", ["walk", "slow"])
def test_playback_targets_interpolate_as_gait_at(gait):
    """GaitPlayback.targets (one scalar time, the played columns only) equals Gait.at to the last bit."""
    g = load_gait(gait)
    pb = GaitPlayback(g)
    vel = g.velocities()
    c = pb.cycle
    times = [-0.1, 0.0, 0.0005, 0.001, 1.2345, c.start, c.end - 1e-9, c.end, c.end + 0.0004, g.duration,
             g.duration + 0.5, 40.0, *np.random.default_rng(3).uniform(0.0, 30.0, 200)]
    cols = [g.names.index(n) for n in pb.names if n in g.names]
    dst = [i for i, n in enumerate(pb.names) if n in g.names]
    for t in times:
        tr = pb.recording_time(t)
        q, qd = pb.targets(t)
        assert q[dst].tobytes() == g.at(tr)[cols].tobytes(), t
        assert qd[dst].tobytes() == vel[min(round(tr / g.dt), len(vel) - 1), cols].tobytes(), t
