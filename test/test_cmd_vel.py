"""/cmd_vel's pure core (walker/cmd_vel.py): the speed map's inverse and its monotone fit, the limits, the
follower's states (following, standing, timeout and resume, reversal through α = 0), bad input, and the
heading anti-windup of the feedback controller."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

from cpg_walker.walker.cmd_vel import (
    REVERSE_ALPHA,
    REVERSE_ALPHA_RATE,
    CmdVelFollower,
    CmdVelLimits,
    CmdVelOutput,
    SpeedMap,
    apply_output,
    check_twist,
    monotone,
)
from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController


def limits(**kw) -> CmdVelLimits:
    base = {"timeout": 0.5, "max_linear_x": 0.11, "min_linear_x": -0.1, "max_angular_z": 0.15,
            "stand_below": 0.005, "alpha_fall_rate": 1000.0,  # 1000: α drops within a tick
            "angular_z_rate": 1000.0, "angular_z_rate_in_place": 1000.0, "max_linear_y": 0.05,
            "steer_alpha": 0.3, "turn_alpha": 0.25}
    return CmdVelLimits(**{**base, **kw})


def toy_map(**over) -> dict:
    d = {"slow_abs_zeta": 1.0,
         "forward": {"zeta_speed": [[0.7, 0.05], [1.0, 0.08], [1.2, 0.1], [1.4, 0.095], [1.5, 0.11]],
                     "alpha_speed": [[0.4, 0.03], [0.8, 0.065]]},
         "backward": {"zeta_speed": [[-1.0, -0.09], [-1.5, -0.105]],
                      "alpha_speed": [[0.5, -0.04]]}}
    d.update(over)
    return d


def test_packaged_map_inverse_round_trips_and_is_monotone():
    """config/speed_map.yaml: the inverse of the map's own speeds gives back (ζ, α); |v| at or above the
    ζ = 1 speed is reached through ζ at α 1 up to the fastest such ζ, past it through the fast nodes (α > 1,
    the ankle pathway's), below it through α at ζ 1; ζ and α rise with |v|."""
    m = SpeedMap.load()
    lim = CmdVelLimits.load()
    for branch, sign in ((m.forward, 1.0), (m.backward, -1.0)):
        for c, v in zip(branch.c, branch.speed, strict=True):
            z, a = m.inverse(sign * v)
            assert (z, a) == pytest.approx(branch.modulation(c))
            assert m.speed(z, a) == pytest.approx(sign * v)
        vs = np.linspace(branch.v_min, branch.v_max, 200)
        za = np.array([m.inverse(sign * v) for v in vs])
        assert np.all(np.diff(np.abs(za[:, 0])) >= -1e-12) and np.all(np.diff(za[:, 1]) >= -1e-12)
        assert np.all(np.sign(za[:, 0]) == sign)
        quick = vs >= branch.speed[list(branch.c).index(1.0)]
        longer = vs > branch.v_plain + 1e-12
        assert np.all(za[quick & ~longer, 1] == 1.0) and np.all(np.abs(za[~quick, 0]) == 1.0)
        assert len(branch.fast) and np.all(za[longer, 1] > 1.0)
        assert np.abs(za[-1]) == pytest.approx(branch.fast[-1])  # the fastest node
    # the limits are what the map reaches (forward: below it, beyond the speeds without the ankle pathway)
    assert m.forward.v_plain < lim.max_linear_x <= m.v_max
    assert lim.min_linear_x == pytest.approx(m.v_min, abs=1e-3)


def test_map_clamps_and_stands():
    m = SpeedMap(toy_map())
    lim = limits()
    assert m.command(0.5, lim) == m.inverse(0.11) == pytest.approx((1.5, 1.0))  # above max: the fastest
    assert m.command(-0.5, lim) == pytest.approx(m.inverse(-0.1))  # min_linear_x
    assert m.inverse(0.001) == pytest.approx((1.0, 0.4))  # below the slowest walk: the slowest walk
    assert m.command(0.004, lim) == (1.0, 0.0)  # below stand_below: stand
    assert m.command(-0.004, lim) == (-1.0, 0.0)
    assert m.command(0.0, lim)[1] == 0.0
    assert m.inverse(0.08) == pytest.approx((1.0, 1.0))  # the two branches meet at ζ 1, α 1
    assert m.inverse(0.0799)[0] == 1.0 and m.inverse(0.0799)[1] == pytest.approx(1.0, abs=0.01)
    assert m.inverse(-0.04) == pytest.approx((-1.0, 0.5))


def test_noisy_points_are_pooled_into_a_monotone_map():
    """ζ 1.4 measured slower than 1.2: pooled (mean ζ 1.3, mean speed); ζ below slow_abs_zeta unused."""
    x, y = monotone(np.array([1.0, 1.2, 1.4, 1.5]), np.array([0.08, 0.1, 0.095, 0.11]))
    assert x.tolist() == pytest.approx([1.0, 1.3, 1.5]) and y.tolist() == pytest.approx([0.08, 0.0975, 0.11])
    m = SpeedMap(toy_map())
    assert m.forward.c.tolist() == pytest.approx([0.4, 0.8, 1.0, 1.3, 1.5])
    assert np.all(np.diff(m.forward.speed) > 0)


@pytest.mark.parametrize("change, why", [
    ({"forward": {"zeta_speed": [[1.0, 0.08]], "alpha_speed": [[0.5, -0.04]]}}, "forward.alpha_speed"),
    ({"backward": {"zeta_speed": [[-1.0, 0.09]], "alpha_speed": [[0.5, -0.04]]}}, "backward.zeta_speed"),
    ({"forward": {"zeta_speed": [[1.2, 0.1]], "alpha_speed": [[0.5, 0.04]]}}, "zeta = 1"),
    ({"forward": {"zeta_speed": [[1.0, math.nan]], "alpha_speed": [[0.5, 0.04]]}}, "finite"),
    ({"forward": {"zeta_speed": "fast", "alpha_speed": [[0.5, 0.04]]}}, "zeta_speed"),
    ({"forward": None}, "forward: missing"),
    ({"slow_abs_zeta": 3.0}, "slow_abs_zeta"),
])
def test_bad_map_data_is_refused_naming_the_key(change, why):
    with pytest.raises(ValueError, match=why):
        SpeedMap(toy_map(**change), "map.yaml")


def test_limits_are_validated():
    for kw, why in (({"timeout": 0.0}, "timeout"), ({"timeout": math.nan}, "finite"),
                    ({"max_linear_x": -0.1}, "max_linear_x"), ({"min_linear_x": 0.1}, "min_linear_x"),
                    ({"max_angular_z": 2.0}, "max_angular_z"), ({"stand_below": -1.0}, "stand_below"),
                    ({"alpha_fall_rate": 0.0}, "alpha_fall_rate")):
        with pytest.raises(ValueError, match=why):
            limits(**kw)
    lim = limits()
    assert lim.clamp_angular(1.0) == 0.15 and lim.clamp_angular(-1.0) == -0.15
    assert lim.clamp_linear(0.05) == 0.05


def test_follower_follows_times_out_and_resumes():
    m = SpeedMap(toy_map())
    f = CmdVelFollower(m, limits(), zeta=1.0)
    assert f.update(0.0, 1.0, 1.0) is None and f.state == "waiting"  # nothing before the first message
    f.command(10.0, 0.1, 0.05)
    out = f.update(10.002, 1.0, 1.0)
    assert out == CmdVelOutput(m.inverse(0.1)[0], 1.0, 0.05, "following")
    assert f.update(10.5, 1.1, 1.0).state == "following"  # exactly the timeout: still following
    out = f.update(10.502, 1.1, 1.0)
    assert out == CmdVelOutput(m.inverse(0.1)[0], 0.0, 0.0, "timed_out")  # stop stepping, keep ζ
    f.command(12.0, 0.03, 0.0)  # resumes (same direction: no reversal)
    out = f.update(12.002, 1.2, 0.1)
    assert out.state == "following" and out == CmdVelOutput(1.0, pytest.approx(0.4), 0.0, "following")
    f.command(12.1, 0.0, 0.0)  # zero speed: stand, keep the direction
    assert f.update(12.102, 1.0, 0.4) == CmdVelOutput(1.0, 0.0, 0.0, "standing")
    f.command(12.15, 0.0, 0.1)  # zero speed, a turn: step in place at (steer_zeta, turn_alpha)
    assert f.update(12.152, 1.0, 0.0) == CmdVelOutput(1.5, 0.25, 0.1, "stepping in place")
    f.command(12.2, 0.2, 1.0)  # clamped to the limits
    assert f.update(12.202, 1.0, 0.0) == CmdVelOutput(1.5, 1.0, 0.15, "following")


def test_alpha_command_falls_at_most_alpha_fall_rate():
    """A stop (timeout, standing, a slower command) lowers the α command linearly at
    ``alpha_fall_rate`` per sim s, whatever the tick spacing; a rise is not limited by it; a new
    command during the fall takes over from where the α command is."""
    m = SpeedMap(toy_map())
    f = CmdVelFollower(m, limits(alpha_fall_rate=0.5), zeta=1.0)
    f.command(10.0, 0.08, 0.0)
    assert f.update(10.002, 1.0, 1.0).alpha == 1.0
    t, a = 11.6, []  # timed out from 10.5 on: the α command is 1 until then, then falls 0.5 / s
    while t < 14.0:
        a.append((t, f.update(t, 1.0, 1.0).alpha))
        t += 0.013
    assert f.state == "timed_out"
    for (t0, a0), (t1, a1) in itertools.pairwise(a):
        assert a1 == pytest.approx(max(a0 - 0.5 * (t1 - t0), 0.0))
    assert a[0][1] == pytest.approx(1.0 - 0.5 * (11.6 - 10.002)) and a[-1][1] == 0.0
    f.command(14.0, 0.1, 0.0)  # resumes: α up at once (rises are not limited by this)
    assert f.update(14.002, 1.0, 0.0).alpha == 1.0
    slow = m.command(0.04, f.limits)[1]
    assert 0.3 < slow < 0.7
    f.command(14.1, 0.04, 0.0)  # slower: α 1 -> slow at 0.5 / s
    assert f.update(14.5, 1.0, 1.0).alpha == pytest.approx(1.0 - 0.5 * 0.498)
    f.command(15.5, 0.04, 0.0)
    assert f.update(15.6, 1.0, 1.0).alpha == pytest.approx(slow)


def test_reversal_stops_stepping_before_the_zeta_sign_flips():
    """Forward -> backward: α 0 with the old ζ until the applied α < REVERSE_ALPHA, then the new ζ with α 0
    until the applied ζ is near it, then step with α rising at REVERSE_ALPHA_RATE; no ζ of the new sign
    is commanded while α is applied."""
    m = SpeedMap(toy_map())
    f = CmdVelFollower(m, limits(), zeta=1.0)
    f.command(0.0, 0.08, 0.0)
    assert f.update(0.0, 1.0, 1.0).state == "following"
    f.command(1.0, -0.09, 0.1)
    assert f.update(1.0, 1.0, 1.0) == CmdVelOutput(1.0, 0.0, 0.0, "reversing")
    f.command(1.4, -0.09, 0.1)
    assert f.update(1.4, 1.0, 2 * REVERSE_ALPHA) == CmdVelOutput(1.0, 0.0, 0.0, "reversing")
    assert f.update(1.41, 1.0, REVERSE_ALPHA / 2) == CmdVelOutput(-1.0, 0.0, 0.0, "reversing")
    assert f.update(1.42, 0.2, 0.01) == CmdVelOutput(-1.0, 0.0, 0.0, "reversing")  # ζ still on its way
    out = f.update(1.43, -0.95, 0.01)  # stepping again, α rising at REVERSE_ALPHA_RATE per sim s
    assert out == CmdVelOutput(-1.0, pytest.approx(REVERSE_ALPHA_RATE * 0.01), 0.1, "ramping")
    t, alphas = 1.43, []
    while out.state == "ramping":
        t += 0.01
        f.command(t, -0.09, 0.1)
        out = f.update(t, -1.0, out.alpha)
        alphas.append(out.alpha)
    assert out == CmdVelOutput(-1.0, 1.0, 0.1, "following")
    assert t - 1.43 == pytest.approx(1.0 / REVERSE_ALPHA_RATE, abs=0.02)
    assert np.all(np.diff(alphas[:-1]) == pytest.approx(REVERSE_ALPHA_RATE * 0.01))
    # from standing (α already 0): the swap is immediate, then the wait for ζ
    f.command(1.5, 0.0, 0.0)
    f.update(1.5, -1.0, 1.0)
    f.command(1.9, 0.05, 0.0)
    assert f.update(1.9, -1.0, 0.0) == CmdVelOutput(1.0, 0.0, 0.0, "reversing")


def test_bad_twists_are_refused_and_change_nothing():
    f = CmdVelFollower(SpeedMap(toy_map()), limits())
    f.command(0.0, 0.08, 0.0)
    before = f.update(0.1, 1.0, 1.0)
    for vx, wz, why in ((math.nan, 0.0, "linear.x"), (0.05, math.inf, "angular.z"),
                        (-math.inf, 0, "linear.x")):
        with pytest.raises(ValueError, match=why):
            f.command(0.2, vx, wz)
    assert f.last == (0.0, 0.08, 0.0) and f.update(0.3, 1.0, 1.0) == before
    with pytest.raises(ValueError, match=r"linear\.z or angular\.x/y"):
        check_twist(0.0, 0.0, (math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"linear\.y"):
        f.command(0.2, 0.05, 0.0, math.nan)
    assert f.last == (0.0, 0.08, 0.0)


class FakeCPG:
    def __init__(self):
        self.zeta_command, self.alpha_command = 1.0, 1.0

    def set_zeta(self, z):
        self.zeta_command = z

    def set_alpha(self, a):
        self.alpha_command = a


class FakeSource:
    """A gait source's command interface (``ctrl``, ``fb``, ``command``) around FakeCPG."""

    def __init__(self, fb):
        self.ctrl, self.fb = FakeCPG(), fb

    def command(self, z, a):
        self.ctrl.set_zeta(z)
        self.ctrl.set_alpha(a)
        return False


def _quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def test_heading_anti_windup_and_hold():
    """A robot that cannot follow the commanded turn (yaw held at 0): the reference stays within the
    error that saturates the hip-yaw amplitude; once the turn command is 0 the walked heading becomes
    the reference and u decays to 0 (the robot holds its heading), never turning on."""
    cfg = FeedbackConfig.load()
    fb = FeedbackController(cfg, ("heading",))
    src = FakeSource(fb)
    window = cfg.heading_limit_rad / cfg.heading_gain
    dt = 0.01
    t = 0.0
    fb.observe(t, _quat(0.0), np.zeros(3), (10.0, 10.0))
    fb.capture_heading()
    apply_output(src, CmdVelOutput(1.0, 1.0, 0.5, "following"))
    for _ in range(1000):  # 10 s at 0.5 rad/s: 5 rad unbounded
        t += dt
        fb.observe(t, _quat(0.0), np.zeros(3), (10.0, 10.0))
    assert fb.heading_ref == pytest.approx(window)
    assert abs(fb.heading_amplitude()) == pytest.approx(cfg.heading_limit_rad, rel=1e-3)  # saturated
    apply_output(src, CmdVelOutput(1.0, 1.0, 0.0, "following"))
    assert fb.turn_rate == 0.0
    u = []
    for _ in range(800):
        t += dt
        fb.observe(t, _quat(0.0), np.zeros(3), (10.0, 10.0))
        u.append(fb.heading_amplitude())
    u = np.abs(np.array(u))
    assert np.all(np.diff(u) <= 1e-12) and u[-1] < 0.01 * cfg.heading_limit_rad
    assert abs(fb.heading_ref) < 0.01 * window  # the walked heading (yaw 0), not the wound-up reference
    # without anti-windup the same command winds the reference up without bound
    free = FeedbackController(cfg, ("heading",))
    free.observe(0.0, _quat(0.0), np.zeros(3), (10.0, 10.0))
    free.capture_heading()
    free.set_turn_rate(0.5)
    for k in range(1, 1001):
        free.observe(k * dt, _quat(0.0), np.zeros(3), (10.0, 10.0))
    assert free.heading_ref == pytest.approx(5.0, rel=1e-6)


def test_a_twist_drives_the_in_process_robot_and_the_timeout_stops_it():
    """The follower as cpg_node applies it, on the simulated robot (experiments/cmd_vel.py run_drive):
    0.06 m/s with a 0.1 rad/s left turn from 10 s; the speed over 14.8-22 s is the command within 10 %,
    the robot turns left at the commanded rate within 10 % (0.106 rad/s measured: the turn's feedforward
    with the heading pathway's closed loop; 0.069 before the feedforward), and
    after the last Twist (22 s) the timeout stops it: the base moves < 1 cm/s
    within the packaged timeout + the α fall (1 / alpha_fall_rate) + 2 s (the α filter) and stays
    upright."""
    from cpg_walker.experiments.cmd_vel import Drive, run_drive

    m = run_drive(Drive("t", ((22.0, 0.06, 0.1),), tail_s=5.0))
    assert not m["fell"], m
    (seg,) = m["segments"]
    assert seg["speed_mps"] == pytest.approx(0.06, rel=0.1), seg
    # 0.106 rad/s measured for the 0.1 commanded (in-process: deterministic), within the headline walks'
    # 10 % (experiments/headline.py MARGINS)
    assert seg["turn_rate_rad_s"] == pytest.approx(0.1, rel=0.1), seg
    stop = m["speed_below_1cm_s_after_s"]
    lim = CmdVelLimits.load()
    assert stop is not None and lim.timeout < stop <= lim.timeout + 1.0 / lim.alpha_fall_rate + 2.0, m


def test_packaged_timeout_keeps_following_a_one_hertz_sender():
    """`ros2 topic pub` (and `cpg-walker topic pub`) send 1 Hz by default: with the packaged timeout a
    Twist every 1.1 s (1 Hz, late by 10 %) keeps the robot following, never timed out (with
    diff_drive's 0.5 s it stopped and restarted every second and fell in the graph); 0.1 s after the
    timeout without a Twist it stops stepping."""
    lim = CmdVelLimits.load()
    f = CmdVelFollower(SpeedMap.load(), lim, zeta=1.0)
    t = 10.0
    for _ in range(10):
        f.command(t, 0.085, 0.1)
        for dt in (0.002, 0.5, 1.098):
            assert f.update(t + dt, 1.0, 1.0).state == "following", (t, dt)
        t += 1.1
    assert f.update(t - 1.1 + lim.timeout + 0.1, 1.0, 1.0).state == "timed_out"


def test_steering_steps_in_place_or_faster_and_slews_the_turn():
    """linear.x ~ 0 with a turn steps in place at (±steer_zeta, turn_alpha) in the walking direction, with
    a linear.y at (+steer_zeta, steer_alpha) (forward steps); a turn faster than GENTLE_TURN (or a side
    step) while walking steps at steer_zeta with the α that keeps the speed (``SpeedMap.alpha_at``);
    gentler turns keep the map's (ζ, α); linear.y is clamped to max_linear_y; the turn output moves at most
    angular_z_rate_in_place per sim s in place, angular_z_rate otherwise."""
    from cpg_walker.walker.cmd_vel import GENTLE_TURN

    m = SpeedMap(toy_map())
    f = CmdVelFollower(m, limits(), zeta=-1.0)
    f.command(0.0, 0.0, 0.4)
    assert f.target == (-1.5, 0.25, 0.15)  # backward walker: in place at ζ -1.5; turn clamped to 0.15
    f.command(0.05, 0.0, 0.4, 0.02)
    assert f.target == (1.5, 0.3, 0.15) and f.target_y == 0.02  # and a side step: forward, steer_alpha
    f = CmdVelFollower(m, limits(max_angular_z=0.5), zeta=1.0)
    f.command(0.0, 0.08, GENTLE_TURN)
    assert f.target == (*m.command(0.08, f.limits), GENTLE_TURN)
    f.command(0.1, 0.08, 0.3)
    assert f.target == (1.5, pytest.approx(0.08 / 0.11), 0.3)
    assert m.alpha_at(0.08, 1.5) == pytest.approx(0.08 / 0.11)
    f.command(0.2, 0.01, 0.3)  # slower than steer_alpha walks at steer_zeta: steer_alpha
    assert f.target == (1.5, 0.3, 0.3)
    f.command(0.3, 0.0, 0.0, 0.2)
    assert f.target == (1.5, 0.3, 0.0) and f.target_y == 0.05
    assert f.update(0.3, 1.5, 0.3) == CmdVelOutput(1.5, 0.3, 0.0, "stepping in place", 0.05)
    f.command(0.0, 0.0, 0.0)
    assert f.target_y == 0.0 and f.target[1] == 0.0  # standing: no side step
    capped = CmdVelFollower(m, limits(side_step_max_alpha=0.4), zeta=1.0)
    capped.command(0.0, 0.08, 0.0, 0.02)  # forward beside a side step: α at most side_step_max_alpha ...
    assert capped.target == (1.5, 0.4, 0.0) and capped.target_y == 0.02
    capped.command(0.1, 0.08, 0.0)  # ... and the map's (ζ, α) again without it
    assert capped.target == (*m.command(0.08, capped.limits), 0.0)
    capped.command(0.2, 0.02, 0.0, -0.02)  # slower steps are kept
    assert capped.target == (1.5, 0.3, 0.0) and capped.target_y == -0.02
    with pytest.raises(ValueError, match=r"side_step_max_alpha must be >= cmd_vel\.steer_alpha"):
        limits(side_step_max_alpha=0.2)
    slow = CmdVelFollower(m, limits(max_angular_z=0.5, angular_z_rate_in_place=1.0, angular_z_rate=0.5),
                          zeta=1.0)
    slow.command(0.0, 0.0, 0.5)
    turns = [slow.update(t, 1.5, 0.3).turn_rate for t in np.arange(0.0, 0.8, 0.1)]
    # timed out after 0.5 s: not in place any more, down at angular_z_rate
    assert turns == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.45, 0.4])


