"""Our feedback pathways (walker/feedback.py beyond the paper: amplitude, reset_both, heading, ankle,
free_leg), the run-time
API (observe with the IMU quaternion, weight, set_pathways, set_config, turn_rate) and config validation."""

import itertools
import math

import numpy as np
import pytest

from cpg_walker.cpg.hopf import phase as oscillator_phase
from cpg_walker.paths import config_path
from cpg_walker.robot.contact import TouchdownDetector
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.walker import storage
from cpg_walker.walker.controller import HumanoidCPG
from cpg_walker.walker.feedback import (
    ANKLE1,
    ANKLE2,
    HIP1,
    HIP2,
    HIP_YAW,
    KNEE,
    PAPER_PATHWAYS,
    PATHWAYS,
    RIGHT_HIP2,
    FeedbackConfig,
    FeedbackController,
    amplitude_factors,
    default_pathways,
    hip_yaw_offsets,
    phase_reset,
    touchdown_phase,
    yaw_from_quat,
)
from cpg_walker.walker.gait_source import CPGGaitSource, FeedbackGaitSource

UP = np.array([1.0, 0.0, 0.0, 0.0])  # upright, heading 0


def _yawed(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


@pytest.fixture(scope="module")
def learned() -> dict:
    return storage.to_dict(storage.load(config_path("cpg_humanoid.yaml")))


def _ctrl(learned: dict) -> HumanoidCPG:
    return storage.from_dict(learned)


# ----------------------------------------------------------------------------------------- amplitude
def test_amplitude_factors_grow_with_speed_only():
    cfg = FeedbackConfig.load(amp_slope_hip1=-0.6, amp_slope_hip2=-0.2, amp_slope_knee=0.4,
                              amp_slope_ankle1=0.0, amp_slope_ankle2=-0.6, amp_slow_slope_hip1=0.0,
                              amp_slow_slope_hip2=0.0, amp_slow_slope_knee=0.5, amp_slow_slope_ankle1=0.0,
                              amp_slow_slope_ankle2=0.0)
    assert np.array_equal(amplitude_factors(1.0, cfg), np.ones(10))
    slow = amplitude_factors(-0.6, cfg)  # below |ζ| = 1 only the slow slopes act
    assert np.allclose(slow[list(KNEE)], 1.2)
    slow[list(KNEE)] = 1.0
    assert np.array_equal(slow, np.ones(10))
    f = amplitude_factors(1.5, cfg)
    assert np.allclose(f[list(HIP1)], 0.7) and np.allclose(f[list(ANKLE2)], 0.7)
    assert np.allclose(f[list(HIP2)], 0.9) and np.allclose(f[list(KNEE)], 1.2)
    assert np.allclose(f[list(ANKLE1)], 1.0)
    assert np.array_equal(amplitude_factors(-1.5, cfg), f)  # backwards alike (|ζ|)
    assert np.all(amplitude_factors(10.0, cfg) >= 0)  # clipped at 0, never a sign flip


def test_amplitude_pathway_ramps_with_the_applied_zeta_and_keeps_the_phase(learned):
    """The factors follow the filtered ζ (no jump at the command), scale the α of the right CPGs, and
    leave every oscillator's phase exactly as the open loop has it."""
    cfg = FeedbackConfig.load()
    plain, fbc = _ctrl(learned), _ctrl(learned)
    fb = FeedbackController(cfg, ("amplitude",))
    h = plain.settings.control_dt
    for c in (plain, fbc):
        c.set_zeta(1.5)
    fbc.step(h)
    plain.step(h)
    first = fb.amplitude(fbc.zeta)
    assert np.max(np.abs(first - 1.0)) < 1e-3  # the command has not been applied yet: no jump
    for _ in range(3000):  # 6 s: ζ settled (3 lags of 0.25 s), α relaxed
        fbc.set_dof_amplitude_scale(fb.amplitude(fbc.zeta))
        fbc.step(h)
        plain.step(h)
    assert fbc.zeta == pytest.approx(1.5, abs=1e-5)
    ratio = fbc.net.state[3][:, 0] / plain.net.state[3][:, 0]
    assert np.allclose(ratio, amplitude_factors(1.5, cfg), rtol=1e-3)
    assert ratio[HIP1[0]] < 1.0 < ratio[KNEE[0]]
    assert np.allclose(fbc.net.phases(), plain.net.phases(), atol=1e-9)


# ----------------------------------------------------------------------------------------- resets
def test_reset_both_targets_per_foot_and_direction():
    cfg = FeedbackConfig.load(reset_both_strength=0.5, reset_phase_rad=-1.5, reset_phase_backward_rad=1.6)
    fb = FeedbackController(cfg, ("reset_both",))
    fb.touchdowns = (False, True)
    assert fb.reset_events(1.2) == [(-1.5, 0.5)]
    assert fb.reset_events(-1.0) == [(1.6, 0.5)]  # backwards: the backward touchdown phase
    fb.touchdowns = (True, False)  # left foot: half a cycle later
    (target, k), = fb.reset_events(1.0)
    assert target == pytest.approx(-1.5 + math.pi) and k == 0.5
    (target, _), = fb.reset_events(-1.0)
    assert target == pytest.approx(1.6 - math.pi)
    assert touchdown_phase(0.5, cfg) == -1.5 and touchdown_phase(-0.5, cfg) == 1.6
    paper = FeedbackController(cfg, ("reset",))  # the paper's: right foot only, its own phase/strength
    paper.touchdowns = (True, False)
    assert paper.reset_events(1.0) == []
    paper.touchdowns = (False, True)
    assert paper.reset_events(-1.0) == [(cfg.reset_phase_rad, cfg.reset_strength)]


def test_reset_both_is_held_off_below_its_zeta_and_alpha_gates():
    cfg = FeedbackConfig.load(reset_both_strength=0.5, reset_phase_rad=-1.5, reset_min_abs_zeta=0.75,
                              reset_min_alpha=0.75)
    fb = FeedbackController(cfg, ("reset_both",))
    fb.touchdowns = (False, True)
    assert fb.reset_events(1.0, 1.0) == [(-1.5, 0.5)]
    assert fb.reset_events(1.0, 0.75) == [(-1.5, 0.5)]  # at the gate: on
    assert fb.reset_events(1.0, 0.5) == []  # shorter steps
    assert fb.reset_events(0.5, 1.0) == []  # slow, or passing through ζ = 0
    assert fb.reset_events(-0.5, 1.0) == []


def test_left_reset_is_a_time_shift_that_keeps_relative_phases(learned):
    ctrl = _ctrl(learned)
    ctrl.reset_phase(0.4)
    s = ctrl.net.state[:2].copy()
    before = oscillator_phase(s[0], s[1])
    fb = FeedbackController(FeedbackConfig.load(reset_both_strength=0.6), ("reset_both",))
    fb.touchdowns = (True, False)
    (target, k), = fb.reset_events(1.0)
    err = (target - before[RIGHT_HIP2, 0] + math.pi) % (2 * math.pi) - math.pi
    d = phase_reset(s, ctrl.net.omega, target, strength=k)
    assert d == pytest.approx(0.6 * err)  # soft: κ of the wrapped error
    after = oscillator_phase(s[0], s[1])
    shift = np.angle(np.exp(1j * (after - before)))
    assert np.allclose(shift, np.angle(np.exp(1j * ctrl.net.omega / ctrl.net.omega[RIGHT_HIP2, 0] * d)))
    rel = np.angle(np.exp(1j * (after[:, 0] - after[RIGHT_HIP2, 0])))
    rel0 = np.angle(np.exp(1j * (before[:, 0] - before[RIGHT_HIP2, 0])))
    assert np.allclose(rel, rel0, atol=0.01)  # the legs stay half a cycle apart, the DOFs linked


def test_touchdown_detection_on_recorded_gait_loads():
    """The detector on the sole loads of a replay of the recorded walk: alternating feet, one touchdown
    per foot per recorded stride (2.51 s)."""
    from cpg_walker.robot.gait_data import GaitPlayback, find_steady_cycle, load_gait
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.loop import run_replay

    gait = load_gait("walk")
    cycle = find_steady_cycle(gait)
    r = run_replay(Hoap2Sim(), GaitPlayback(gait, cycle=cycle), PidLaw.from_config(), 14.0)
    det = TouchdownDetector()
    events = [(t, side) for t, loads in zip(r.t, r.loads, strict=True)
              for side, ev in zip(("left", "right"), det.update(float(t), tuple(loads)), strict=True) if ev]
    sides = [s for _, s in events]
    assert len(events) >= 6
    assert all(a != b for a, b in itertools.pairwise(sides))  # alternate
    late = [t for t, s in events if s == "right" and t > 7.0]
    assert np.allclose(np.diff(late), cycle.period, atol=0.1)


# ----------------------------------------------------------------------------------------- heading
def test_heading_error_sign_turn_rate_and_hip_yaw_pattern():
    cfg = FeedbackConfig.load(heading_gain=0.5, heading_limit_rad=0.2, heading_time_constant_s=0.0)
    fb = FeedbackController(cfg, ("heading",))
    fb.observe(0.0, UP, np.zeros(3), (30, 30))
    assert fb.heading_amplitude() == 0.0  # no reference yet
    fb.capture_heading()
    fb.observe(0.002, _yawed(-0.1), np.zeros(3), (30, 30))  # turned right of the reference
    assert fb.heading_error == pytest.approx(0.1)
    assert fb.heading_amplitude() == pytest.approx(0.05)  # > 0: turn left
    fb.observe(0.004, _yawed(-0.1 + 2 * math.pi), np.zeros(3), (30, 30))  # yaw is unwrapped
    assert fb.heading_error == pytest.approx(0.1)
    fb.set_turn_rate(0.5)
    fb.observe(1.004, _yawed(-0.1), np.zeros(3), (30, 30))
    assert fb.heading_ref == pytest.approx(0.5)  # the reference turns at turn_rate
    assert fb.heading_amplitude() == pytest.approx(0.2)  # clipped
    assert yaw_from_quat(_yawed(0.3)) == pytest.approx(0.3)
    # the hip-yaw pattern: right hip +u at right touchdown, the left opposite; q̇ is dq/dθ·θ̇
    q, qd = hip_yaw_offsets(0.05, -1.5, -1.5, 2.5)
    assert q == pytest.approx([-0.05, 0.05]) and qd == pytest.approx([0.0, 0.0])
    q1, _ = hip_yaw_offsets(0.05, -1.5 + 1e-6, -1.5, 2.5)
    _, qd2 = hip_yaw_offsets(0.05, -1.5 + 0.3, -1.5, 2.5)
    q3, _ = hip_yaw_offsets(0.05, -1.5 + 0.3 + 1e-6, -1.5, 2.5)
    q2, _ = hip_yaw_offsets(0.05, -1.5 + 0.3, -1.5, 2.5)
    assert qd2 == pytest.approx((q3 - q2) / 1e-6 * 2.5, rel=1e-4)
    assert q1[1] < q[1] + 1e-12


def test_heading_pathway_drives_only_the_hip_yaws(learned):
    """With a held positive u the source adds the hip-yaw pattern to the open-loop targets and nothing
    else."""
    ctrl_a, ctrl_b = _ctrl(learned), _ctrl(learned)
    fb = FeedbackController(FeedbackConfig.load(heading_time_constant_s=0.0), ("heading",))
    src = FeedbackGaitSource(ctrl_a, fb)
    ref = CPGGaitSource(ctrl_b)
    h = ctrl_a.settings.control_dt
    k0 = int(np.ceil(src.active_from / h))
    yaw_idx = [JOINT_NAMES.index(j) for j in HIP_YAW]
    moved = 0.0
    for k in range(k0, k0 + 200):
        t = k * h
        src.observe(t, UP if k == k0 else _yawed(-0.2), np.zeros(3), (30, 30))
        q, _ = src.targets(t)
        q0, _ = ref.targets(t)
        others = np.ones(len(JOINT_NAMES), bool)
        others[yaw_idx] = False
        assert np.array_equal(q[others], q0[others])
        d = q[yaw_idx] - q0[yaw_idx]
        assert d[0] == pytest.approx(-d[1])  # antisymmetric
        moved = max(moved, abs(d[1]))
    assert moved > 0.01


@pytest.mark.parametrize("where", ["handover", "start"])
def test_heading_reference_is_captured_at_the_handover_or_the_start(learned, where):
    fb = FeedbackController(FeedbackConfig.load(heading_reference=where), ("heading",))
    src = FeedbackGaitSource(_ctrl(learned), fb)
    src.observe(0.0, _yawed(0.2), np.zeros(3), (30, 30))
    src.targets(0.0)
    assert (fb.heading_ref is None) == (where == "handover")
    src.observe(src.active_from, _yawed(0.3), np.zeros(3), (30, 30))
    assert fb.heading_ref == pytest.approx(0.3 if where == "handover" else 0.2)


@pytest.mark.slow
def test_held_positive_hip_yaw_amplitude_turns_left(learned):
    """Physics check of the heading sign: u > 0 turns the walking robot counter-clockwise (left)."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker.loop import run_replay

    turned = {}
    for u in (0.05, -0.05):
        fb = FeedbackController(FeedbackConfig.load(), ("heading",))
        fb.heading_amplitude = lambda stride_s=0.0, alpha=1.0, u=u: u  # held amplitude, no loop
        src = FeedbackGaitSource(_ctrl(learned), fb)
        r = run_replay(Hoap2Sim(), src, PidLaw.from_config(), src.active_from + 6.0)
        i0 = int(np.searchsorted(r.t, src.active_from))
        turned[u] = math.degrees(r.heading[-1] - r.heading[i0])
    assert turned[0.05] > 10.0 and turned[-0.05] < -10.0, turned


# ----------------------------------------------------------------------------------------- weight, API
def _drive(src, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Feed a source synthetic sensor data (tilt, yaw, touchdowns every 0.6 s) and collect its targets."""
    h = src.ctrl.settings.control_dt
    out = []
    for k in range(n):
        t = k * h
        if hasattr(src, "observe"):
            roll, pitch, yaw = 0.05 * math.sin(2.5 * t), 0.06 + 0.02 * math.sin(5 * t), 0.1 * math.sin(t)
            cr, sr, cp, sp, cy, sy = (math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2),
                                      math.sin(pitch / 2), math.cos(yaw / 2), math.sin(yaw / 2))
            q = np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                          cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])
            phase_ = (t % 1.2) / 1.2
            loads = (40.0 if phase_ < 0.5 else 0.0, 0.0 if phase_ < 0.5 else 40.0)
            src.observe(t, q, rng.normal(size=3), loads)
        q_t, qd_t = src.targets(t)
        out.append(np.concatenate([q_t, qd_t]))
    return out


