"""CPGDriver (walker/cpg_driver.py), cpg_node's logic, without ROS: ticks and their targets, re-sent ticks,
lookahead, the horizon, commands before and after the CPG takes over, re-entry (a late first tick, the
servos' release, a restarted sim), the stray-tick guard and the lockstep sensor wait."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cpg_walker.timing import CLOCK_JUMP_NS
from cpg_walker.walker import storage
from cpg_walker.walker.cmd_vel import CmdVelLimits, SpeedMap
from cpg_walker.walker.cpg_driver import REJOIN_AFTER_S, CPGDriver, FeedbackFade
from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController, default_pathways
from cpg_walker.walker.learning import cpg_defaults, load_controller

MS = 1_000_000  # ns
PERIOD = 2 * MS


def _make(ctrl, settings) -> tuple[CPGDriver, _Out]:
    out = _Out()
    return CPGDriver(ctrl, out, **settings), out


class _Out:
    """A DriverOutput that keeps what the driver sends."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.horizons: list[tuple[int, np.ndarray]] = []
        self.monitors: list[tuple[int, dict]] = []
        self.logs: list[tuple[str, str]] = []

    def targets(self, t_ns, q, qd):
        self.sent.append((t_ns, q.copy(), qd.copy()))

    def horizon(self, t_ns, offsets_ns, q, qd):
        assert q.shape == (offsets_ns.size, 25) and np.isfinite(q).all()
        self.horizons.append((t_ns, offsets_ns.copy()))

    def monitor(self, t_ns, state, values):
        self.monitors.append((t_ns, values))

    def log(self, level, text, key=None):
        self.logs.append((level, text))

    def said(self, text: str) -> bool:
        return any(text in line for _, line in self.logs)


def _run(d: CPGDriver, t0_ns: int, t1_ns: int) -> None:
    for t in range(t0_ns, t1_ns, PERIOD):
        d.clock(t)


