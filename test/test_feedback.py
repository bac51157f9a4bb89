"""Feedback pathways (walker/feedback.py): the laws of eqs 14–20, the radial projection, phase resetting,
and one closed-loop walk."""

import math

import numpy as np
import pytest

from cpg_walker.cpg.hopf import phase as oscillator_phase
from cpg_walker.errors import InputError
from cpg_walker.paths import config_path
from cpg_walker.robot.contact import TouchdownDetector
from cpg_walker.robot.hoap2 import tilt_from_quat
from cpg_walker.walker import storage
from cpg_walker.walker.controller import HumanoidCPG
from cpg_walker.walker.feedback import (
    ANKLE1,
    ANKLE2,
    HIP1,
    KNEE,
    RIGHT_HIP2,
    FeedbackConfig,
    FeedbackController,
    feedback_vector,
    gains,
    lateral_terms,
    pendulum_term,
    phase_reset,
)


def _quat(roll: float, pitch: float) -> np.ndarray:
    """Chest orientation (w, x, y, z) with this (roll, pitch) tilt: pitch about y, then roll about x."""
    qy = np.array([math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0])
    qx = np.array([math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0])
    w1, x1, y1, z1 = qy
    w2, x2, y2, z2 = qx
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


@pytest.fixture(scope="module")
def ctrl() -> HumanoidCPG:
    return storage.load(config_path("cpg_humanoid.yaml"))


def test_gains_eq19_20():
    cfg = FeedbackConfig.load(lateral_base=2000.0, lateral_slope=200.0, pendulum_slope=1000.0)
    assert gains(1.0, cfg) == (2000.0, 0.0)
    k_lat, k_pend = gains(1.5, cfg)
    assert k_lat == pytest.approx(2100.0) and k_pend == pytest.approx(500.0)
    k_lat, k_pend = gains(0.8, cfg)
    assert k_lat == pytest.approx(1960.0) and k_pend == pytest.approx(-200.0)


def test_lateral_signs():
    # eqs 14-15: |psi| -> the sign of the tilt does not matter; Ankle2 positive, Hip1 negative
    assert lateral_terms(0.1, 2000.0) == pytest.approx((200.0, -200.0))
    assert lateral_terms(-0.1, 2000.0) == pytest.approx((200.0, -200.0))
    # signed variant: the sign follows the tilt
    assert lateral_terms(-0.1, 2000.0, "signed") == pytest.approx((-200.0, 200.0))
    assert lateral_terms(0.1, 2000.0, "signed", -1.0) == pytest.approx((-200.0, 200.0))
    assert pendulum_term(0.05, 500.0) == pytest.approx(25.0)


def test_feedback_vector_targets_the_right_cpgs():
    cfg = FeedbackConfig.load(gain_scale=0.01, g_limit=100.0, lateral_base=2000.0, lateral_slope=200.0,
                              pendulum_slope=1000.0, lateral_mode="abs")
    g = feedback_vector(0.05, 0.02, 1.5, cfg)
    assert np.allclose(g[list(ANKLE2)], 0.01 * 2100 * 0.05)
    assert np.allclose(g[list(HIP1)], -0.01 * 2100 * 0.05)
    assert np.allclose(g[list(KNEE) + list(ANKLE1)], 0.01 * 500 * 0.02)
    others = np.ones(10, bool)
    others[list(ANKLE2) + list(HIP1) + list(KNEE) + list(ANKLE1)] = False
    assert np.all(g[others] == 0)  # the two Hip2 CPGs get nothing
    only_lat = feedback_vector(0.05, 0.02, 1.5, cfg, ("lateral",))
    assert np.all(only_lat[list(KNEE)] == 0) and np.all(only_lat[list(ANKLE2)] != 0)
    assert np.all(np.abs(feedback_vector(10.0, 10.0, 1.5, cfg)) <= cfg.g_limit)


def test_tilt_from_quat_signs():
    def q(axis, ang):
        a = np.asarray(axis, float) * math.sin(ang / 2)
        return (math.cos(ang / 2), *a)

    # rotation about +x by +a: the up-axis goes to -y (left side up) = leaning right, roll > 0
    roll, pitch = tilt_from_quat(q((1, 0, 0), 0.1))
    assert roll == pytest.approx(0.1) and pitch == pytest.approx(0.0, abs=1e-12)
    roll, pitch = tilt_from_quat(q((0, 1, 0), 0.1))  # about +y: up-axis to +x = leaning forward
    assert pitch == pytest.approx(0.1) and roll == pytest.approx(0.0, abs=1e-12)
    # yaw does not change the tilt
    yawed = tilt_from_quat(np.array([0.9, 0.05, 0.03, 0.4]) / np.linalg.norm([0.9, 0.05, 0.03, 0.4]))
    base = tilt_from_quat(np.array([0.9, 0.05, 0.03, 0.0]) / np.linalg.norm([0.9, 0.05, 0.03, 0.0]))
    assert abs(yawed[0]) > 0.05 and abs(base[0]) > 0.05


