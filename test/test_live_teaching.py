"""Live teaching (walker/live_teaching.py): the CPG learned from a joint-angle stream as it arrives.

Streams come from walker/teaching_stream.py (a recording, then its steady stride repeated; optionally
time-scaled), sampled at 100 Hz of teacher time as a teacher node would publish them. Measured (this
module's streams): the slow walk learned at 0.3908 Hz against the recording's 0.3906 (0.045 %), the walk
at 0.8x and 1.25x within 0.02 %; the live-taught slow walk walks 60 s open loop, 2.75 m."""

from __future__ import annotations

import numpy as np
import pytest

from cpg_walker.errors import InputError
from cpg_walker.robot.gait_data import Gait, load_gait
from cpg_walker.walker.controller import DOFS
from cpg_walker.walker.learning import learning_settings, live_teaching_config
from cpg_walker.walker.live_teaching import (
    COLLECTING,
    CONVERGED,
    LEARNING,
    REFUSED,
    SEARCH_EVERY_S,
    LiveTeacher,
    LiveTeachingConfig,
)
from cpg_walker.walker.teaching_stream import TeachingStream

SAMPLE_DT = 0.01  # teacher s between samples (100 Hz)


def _teacher() -> LiveTeacher:
    settings, params = learning_settings()
    return LiveTeacher(settings, params, live_teaching_config())


def _feed(teacher: LiveTeacher, signal, t0: float = 0.0, until: float = 900.0, now0: float = 0.0,
          names=DOFS) -> float:
    """Stream ``signal(t)`` into ``teacher`` (the caller's clock running with teacher time from ``now0``)
    until it converges or refuses, or ``until``; returns the teacher time reached."""
    t = t0
    while t < until:
        teacher.add(t, names, list(signal(t)), now=now0 + t - t0)
        teacher.advance(50)
        if teacher.state in (CONVERGED, REFUSED):
            break
        t = round(t + SAMPLE_DT, 6)
    return t


@pytest.fixture(scope="module")
def slow():
    """The slow walk taught live, and the stream it was taught."""
    stream = TeachingStream("slow")
    teacher = _teacher()
    _feed(teacher, stream.at)
    return teacher, stream