def test_the_driver_and_its_tests_need_no_ros() -> None:
    code = ("import sys; import cpg_walker.walker.cpg_driver; "
            "assert not [m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rcl_interfaces')], 'ROS'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_each_tick_sends_its_target_and_the_next_and_a_resent_tick_the_same_again() -> None:
    d, out = _make(*_setup())
    _run(d, 0, 20 * MS)
    stamps = [t for t, _, _ in out.sent]
    assert stamps[0] == 0 and stamps[1:] == list(range(2 * MS, 22 * MS, 2 * MS))  # lookahead: t + period
    before = {t: q for t, q, _ in out.sent}
    d.clock(18 * MS)  # re-sent: its cached target again, bit for bit
    t, q, _ = out.sent[-1]
    assert t == 18 * MS and np.array_equal(q, before[18 * MS])
    assert d.control_period_ns == PERIOD and d.stage == "starting"
    assert out.horizons and out.horizons[0][1][0] == 0 and out.horizons[0][1][-1] == 4000 * MS  # 1 s + 3 s
    d.idle()  # the pending monitor output goes out between messages
    assert [t for t, _ in out.monitors] == [0] and out.monitors[0][1]["zeta_command"] == "1"


def test_the_horizon_goes_out_every_horizon_period_with_points_every_horizon_step() -> None:
    """``horizon_period`` spaces the messages (0: every horizon_step), ``horizon_step`` their points; a
    period longer than half the horizon is refused (pid_node could ride less than half of it)."""
    for period_ms, every_ms in ((0, 40), (200, 200)):
        ctrl, settings = _setup()
        d, out = _make(ctrl, {**settings, "horizon_period_ns": period_ms * MS})
        _run(d, 0, 1000 * MS)
        starts = [t for t, _ in out.horizons]
        assert np.all(np.diff(starts) == every_ms * MS), starts
        offsets = out.horizons[-1][1]
        assert np.all(np.diff(offsets[offsets >= 40 * MS]) == 40 * MS) and offsets[-1] == 4000 * MS
    ctrl, settings = _setup()
    with pytest.raises(ValueError, match="half the horizon"):
        _make(ctrl, {**settings, "horizon_period_ns": 600 * MS})


def test_a_command_before_the_takeover_waits_for_it_and_one_after_applies_at_once() -> None:
    d, _ = _make(*_setup())
    _run(d, 0, 100 * MS)
    assert d.command(1.3, 0.8) == pytest.approx(d.walk_from_s)  # deferred to the end of the cross-fade
    assert d.ctrl.zeta_command == 1.0
    start = round(d.walk_from_s * 1e9) // PERIOD * PERIOD
    _run(d, 100 * MS, start + 10 * MS)
    assert (d.ctrl.zeta_command, d.ctrl.alpha_command) == (1.3, 0.8)
    after = d.command(0.9, 1.0)
    assert after == pytest.approx((start + 8 * MS) / 1e9) and d.ctrl.zeta_command == 0.9


def test_a_late_first_tick_re_enters_from_the_crouch_after_standing_by() -> None:
    ctrl, settings = _setup()
    d, out = _make(ctrl, {**settings, "rejoin_settle_ns": 100 * MS})
    t0 = 30_000 * MS
    _run(d, t0, t0 + 100 * MS)  # standing by: nothing sent
    assert not out.sent and out.said("of a running sim: standing by")
    _run(d, t0 + 100 * MS, t0 + 120 * MS)
    assert out.sent and d.reentries == 1 and d.rejoined_at_s == pytest.approx((t0 + 100 * MS) / 1e9)
    assert d.walk_from_s == pytest.approx(d.rejoined_at_s + d.source.blend)
    assert out.said("joined a running sim at 30.100 s: re-entering the gait from the standing crouch")
    d2, out2 = _make(storage.from_dict(storage.to_dict(ctrl)), {**settings, "rejoin_settle_ns": 100 * MS,
                                                                "lockstep": True})
    d2.clock(t0)  # lockstep: at once
    assert d2.reentries == 1 and out2.sent
    assert REJOIN_AFTER_S < t0 / 1e9


def test_the_servos_release_re_enters_the_gait() -> None:
    d, out = _make(*_setup())
    _run(d, 0, 50 * MS)
    d.servo_hold(True)
    _run(d, 50 * MS, 60 * MS)
    assert d.reentries == 0
    d.servo_hold(False)
    d.clock(60 * MS)
    assert d.reentries == 1 and out.said("the servos were released at 0.060 s")
    status = d.status(60 * MS)  # the same as machine-readable /diagnostics values
    assert (status["reentries"], status["reentry_cause"], status["rejoined_at_s"], status["servos_held"],
            status["clock_resets"]) == ("1", "the servos were released", "0.060", "false", "0")


def test_a_stray_tick_is_dropped_a_confirmed_jump_taken_and_a_restarted_sim_starts_over() -> None:
    d, out = _make(*_setup())
    _run(d, 0, 10 * MS)
    last = d.last_tick_ns
    d.clock(2**62)  # a stray far-future tick would end the walk: every real tick after it looks old
    assert d.counters["clock_dropped"] == 1 and d.last_tick_ns == last
    d.clock(last + PERIOD)
    assert d.last_tick_ns == last + PERIOD
    far = d.last_tick_ns + 5 * CLOCK_JUMP_NS
    d.clock(far)
    assert d.last_tick_ns == last + PERIOD  # dropped once ...
    d.clock(far + PERIOD)
    assert d.last_tick_ns == far + PERIOD  # ... taken when the next continues it
    d.clock(-1)
    assert d.counters["clock_dropped"] == 3
    d.clock(0)
    d.clock(PERIOD)  # a restarted sim: confirmed, the CPG starts over from the loaded network
    assert d.clock_resets == 1 and d.last_tick_ns == PERIOD and out.said("sim restarted")


def test_lockstep_waits_for_the_ticks_samples_then_gives_up_on_a_dead_sensor() -> None:
    now = [0.0]
    ctrl, settings = _setup()
    d, out = _make(ctrl, {**settings, "lockstep": True, "feedback_on": True, "sensor_wait_s": 0.4,
                          "wall": lambda: now[0]})
    quat, gyro = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)
    d.clock(0)
    assert not out.sent and d.waiting  # no samples stamped 0 yet
    d.sample(0, 0, (quat, gyro))
    d.sample(1, 0, 10.0)
    assert not out.sent
    d.sample(2, 0, 10.0)
    assert [t for t, _, _ in out.sent] == [0]  # all three there: the tick ran
    d.clock(PERIOD)
    now[0] = 0.5
    d.idle()  # waited past sensor_wait_s: going on with the newest
    assert d.counters["sensor_wait_timeouts"] == 1 and out.sent[-1][0] == 2 * PERIOD
    assert out.said("going on with the newest (not reproducible)")