def test_g_changes_amplitude_not_phase(ctrl):
    net_a = ctrl.net
    s0 = net_a.state[:2].copy()
    h = 0.002
    g = np.zeros(10)
    g[list(ANKLE2)] = 2.0
    g[list(HIP1)] = -2.0
    runs = {}
    for name, fb in (("open", None), ("fb", g)):
        net_a.state[:2] = s0
        for _ in range(1500):
            net_a.step(h, feedback=fb)
        runs[name] = net_a.state[:2].copy()
    net_a.state[:2] = s0
    r = {k: np.hypot(v[0], v[1]) for k, v in runs.items()}
    th = {k: np.arctan2(v[0], -v[1]) for k, v in runs.items()}
    for b in ANKLE2:
        assert np.all(r["fb"][b] > 1.08 * r["open"][b])
    for b in HIP1:
        assert np.all(r["fb"][b] < 0.92 * r["open"][b])
    for b in KNEE:
        assert np.allclose(r["fb"][b], r["open"][b], rtol=1e-6)
    # integrated over 3 s the phases stay together; the small residual is the eq-4 locking offset,
    # which depends on the radius (tau/r), not a tangential push of g
    dth = np.angle(np.exp(1j * (th["fb"] - th["open"])))
    assert np.max(np.abs(dth)) < 0.03
    # exactly: the g term of eqs 16-17 is parallel to (x, y) - no tangential (phase) component
    d0, d1 = np.empty((2, 10, net_a.N)), np.empty((2, 10, net_a.N))
    net_a._g = None
    net_a.playback_rhs(s0, None, d0)
    net_a._g = g
    net_a.playback_rhs(s0, None, d1)
    net_a._g = None
    dd = d1 - d0
    assert np.max(np.abs(dd)) > 0.1
    assert np.allclose(dd[0] * s0[1] - dd[1] * s0[0], 0.0, atol=1e-12)


def test_phase_reset_sets_phase_and_keeps_relative_phases(ctrl):
    net = ctrl.net
    ctrl.reset_phase(0.7)
    s = net.state[:2].copy()
    omega = net.omega.copy()
    target = -1.53
    before = np.arctan2(s[0], -s[1])
    r_before = np.hypot(s[0], s[1])
    d = phase_reset(s, omega, target)
    after = np.arctan2(s[0], -s[1])
    assert oscillator_phase(s[0, RIGHT_HIP2, 0], s[1, RIGHT_HIP2, 0]) == pytest.approx(target)
    assert abs(d) > 0.1  # 0.7 s into the cycle is not at the touchdown phase: a real shift happened
    assert np.allclose(np.hypot(s[0], s[1]), r_before)
    # a time shift: every oscillator moved by (omega/omega_ref)*d, so eq-8 and eq-13 relations hold
    shift = np.angle(np.exp(1j * (after - before)))
    expect = np.angle(np.exp(1j * (omega / omega[RIGHT_HIP2, 0]) * d))
    assert np.allclose(shift, expect, atol=1e-9)
    main = after[:, 0]
    main_before = before[:, 0]
    rel = np.angle(np.exp(1j * (main - main[RIGHT_HIP2])))
    rel_before = np.angle(np.exp(1j * (main_before - main_before[RIGHT_HIP2])))
    assert np.allclose(rel, rel_before, atol=0.01)  # main oscillators share ~one frequency
    half = phase_reset(s.copy(), omega, target + 1.0, strength=0.5)
    assert half == pytest.approx(0.5, abs=1e-9)


def test_touchdown_detector():
    td = TouchdownDetector(10.0, 3.0, 0.25)
    seq = [(0.0, (20, 20)), (0.1, (20, 1)), (0.2, (20, 20)),  # 0.1 s lift: a graze, no event
           (0.3, (20, 1)), (0.7, (20, 15))]  # 0.4 s lift: right touchdown
    events = [td.update(t, loads) for t, loads in seq]
    assert events == [(False, False)] * 4 + [(False, True)]


def test_controller_filters_and_rejects_unknown_pathways():
    with pytest.raises(ValueError):
        FeedbackController(FeedbackConfig.load(), ("lateral", "vision"))
    fc = FeedbackController(FeedbackConfig.load(tilt_time_constant_s=0.1, pitch_reference_rad=0.05),
                            ("lateral",))
    fc.observe(0.0, _quat(0.0, 0.05), np.zeros(3), (20, 20))
    fc.observe(0.1, _quat(0.1, 0.05), np.zeros(3), (20, 20))
    assert fc.psi[0] == pytest.approx(tilt_from_quat(_quat(0.1, 0.05))[0] * (1 - math.exp(-1)))
    assert fc.psi[1] == pytest.approx(0.0)
    assert FeedbackConfig.load().lateral_mode in ("abs", "signed")