def test_the_slow_walk_streamed_is_learned_at_its_frequency(slow):
    teacher, stream = slow
    assert teacher.state == CONVERGED and teacher.result is not None, teacher.reason
    info = teacher.result_info
    assert info["learned_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)
    assert info["teacher_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)
    # learned within the offline budget (offline: 140 strides from the repeated stride alone)
    assert 0 < info["strides"] <= teacher.settings.max_strides
    assert teacher.result.meta["learning"]["converged"] and not teacher.result.net.learning


def test_the_live_taught_slow_walk_walks(slow):
    """Re-based on the recording (``TeachingStream.aligned``), it starts from the recording's opening steps
    and walks open loop (the walk's feedback gains fell it, as they fall the offline-learned slow CPG)."""
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker import storage
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.loop import run_replay

    teacher, stream = slow
    ctrl = storage.from_dict(storage.to_dict(teacher.result))  # as saved and loaded
    ctrl = stream.aligned(ctrl, ctrl.meta["teaching"]["cycle_start_s"])
    assert ctrl.meta["teaching"]["gait"] == "slow"
    sim = Hoap2Sim()
    sim.reset()
    r = run_replay(sim, CPGGaitSource(ctrl), PidLaw.from_config(), 30.0)
    assert not r.fell, r.fall_time_s
    # 1.38 m in 30 s measured (the slow walk's replay: 0.046 m/s)
    assert float(np.linalg.norm(np.asarray(r.base_xy)[-1] - np.asarray(r.base_xy)[0])) > 1.0


@pytest.mark.parametrize("speed", [1.25])
def test_a_time_scaled_stream_is_learned_at_its_own_frequency(speed):
    stream = TeachingStream("walk", speed)
    teacher = _teacher()
    _feed(teacher, stream.at)
    assert teacher.state == CONVERGED, teacher.reason
    assert teacher.result_info["learned_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)
    assert abs(stream.frequency_hz / TeachingStream("walk").frequency_hz - speed) < 1e-9


def test_a_non_periodic_stream_is_refused_and_a_new_stream_starts_after_a_pause():
    rng = np.random.default_rng(5)
    knots = np.cumsum(rng.normal(0.0, 0.05, size=(200, len(DOFS))), axis=0)  # a smooth random walk
    grid = np.arange(len(knots)) * 0.5

    def wander(t: float) -> np.ndarray:
        return np.array([np.interp(t, grid, knots[:, j]) for j in range(len(DOFS))])

    teacher = _teacher()
    end = _feed(teacher, wander, until=90.0)
    cfg = teacher.cfg
    assert teacher.state == REFUSED and "not periodic" in teacher.reason, teacher.reason
    assert end == pytest.approx(cfg.give_up_s, abs=SAMPLE_DT + 1.0) and teacher.result is None
    teacher.add(end + SAMPLE_DT, DOFS, list(wander(end)), now=end + SAMPLE_DT)  # no pause: still refused
    assert teacher.state == REFUSED
    t = end + cfg.stall_s + 1.0  # after a pause: a new teaching
    teacher.add(t, DOFS, list(wander(t)), now=t)
    assert teacher.state == COLLECTING and teacher.teachings == 2


def test_a_drifting_recording_is_streamed_whole_and_refused_as_not_periodic():
    """A recording that drifts (a random walk of every joint, 20 s) has no stride by live teaching's rule
    (past the first lag correlating below PERIOD_DIP, at least min_correlation): the stream is all of it
    over and over, refused within give_up_s. Without the dip its legs correlate 0.93 at 0.5 s: offline
    learning's rule (correlation 0.8) cut a 0.36 s "stride" from it, looped into a periodic stream the
    learner learned (`teach --csv` of such a drift: refused only after 600 strides). The packaged walks
    keep their strides."""
    walk = load_gait("walk")
    rng = np.random.default_rng(4)
    n = 20001  # 20 s at the walk's 1 ms
    q = walk.q[0] + np.cumsum(rng.normal(0.0, 0.002, size=(n, len(walk.names))), axis=0)
    drift = Gait("drift", walk.names, np.arange(n) * 0.001, q, "drift")
    stream = TeachingStream(drift)
    assert not stream.periodic and "at least 0.9 needed" in stream.why_not_periodic, stream.why_not_periodic
    assert (stream.cycle_start, stream.cycle_period) == (0.0, drift.duration)
    assert np.array_equal(stream.at(drift.duration + 5.0), stream.gait.at(5.0))  # the whole of it again
    for name, start, period in (("walk", 5.616, 2.513), ("slow", 6.284, 2.56)):
        kept = TeachingStream(name)
        assert kept.periodic
        assert (kept.cycle_start, kept.cycle_period) == pytest.approx((start, period), abs=1e-9)
    teacher = _teacher()
    end = _feed(teacher, stream.at, until=120.0)
    cfg = teacher.cfg
    assert teacher.state == REFUSED and "not periodic" in teacher.reason, (teacher.state, teacher.reason)
    assert end <= cfg.give_up_s + SEARCH_EVERY_S + SAMPLE_DT and teacher.result is None


@pytest.mark.parametrize("bad, reason", [
    ("missing", "lacks 1 of the CPG's joints: rleg_joint_6"),
    ("nan", "lleg_joint_3 is NaN or infinite at teacher time 20.000 s"),
    ("backwards", "teacher time went from 20.000 s back to 19.000 s"),
    ("jump", "teacher time jumped by 5.000 s"),
    ("stop", "the teaching stream stopped at teacher time 20.000 s"),
])
def test_a_broken_stream_is_refused_naming_the_problem(bad, reason):
    stream = TeachingStream("walk")
    teacher = _teacher()
    _feed(teacher, stream.at, until=20.0)
    assert teacher.state == LEARNING  # the period found, learning
    t, q = 20.0, list(stream.at(20.0))
    if bad == "missing":
        teacher.add(t, DOFS[:-1], q[:-1], now=t)
    elif bad == "nan":
        q[DOFS.index("lleg_joint_3")] = float("nan")
        teacher.add(t, DOFS, q, now=t)
    elif bad == "backwards":
        teacher.add(t, DOFS, q, now=t)
        teacher.add(19.0, DOFS, q, now=t)
    elif bad == "jump":
        teacher.add(t, DOFS, q, now=t)
        teacher.add(25.0, DOFS, list(stream.at(25.0)), now=t)
    else:
        teacher.add(t, DOFS, q, now=t)
        assert not teacher.stalled(t + teacher.cfg.stall_s / 2)
        assert teacher.stalled(t + teacher.cfg.stall_s)
    assert teacher.state == REFUSED and reason in teacher.reason, teacher.reason
    assert teacher.net is None and teacher.result is None  # what it was learning is dropped
    assert teacher.progress()["reason"] == teacher.reason


def test_progress_reports_per_dof_frequencies_amplitudes_and_errors():
    """Measured on the walk: after 60 teacher s every DOF within 6 % of the stream's frequency, errors
    1.5-3.2 deg; after 120 s within 0.16 %, errors 0.16-2.2 deg."""
    stream = TeachingStream("walk")
    teacher = _teacher()
    _feed(teacher, stream.at, until=60.0)
    early = teacher.progress()
    _feed(teacher, stream.at, t0=60.0, until=120.0, now0=60.0)
    p = teacher.progress()
    assert early["state"] == p["state"] == LEARNING and p["strides"] > early["strides"] > 5
    assert len(p["learned_frequency_hz"]) == len(p["amplitude_rad"]) == len(p["error_deg"]) == len(DOFS)
    assert np.allclose(p["learned_frequency_hz"], stream.frequency_hz, rtol=0.01)
    assert all(a > 0 for a in p["amplitude_rad"])
    assert max(p["error_deg"]) < max(early["error_deg"]) and np.all(np.isfinite(p["error_deg"]))
    assert p["teacher_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)


def test_the_settings_are_checked():
    good = {"window_s": 12.0, "min_period_s": 0.5, "max_period_s": 5.0, "min_correlation": 0.9,
            "give_up_s": 40.0, "max_gap_s": 0.1, "stall_s": 2.0}
    assert LiveTeachingConfig.from_mapping(good, "x").window_s == 12.0
    with pytest.raises(InputError, match=r"window_s .* must hold two of the longest period"):
        LiveTeachingConfig.from_mapping({**good, "window_s": 8.0}, "x")
    with pytest.raises(InputError, match=r"missing key\(s\) \['stall_s'\]"):
        LiveTeachingConfig.from_mapping({k: v for k, v in good.items() if k != "stall_s"}, "x")


def test_the_driver_learns_from_teach_samples_takes_over_and_saves(tmp_path):
    """CPGDriver (cpg_node's logic) standing at α 0 (the gait fixed by its commands, no physics): taught
    the slow walk at 10 teacher s per sim s (a teacher at --rate 10 on a realtime sim), take-over is refused
    with the reason until the learning converges; asked while walking, it stops the robot, switches in
    standing, cross-fades (no jump in the targets) and steps off again; saved as a file cpg_file loads
    (starting from standing)."""
    from cpg_walker.walker import storage
    from cpg_walker.walker.cmd_vel import CmdVelLimits, SpeedMap
    from cpg_walker.walker.cpg_driver import CPGDriver, FeedbackFade
    from cpg_walker.walker.feedback import FeedbackConfig, FeedbackController, default_pathways
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    class Out:
        def __init__(self):
            self.sent, self.logs = [], []

        def targets(self, t_ns, q, qd):
            self.sent.append((t_ns, q.copy()))

        def horizon(self, *a):
            pass

        def monitor(self, *a):
            pass

        def log(self, level, text, key=None):
            self.logs.append((level, text))

    clock = {"now": 0.0}
    out = Out()
    d = CPGDriver(load_controller(cpg_defaults()["cpg_file"])[0], out,
                  feedback=FeedbackController(FeedbackConfig.load(), default_pathways()), feedback_on=False,
                  fade=FeedbackFade(0.5, 0.05), zeta=1.0, alpha=0.0, speed_map=SpeedMap.load(),
                  cmd_vel_limits=CmdVelLimits.load(), teacher=_teacher(), teach_steps=4,
                  wall=lambda: clock["now"])
    d.warm_up()
    stream = TeachingStream("slow")
    period_ns, rate = 2_000_000, 10
    t_ns, k = 0, 0
    with pytest.raises(ValueError, match="no taught network has converged yet: teaching is idle"):
        d.take_over()
    while d.teacher.result is None and t_ns < 100_000_000_000:
        clock["now"] = t_ns / 1e9
        teach_t = k * SAMPLE_DT
        while teach_t <= rate * t_ns / 1e9:  # the samples due by now at the teacher's rate
            d.teach(teach_t, DOFS, list(stream.at(teach_t)))
            k += 1
            teach_t = k * SAMPLE_DT
        d.clock(t_ns)
        t_ns += period_ns
        if t_ns == 20_000_000_000:
            with pytest.raises(ValueError, match="no taught network has converged yet: teaching is learning"):
                d.take_over()
            assert d.teach_status()["teaching"] == "learning"
    info = d.teacher.result_info
    assert info["learned_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)
    assert any("live teaching converged" in text for _, text in out.logs)
    status = d.teach_status()
    assert status["teaching"] == "converged" and float(status["taught_learned_frequency_hz"]) == \
        pytest.approx(info["learned_frequency_hz"], rel=1e-5)  # as printed (6 digits)
    old_offset = d.ctrl.net.offset.copy()
    d.command(1.0, 1.0)  # step off, then take over while walking
    for _ in range(3000):
        d.clock(t_ns)
        t_ns += period_ns
    before = len(out.sent)
    message = d.take_over()
    assert "taking over" in message and d.pending is not None
    with pytest.raises(ValueError, match="already under way"):
        d.take_over()
    while d.pending is not None and t_ns < 200_000_000_000:  # it stops first, then switches
        d.clock(t_ns)
        t_ns += period_ns
    assert d.ctrl.meta["teaching"]["phase"] == "stream" and d.ctrl.alpha < 0.01
    for _ in range(2000):  # the cross-fade, then stepping off
        d.clock(t_ns)
        t_ns += period_ns
    assert d.ctrl.alpha_command > 0
    q = np.array([q for _, q in out.sent[before - 5:]])
    steps = np.abs(np.diff(q, axis=0)).max()
    assert steps < 0.01, steps  # rad per 2 ms: continuous through the hand-over (the gait: ~0.002)
    assert not np.allclose(d.ctrl.net.offset, old_offset)  # the slow walk's posture now
    assert d.summary()["teaching"]["took_over"] == 1
    path = d.save_taught(tmp_path / "taught.yaml")
    saved = storage.load(path)
    assert saved.gait_frequency_hz() == pytest.approx(info["learned_frequency_hz"])
    assert CPGGaitSource(saved).transition == "standing"  # its phase 0 is the stream's, not the recording's
    work = d.summary()["teaching"]["work_ms"]
    assert work is not None and work["max"] > 0


def test_a_recording_time_scaled_in_its_csv_is_learned_at_its_frequency(tmp_path):
    """The walk's CSV with its time column halved (0.80 Hz: a stride of 1.26 s, shorter than any recorded
    one): its steady stride is found (TeachingStream searches the live teaching's period range) and the
    stream learned at its frequency, the teacher's estimate too (the shortest of the lags that correlate
    about as well, not two strides)."""
    from cpg_walker.robot.gait_data import load_gait

    walk = load_gait("walk")
    path = tmp_path / "walk_fast.csv"
    rows = (f"{t:.6f}," + ",".join(f"{x:.6f}" for x in q) for t, q in zip(walk.t * 0.5, walk.q, strict=True))
    path.write_text("time_s," + ",".join(walk.names) + "\n" + "\n".join(rows) + "\n")
    stream = TeachingStream(path)
    assert stream.periodic and stream.frequency_hz == pytest.approx(2 / 2.513, rel=1e-3)
    teacher = _teacher()
    _feed(teacher, stream.at)
    assert teacher.state == CONVERGED, teacher.reason
    info = teacher.result_info
    assert info["learned_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)
    assert info["teacher_frequency_hz"] == pytest.approx(stream.frequency_hz, rel=0.01)


def test_the_taught_slow_walk_taken_over_through_standing_walks(slow):
    """cpg_node's take-over, in-process with physics (its sequence on the gait source: stop through the
    governor, switch standing, step off at teach's α 0.8), from the walk open loop at 10.0 s, one of the
    two phases (of 8) at which stepping off to α 1 fell about 20 s later; then 60 s of the taught gait."""
    from cpg_walker.experiments.teach import TAUGHT_ALPHA
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw
    from cpg_walker.walker import storage
    from cpg_walker.walker.cpg_driver import TAKE_OVER_ALPHA
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.governor import GovernorConfig
    from cpg_walker.walker.learning import cpg_defaults, load_controller
    from cpg_walker.walker.loop import run_replay

    teacher, _ = slow
    source = CPGGaitSource(load_controller(cpg_defaults()["cpg_file"])[0], governor=GovernorConfig.load())
    taught = storage.from_dict(storage.to_dict(teacher.result))
    events: dict[str, float] = {}

    class TakingOver:
        names = source.names

        def targets(self, t: float):
            if "asked" not in events and t >= 10.0:
                source.command(source.ctrl.zeta_command, 0.0)
                events["asked"] = t
            elif "asked" in events and "switched" not in events and source.ctrl.alpha < TAKE_OVER_ALPHA:
                source.switch(taught, 2.0)
                source.command(1.0, TAUGHT_ALPHA)
                events["switched"] = t
            return source.targets(t)

    sim = Hoap2Sim()
    sim.reset()
    r = run_replay(sim, TakingOver(), PidLaw.from_config(), 75.0)
    assert not r.fell, (r.fall_time_s, events)
    assert 10.0 < events["switched"] < 15.0 and source.ctrl is taught
    xy = np.asarray(r.base_xy)
    t = np.asarray(r.t)
    after = xy[-1] - xy[np.searchsorted(t, events["switched"])]
    assert float(np.hypot(*after)) > 1.2  # measured 1.69 m in the 61.5 s after the switch