def test_the_summary_counts_what_happened() -> None:
    d, _ = _make(*_setup())
    _run(d, 0, 20 * MS)
    s = d.summary()
    assert s["tick"]["ticks"] == 10 and s["reentries"] == 0 and s["clock_resets"] == 0
    assert set(s["feedback"]) >= {"dropped", "wait_timeouts", "clock_dropped", "targets_withheld"}


def _setup():
    ctrl = load_controller(cpg_defaults()["cpg_file"])[0]
    settings = dict(feedback=FeedbackController(FeedbackConfig.load(), default_pathways()), feedback_on=False,
                    fade=FeedbackFade(0.5, 0.05), zeta=1.0, alpha=1.0, speed_map=SpeedMap.load(),
                    cmd_vel_limits=CmdVelLimits.load(), horizon_s=1.0, horizon_stop_s=3.0,
                    horizon_step_ns=40 * MS, monitor_period_ns=100 * MS)
    return ctrl, settings


def test_the_ankle_pathway_acts_in_lockstep_or_when_allowed_in_realtime() -> None:
    """Outside lockstep the ankle pathway stays out unless ``ankle_in_realtime`` (config/cpg.yaml: its rate
    gains fell on an overloaded realtime machine); the other pathways act either way."""
    quat, gyro = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.4, 0.3, 0.0])  # rolling and pitching
    offsets = {}
    cases = (("realtime", {}), ("allowed", {"ankle_in_realtime": True}), ("lockstep", {"lockstep": True}))
    for name, extra in cases:
        ctrl, settings = _setup()
        settings["feedback"] = FeedbackController(FeedbackConfig.load(), (*default_pathways(), "ankle"))
        d, _ = _make(ctrl, {**settings, "feedback_on": True, "horizon_s": 0.0, **extra})
        for t in range(0, 7_000 * MS, PERIOD):
            d.sample(0, t, (quat, gyro))
            d.sample(1, t, 20.0)
            d.sample(2, t, 20.0)
            d.clock(t)
        offsets[name] = d.source.fb.ankle_offsets()
        assert d.summary()["feedback"]["ankle_allowed"] is (name != "realtime")
        assert d.fade.weight == 1.0  # the pathways closed
    assert offsets["realtime"] == (0.0, 0.0)
    assert all(abs(v) > 0.01 for v in (*offsets["allowed"], *offsets["lockstep"])), offsets


def _tilted_ticks(d: CPGDriver, t0_ms: int, t1_ms: int, vy: float | None = None,
                  vx: float = 0.0) -> list[bool]:
    """Ticks from t0 to t1 with a rolling and pitching chest (and a /cmd_vel of ``vx`` forward and a side
    step of ``vy`` every 0.1 s unless vy is None); whether the ankle pathway was allowed at each."""
    quat, gyro = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.4, 0.3, 0.0])
    allowed = []
    for t in range(t0_ms * MS, t1_ms * MS, PERIOD):
        if vy is not None and t % (100 * MS) == 0:
            d.twist(vx, 0.0, vy)
        d.sample(0, t, (quat, gyro))
        d.sample(1, t, 20.0)
        d.sample(2, t, 20.0)
        d.clock(t)
        allowed.append(d.source.fb.ankle_allowed)
    return allowed