def test_weight_zero_is_the_open_loop_bit_for_bit(learned):
    kw = dict(zeta=1.0, schedule=[(2.5, 1.5, 1.0)], handover_s=1.0)  # feedback active from 2 s
    open_loop = _drive(CPGGaitSource(_ctrl(learned), **kw), 2500, np.random.default_rng(0))
    every = ("lateral", "pendulum", "amplitude", "reset_both", "heading")
    fb = FeedbackController(FeedbackConfig.load(), every)
    fb.weight = 0.0
    closed = _drive(FeedbackGaitSource(_ctrl(learned), fb, **kw), 2500, np.random.default_rng(0))
    assert all(np.array_equal(a, b) for a, b in zip(open_loop, closed, strict=True))
    fb1 = FeedbackController(FeedbackConfig.load(), every)
    full = _drive(FeedbackGaitSource(_ctrl(learned), fb1, **kw), 2500, np.random.default_rng(0))
    assert not np.array_equal(open_loop[-1], full[-1])  # the same drive with weight 1 does act
    assert len(fb1.resets) > 0


def test_run_time_api_validates(learned):
    fb = FeedbackController(FeedbackConfig.load())
    assert fb.pathways == default_pathways()
    assert set(PAPER_PATHWAYS) < set(PATHWAYS)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="weight"):
            fb.weight = bad
    with pytest.raises(ValueError, match="reset_both"):
        fb.set_pathways(["reset", "reset_both"])
    with pytest.raises(ValueError, match="unknown feedback pathway"):
        fb.set_pathways(["heading", "vision"])
    with pytest.raises(ValueError, match="list of names"):
        fb.set_pathways("heading")
    fb.set_pathways(["heading"])
    assert fb.pathways == ("heading",)
    with pytest.raises(ValueError, match="turn_rate"):
        fb.set_turn_rate(float("inf"))
    with pytest.raises(ValueError, match="quat"):
        fb.observe(0.0, np.array([0.0, 0.0, 0.0, 0.0]), np.zeros(3), (0, 0))
    fb.set_config(FeedbackConfig.load(heading_time_constant_s=0.5))
    assert fb.cfg.heading_time_constant_s == 0.5 and fb._herr.T == 0.5