@pytest.mark.slow
def test_turning_in_place_reaches_the_commanded_rate_in_process():
    """The simulated robot, walking, gets angular.z 0.5 rad/s with linear.x 0 at 10 s: it steps in place
    and turns at >= 0.5 rad/s (the issue's target) over 13-20 s (0.591 measured), >= 4 rad in the 10 s
    from the command (the issue's must-show; 5.13 measured), moves < 3 cm/s, and stays up."""
    from cpg_walker.experiments.cmd_vel import Drive, run_drive

    m = run_drive(Drive("t", ((20.0, 0.0, 0.5),), windows=((13.0, 20.0),), tail_s=3.0))
    assert not m["fell"], m
    (seg,) = m["segments"]
    assert seg["turn_rate_rad_s"] >= 0.5 and abs(seg["speed_mps"]) < 0.03, seg
    assert seg["whole"]["turned_rad"] >= 4.0, seg


def test_fast_nodes_go_on_past_the_fastest_zeta_and_a_follower_without_them_stops_short():
    """``fast_speed`` rows continue the chain past the fastest ζ at α 1 (linear between nodes, speed
    monotone); ``command(..., fast=False)`` and a follower with ``allow_fast(False)`` stop at that ζ's
    speed; malformed rows name the key."""
    d = toy_map()
    d["forward"]["fast_speed"] = [[1.6, 1.2, 0.13], [1.7, 1.4, 0.15]]
    m = SpeedMap(d, "toy.yaml")
    lim = limits(max_linear_x=0.15)
    assert m.forward.v_plain == pytest.approx(0.11) and m.v_max == pytest.approx(0.15)
    assert m.inverse(0.12) == pytest.approx((1.55, 1.1))  # half way to the first node
    assert m.inverse(0.15) == pytest.approx((1.7, 1.4)) and m.command(0.2, lim) == pytest.approx((1.7, 1.4))
    assert m.speed(1.6, 1.2) == pytest.approx(0.13) and m.speed(1.7, 1.0) == pytest.approx(0.11)
    assert m.command(0.14, lim, fast=False) == pytest.approx((1.5, 1.0))
    assert m.command(0.1, lim, fast=False) == m.command(0.1, lim)
    f = CmdVelFollower(m, lim)
    f.command(0.0, 0.14, 0.0)
    assert f.target[:2] == pytest.approx((1.65, 1.3))
    f.allow_fast(False)
    assert f.target[:2] == pytest.approx((1.5, 1.0))
    f.allow_fast(True)
    assert f.target[0] > 1.5
    for rows, why in (([[1.6, 0.9, 0.13]], "alpha must rise"), ([[1.4, 1.2, 0.13]], "alpha must rise"),
                      ([[1.6, 1.2]], "[zeta, alpha, speed]"), ([[-1.6, 1.2, 0.13]], "must be > 0")):
        bad = toy_map()
        bad["forward"]["fast_speed"] = rows
        with pytest.raises(ValueError, match=re.escape(why)) as err:
            SpeedMap(bad, "toy.yaml")
        assert "toy.yaml: forward.fast_speed" in str(err.value)