def test_a_side_step_closes_the_ankle_pathway_in_realtime_while_it_lasts() -> None:
    """Outside lockstep, ``ankle_for_side_step`` (the default) closes the ankle pathway for a /cmd_vel side
    step from its command until its amplitude has wound down after it; without it the side step is
    refused (counted as 0, the reason on the status) and the pathway stays out."""
    for for_side in (True, False):
        ctrl, settings = _setup()
        settings["feedback"] = FeedbackController(FeedbackConfig.load(), default_pathways())
        d, _ = _make(ctrl, {**settings, "feedback_on": True, "horizon_s": 0.0,
                            "ankle_for_side_step": for_side})
        assert not any(_tilted_ticks(d, 0, 8_000)) and d.source.fb.ankle_offsets() == (0.0, 0.0)
        allowed = _tilted_ticks(d, 8_000, 14_000, 0.03)
        assert d.source.side_stepping is for_side and allowed[-1] is for_side
        assert (d.cmd_side == "ok") is for_side and (for_side or "ankle_for_side_step" in d.cmd_side)
        if for_side:
            assert abs(d.source.fb.ankle_offsets()[0]) > 0.01
        allowed = _tilted_ticks(d, 14_000, 20_000)  # no more commands: the timeout, the amplitude winds down
        assert not d.source.side_stepping and not allowed[-1]


def test_longer_steps_close_the_ankle_pathway_in_realtime_while_they_last() -> None:
    """Outside lockstep, ``ankle_for_speed`` (the default) closes the ankle pathway for a /cmd_vel speed on
    the speed map's fast nodes (steps longer than the plain envelope's) until the steps are short again
    after it; the governor reaches them only once it is closed. Without it linear.x stops short of them
    (ζ 1.5, α 1) and the pathway stays out."""
    from cpg_walker.walker.governor import GovernorConfig

    for for_speed in (True, False):
        ctrl, settings = _setup()
        d, _ = _make(ctrl, {**settings, "feedback_on": True, "horizon_s": 0.0,
                            "governor": GovernorConfig.load(), "ankle_for_speed": for_speed})
        assert not any(_tilted_ticks(d, 0, 8_000))
        alphas, closed = [], []
        for t0 in range(8_000, 24_000, 1_000):
            allowed = _tilted_ticks(d, t0, t0 + 1_000, 0.0, 0.15)
            alphas.append(d.ctrl.alpha_command)
            closed.append(allowed[-1])
            assert not (d.ctrl.alpha_command > 1.0 + 1e-9 and d.source.fb.ankle_fresh < 1.0)  # once closed
        assert d.cmd.fast_allowed is for_speed
        if for_speed:
            assert d.cmd.target[0] > 1.5 and d.cmd.target[1] > 1.0
        else:
            assert d.cmd.target[:2] == pytest.approx((1.5, 1.0))
        assert (max(alphas) > 1.3) is for_speed and closed[-1] is for_speed and any(closed) is for_speed
        assert d.summary()["feedback"]["ankle_for_speed"] is for_speed
        allowed = _tilted_ticks(d, 24_000, 34_000)  # no more commands: the timeout, the steps shorten
        assert d.ctrl.alpha_command == 0.0 and not allowed[-1]


def test_started_at_alpha_0_it_stands_without_the_recorded_opening_steps() -> None:
    """α 0 at the start: the source fades in from standing (no recorded steps to stop from); otherwise the
    recording's opening steps hand over to the CPG."""
    for alpha, transition in ((0.0, "standing"), (0.6, "recording")):
        ctrl, settings = _setup()
        d, _ = _make(ctrl, {**settings, "alpha": alpha})
        assert d.source.transition == transition