@pytest.mark.parametrize("field,value", [
    ("reset_both_strength", 0.0), ("reset_both_strength", 1.2), ("heading_gain", -1.0),
    ("heading_limit_rad", 0.8), ("amp_slope_knee", float("nan")), ("amp_slope_hip1", 3.0),
    ("amp_slow_slope_knee", -2.5),
    ("reset_phase_backward_rad", 4.0), ("tilt_time_constant_s", -0.1), ("gain_scale", "x"),
    ("lateral_sign", 0.5), ("reset_strength", 0.0), ("heading_reference", "north"),
    ("reset_min_abs_zeta", -1.0), ("reset_min_alpha", -0.1), ("free_leg_gain", -1.0),
    ("free_leg_limit_rad", 0.8), ("free_leg_max_alpha", 0.0), ("free_leg_unloaded_n", -5.0),
])
def test_bad_config_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        FeedbackConfig.load(**{field: value})


def test_default_pathways_come_from_the_yaml(tmp_path):
    import yaml

    d = yaml.safe_load(open(config_path("feedback.yaml"), encoding="utf-8"))
    assert default_pathways() == tuple(d["pathways"])
    d["pathways"] = ["reset", "reset_both"]
    bad = tmp_path / "fb.yaml"
    bad.write_text(yaml.safe_dump(d))
    with pytest.raises(ValueError, match="reset_both"):
        default_pathways(str(bad))
    assert FeedbackConfig.load(str(bad)).heading_gain == d["heading_gain"]  # the list is not a field