def test_feedback_config_lives_in_the_yaml_only(tmp_path):
    with pytest.raises(TypeError):
        FeedbackConfig()  # no code defaults: config/feedback.yaml is the one home of the values
    bad = tmp_path / "fb.yaml"
    bad.write_text("gain_scale: 0.01\n")
    with pytest.raises(ValueError, match="missing key"):
        FeedbackConfig.load(str(bad))
    with pytest.raises(ValueError, match="unknown key"):
        FeedbackConfig.load(gain_sclae=0.02)


def test_feedback_trace_keeps_one_sample_per_trace_period(ctrl):
    """The g trace has a sample every 10 ms of sim time from 2 ms ticks (float equality dropped some)."""
    from cpg_walker.walker.gait_source import FeedbackGaitSource

    src = FeedbackGaitSource(storage.from_dict(storage.to_dict(ctrl)),
                             FeedbackController(FeedbackConfig.load(), ("lateral",)))
    h = ctrl.settings.control_dt
    k0 = int(np.ceil(src.active_from / h))
    n = 1500  # 3 s of 2 ms ticks
    for k in range(k0, k0 + n):
        t = k * h
        src.observe(t, _quat(0.01, 0.06), np.zeros(3), (30.0, 30.0))
        src.targets(t)
    times = np.array([row[0] for row in src.g_trace])
    assert len(times) == pytest.approx(n * h / src.trace_dt, abs=1)
    assert np.allclose(np.diff(times), src.trace_dt, atol=1e-9)


@pytest.mark.slow
def test_walk_with_feedback_zeta1_does_not_fall(ctrl):
    from cpg_walker.experiments.cpg_walk import walk

    fb = FeedbackController(FeedbackConfig.load(), ("lateral", "pendulum", "reset"))
    m = walk(ctrl, 25.0, zeta=1.0, feedback=fb)
    assert m["feedback"] is True
    assert not m["fell"]
    assert m["phase_resets"] >= 5
    assert m["distance_m"] > 1.5


def test_side_step_soles_tilt_in_place_and_level_turning_or_on_longer_steps():
    """The side step's ankle-roll ratio: side_step_ankle_ratio (0: soles tilted with the legs) stepping in
    place at α 0.3 without a turn at a full amplitude; 1 (soles level) below side_step_tilt_from_rad, from
    |turn rate| side_step_level_turn_rad_s or from α side_step_level_alpha_to on, linear in between; bad
    values are refused with the field's name."""
    import dataclasses

    cfg = FeedbackConfig.load()
    fc = FeedbackController(cfg)
    lo, hi = cfg.side_step_level_alpha_from, cfg.side_step_level_alpha_to
    a0, a1 = cfg.side_step_tilt_from_rad, cfg.side_step_tilt_full_rad
    full = cfg.side_step_limit_rad
    assert a1 <= full
    assert fc.side_step_ankle_ratio(0.3, full) == fc.side_step_ankle_ratio(0.3, -a1) == 0.0
    assert fc.side_step_ankle_ratio(0.3, a0) == fc.side_step_ankle_ratio(0.3, -0.05) == 1.0
    assert fc.side_step_ankle_ratio(0.3, (a0 + a1) / 2) == pytest.approx(0.5)
    assert fc.side_step_ankle_ratio(hi, full) == fc.side_step_ankle_ratio(1.0, full) == 1.0
    assert fc.side_step_ankle_ratio((lo + hi) / 2, full) == pytest.approx(0.5)
    fc.turn_rate = -0.5 * cfg.side_step_level_turn_rad_s
    assert fc.side_step_ankle_ratio(0.3, full) == pytest.approx(0.5)
    fc.turn_rate = 2 * cfg.side_step_level_turn_rad_s
    assert fc.side_step_ankle_ratio(0.3, full) == 1.0
    for bad, field in (({"side_step_ankle_ratio": 1.5}, "side_step_ankle_ratio"),
                       ({"side_step_level_alpha_from": 0.5}, "side_step_level_alpha_from"),
                       ({"side_step_tilt_from_rad": 0.2}, "side_step_tilt_from_rad"),
                       ({"side_step_level_turn_rad_s": 0.0}, "side_step_level_turn_rad_s")):
        with pytest.raises(InputError, match=field):
            dataclasses.replace(cfg, **bad)