@pytest.mark.slow
def test_the_fastest_command_walks_on_longer_steps_in_process():
    """The simulated robot, walking, gets linear.x 0.15 (the limit) from 10 s: it walks on the speed map's
    fast nodes (α > 1 with the ankle pathway) at >= 0.15 m/s over 30-50 s (the issue's target; 0.156
    measured, 0.153 through the realtime graph); backward at the limit (-0.129, after the reversal) at
    least 0.12 m/s over 50-80 s (-0.132 measured, -0.128 realtime); each stops on the timeout upright."""
    from cpg_walker.experiments.cmd_vel import Drive, run_drive
    from cpg_walker.experiments.walk_runs import run_many

    drives = (Drive("fast", ((50.0, 0.15, 0.0),), windows=((30.0, 50.0),), tail_s=6.0),
              Drive("back", ((80.0, -0.129, 0.0),), windows=((50.0, 80.0),), tail_s=6.0))
    for m, fast in zip(run_many(run_drive, drives, jobs=2), (0.15, -0.12), strict=True):
        assert not m["fell"], m
        (seg,) = m["segments"]
        assert seg["alpha"] > 1.0 and seg["speed_mps"] * np.sign(fast) >= abs(fast), seg


@pytest.mark.slow
def test_side_steps_walk_the_limit_left_right_and_beside_a_forward_walk_or_a_turn_in_process():
    """The simulated robot, walking, gets linear.y at the limit (0.05 m/s) from 10 s for 20 s: it moves
    >= 0.8 m sideways each way (the issue's must-show; 0.85-0.90 m measured in-process, 1.00-1.04 m
    through the realtime graph) without falling, on soles tilted with the legs. Beside linear.x 0.08 (α
    capped at side_step_max_alpha: 4 of 4 fell uncapped at α 0.76; soles level: on tilted ones the base
    yawed) it goes forward and sideways without turning (0.50 / 0.48 m, 0.17 rad in 30 s); beside a turn
    of 0.4 rad/s (soles level: on tilted ones the turn slipped) it turns (11.2 rad in 30 s) and still
    steps sideways (1.0 m)."""
    from cpg_walker.experiments.cmd_vel import Drive, run_drive
    from cpg_walker.experiments.walk_runs import run_many

    lim = CmdVelLimits.load()
    assert lim.max_linear_y >= 0.05
    drives = (Drive("left", ((30.0, 0.0, 0.0, 0.05),), windows=((10.0, 30.0),), tail_s=6.0),
              Drive("right", ((30.0, 0.0, 0.0, -0.05),), windows=((10.0, 30.0),), tail_s=6.0),
              Drive("forward and left", ((40.0, 0.08, 0.0, 0.05),), windows=((10.0, 40.0),), tail_s=6.0),
              Drive("turning and left", ((40.0, 0.0, 0.4, 0.05),), windows=((10.0, 40.0),), tail_s=6.0))
    left, right, forward, turning = run_many(run_drive, drives, jobs=2)
    for m, sign in ((left, 1.0), (right, -1.0)):
        assert not m["fell"], m
        (seg,) = m["segments"]
        assert seg["whole"]["sideways_m"] * sign >= 0.8, seg
    for m in (forward, turning):
        assert not m["fell"], m
    (seg,) = forward["segments"]
    assert seg["alpha"] == pytest.approx(lim.side_step_max_alpha, abs=0.02), seg
    w = seg["whole"]
    assert w["sideways_m"] >= 0.4 and w["forward_m"] >= 0.4 and abs(w["turned_rad"]) <= 0.5, seg
    (seg,) = turning["segments"]
    assert seg["whole"]["turned_rad"] >= 10.0 and seg["whole"]["sideways_m"] >= 0.8, seg