def test_forecast_carries_the_dof_amplitude_factors(learned):
    """HumanoidCPG.forecast while α is being reached applies the per-DOF factors as stepping does."""
    ctrl = _ctrl(learned)
    h = ctrl.settings.control_dt
    ctrl.set_dof_amplitude_scale(np.linspace(0.7, 1.2, 10))
    for _ in range(500):
        ctrl.step(h)
    ctrl.set_alpha(0.8)
    ctrl.step(h)
    offsets = np.array([0.04, 0.1, 0.2])
    q, _ = ctrl.forecast(offsets)
    steps_done, rows = 0, []
    for n in np.rint(offsets / h).astype(int):
        for _ in range(n - steps_done):
            ctrl.step(h)
        steps_done = n
        rows.append(ctrl.joint_targets()[0])
    assert np.abs(q - np.array(rows)).max() < 2e-3


def test_forecast_includes_the_hip_yaw_oscillation(learned):
    fb = FeedbackController(FeedbackConfig.load(heading_time_constant_s=0.0), ("heading",))
    src = FeedbackGaitSource(_ctrl(learned), fb)
    h = src.ctrl.settings.control_dt
    k0 = int(np.ceil(src.active_from / h))
    src.observe(k0 * h, UP, np.zeros(3), (30, 30))
    src.observe((k0 + 1) * h, _yawed(-0.2), np.zeros(3), (30, 30))
    src.targets((k0 + 1) * h)
    times = (k0 + 1) * h + np.array([0.02, 0.1, 0.3])
    q, _ = src.forecast(times)
    yaw_idx = [JOINT_NAMES.index(j) for j in HIP_YAW]
    exact = []
    for t in times:  # the same held u: no new observation changes it
        exact.append(src.targets(t)[0][yaw_idx])
    assert np.abs(q[:, yaw_idx] - np.array(exact)).max() < 2e-3
    assert np.abs(np.array(exact)).max() > 0.01


def test_the_ankle_pathway_acts_only_on_fresh_samples():
    """ankle: offsets from the tilt and rate (clipped); samples older than ankle_max_sample_age_s fade it
    out over ankle_fade_s, fresh ones back in; age 0 (in-process, lockstep) never fades it."""
    cfg = FeedbackConfig.load()
    fb = FeedbackController(cfg, ("ankle",))
    lean = np.array([math.cos(0.1), 0.0, math.sin(0.1), 0.0])  # 0.2 rad forward pitch (w, x, y, z)
    dt = 0.002

    def tick(k: int, age: float) -> tuple[float, float]:
        fb.observe(k * dt, lean, np.array([0.3, 0.1, 0.0]), (30.0, 30.0), age)
        return fb.ankle_offsets()

    fresh = [tick(k, 0.0) for k in range(50)][-1]
    pitch = cfg.ankle_pitch_gain * fb.psi[1] + cfg.ankle_pitch_rate_gain * 0.1
    roll = cfg.ankle_roll_gain * fb.psi[0] + cfg.ankle_roll_rate_gain * 0.3
    assert fresh == pytest.approx((np.clip(pitch, -cfg.ankle_limit_rad, cfg.ankle_limit_rad),
                                   np.clip(roll, -cfg.ankle_limit_rad, cfg.ankle_limit_rad)))
    assert fb.ankle_fresh == 1.0 and abs(fresh[0]) > 0.01
    stale = cfg.ankle_max_sample_age_s * 2
    n = round(cfg.ankle_fade_s / dt)
    half = [tick(50 + k, stale) for k in range(n // 2)][-1]
    assert 0.0 < fb.ankle_fresh < 1.0 and abs(half[0]) < abs(fresh[0])
    gone = [tick(50 + n // 2 + k, stale) for k in range(n)][-1]
    assert fb.ankle_fresh == 0.0 and gone == (0.0, 0.0)
    back = [tick(50 + 2 * n + k, cfg.ankle_max_sample_age_s) for k in range(n + 1)][-1]
    assert fb.ankle_fresh == 1.0 and back == pytest.approx(fresh)


def _rolled(roll: float) -> np.ndarray:
    return np.array([math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0])  # about the forward (x) axis


def test_the_free_leg_pathway_swings_the_unloaded_upper_leg_out_while_standing():
    """free_leg: past the tilt threshold, with the upper sole off the ground, both hip rolls turn outward
    (the free leg by free_leg_gain, the stance leg by free_leg_stance_gain per rad beyond the threshold,
    each clipped); mirrored for the other side; nothing in double support, with the lower foot lifted,
    below the threshold, or at α >= free_leg_max_alpha (half at half of it)."""
    cfg = FeedbackConfig.load(tilt_time_constant_s=0.0)
    fb = FeedbackController(cfg, ("free_leg",))
    tilt = cfg.free_leg_threshold_rad + 0.05

    def offsets(roll: float, loads: tuple[float, float], alpha: float = 0.0) -> tuple[float, float]:
        fb.observe(0.0, _rolled(roll), np.zeros(3), loads)
        return fb.free_leg_offsets(alpha)

    free = min(cfg.free_leg_gain * 0.05, cfg.free_leg_limit_rad)
    stance = min(cfg.free_leg_stance_gain * 0.05, cfg.free_leg_limit_rad)
    assert fb.psi[0] == 0.0 and free > 0.0 and stance > 0.0
    # tilted right (ψ_lat > 0): the left foot is the upper one; outward = +roll left, -roll right
    assert offsets(tilt, (0.0, 70.0)) == pytest.approx((free, -stance))
    assert fb.psi[0] == pytest.approx(tilt)
    assert offsets(-tilt, (70.0, 0.0)) == pytest.approx((stance, -free))
    assert offsets(tilt, (30.0, 40.0)) == (0.0, 0.0)  # double support
    assert offsets(tilt, (70.0, 0.0)) == (0.0, 0.0)  # the lower foot lifted: not a fall over the edge
    assert offsets(cfg.free_leg_threshold_rad - 0.005, (0.0, 70.0)) == (0.0, 0.0)
    assert offsets(tilt, (0.0, 70.0), cfg.free_leg_max_alpha) == (0.0, 0.0)  # walking
    assert offsets(tilt, (0.0, 70.0), cfg.free_leg_max_alpha / 2) == pytest.approx((free / 2, -stance / 2))
    assert offsets(1.0, (0.0, 70.0))[0] == pytest.approx(cfg.free_leg_limit_rad)
    fb.weight = 0.0
    assert offsets(tilt, (0.0, 70.0)) == (0.0, 0.0)
    assert FeedbackController(cfg, ("ankle",)).free_leg_offsets(0.0) == (0.0, 0.0)


def test_the_free_leg_offsets_reach_the_hip_roll_targets(learned):
    """Two standing sources tilted alike, one with its upper sole off the ground: their targets differ by
    the free_leg offsets, on the hip rolls only; the forecast carries them."""
    def source() -> FeedbackGaitSource:
        fb = FeedbackController(FeedbackConfig.load(tilt_time_constant_s=0.0), ("free_leg",))
        return FeedbackGaitSource(_ctrl(learned), fb, alpha=0.0)

    lifted, planted = source(), source()
    h = lifted.ctrl.settings.control_dt
    t = np.ceil(lifted.active_from / h) * h
    while lifted.ctrl.alpha > 1e-3 and t < lifted.active_from + 20.0:  # the recording's steps ending
        for src in (lifted, planted):
            src.observe(t, UP, np.zeros(3), (35.0, 35.0))
            src.targets(t)
        t += h
    for src, loads in ((lifted, (0.0, 70.0)), (planted, (35.0, 35.0))):
        src.observe(t, _rolled(0.1), np.zeros(3), loads)
    assert lifted.ctrl.alpha < lifted.fb.cfg.free_leg_max_alpha
    want = lifted.fb.free_leg_offsets(lifted.ctrl.alpha)
    assert want[0] > 0.01 and want[1] < -0.01 and planted.fb.free_leg_offsets(0.0) == (0.0, 0.0)
    diff = lifted.targets(t)[0] - planted.targets(t)[0]
    roll_idx = [JOINT_NAMES.index(f"{s}leg_joint_2") for s in "lr"]
    assert diff[roll_idx] == pytest.approx(want)
    assert np.abs(np.delete(diff, roll_idx)).max() == 0.0
    ahead = lifted.forecast(np.array([t]))[0][0] - planted.forecast(np.array([t]))[0][0]
    assert ahead[roll_idx] == pytest.approx(want)
