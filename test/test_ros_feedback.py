"""cpg_node's sensory feedback through the ROS graph: the fade law and the sensor checks (pure), the
feedback parameters through the parameter service, stale-sensor fade-out and fade-in with a stand-in for
the sim (the test publishes /clock, /imu and /foot_load and then stops /imu), and lockstep walks with
feedback through the three-node graph: bit-identical, with a ``walk --schedule`` change landing at its
sim time. Waits are for conditions, with hang-guard deadlines (ros_helpers.py)."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest
from ros_helpers import START_S, SimWatchdog, sim_deadline

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.cpg_params import pathway_list
from cpg_walker.nodes.validation import validate_imu, validate_load
from cpg_walker.walker.cpg_driver import FeedbackFade
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig

# ------------------------------------------------------------------------------------------ pure


def test_fade_ramps_out_and_back_in_smoothly():
    """Stale samples take the weight from 1 to 0 in fade_s sim s along smootherstep (monotone, flat at
    both ends), fresh ones bring it back; states say why."""
    fade = FeedbackFade(fade_s=0.5, timeout_s=0.05)
    dt = 0.002
    assert fade.state(True) == "stale" and fade.weight == 0.0  # no sample yet
    for _ in range(250):
        fade.update(dt, True, 0.0)
    assert fade.weight == 1.0 and fade.state(True) == "active"
    w = []
    for _ in range(300):
        w.append(fade.update(dt, True, 0.2))  # 0.2 s old > timeout
    w = np.array(w)
    assert np.all(np.diff(w) <= 0) and w[-1] == 0.0
    n_zero = int(np.argmax(w == 0.0))
    assert n_zero * dt == pytest.approx(0.5, abs=2 * dt)  # faded out in fade_s
    assert 1 - w[0] < 1e-4 and w[n_zero - 1] < 1e-4  # flat at both ends (C1 ramp)
    assert fade.state(True) == "stale"
    fade.update(dt, True, 0.0)
    assert 0 < fade.weight < 1e-4 and fade.state(True) == "active"  # fading back in
    for _ in range(50):
        fade.update(dt, True, 0.0)
    fade.update(dt, False, 0.0)
    assert 0 < fade.weight < 1 and fade.state(False) == "fading"  # switched off: fading out
    for _ in range(60):
        fade.update(dt, False, 0.0)
    assert fade.weight == 0.0 and fade.state(False) == "off"
    instant = FeedbackFade(fade_s=0.0, timeout_s=0.05)
    assert instant.update(dt, True, 0.0) == 1.0 and instant.update(dt, True, None) == 0.0


def test_malformed_sensor_samples_are_refused_with_a_reason():
    q, w = validate_imu("imu", "imu", (1.0, 0.0, 0.0, 0.0), (0.1, 0.2, 0.3))
    assert q.tolist() == [1.0, 0.0, 0.0, 0.0] and w.tolist() == [0.1, 0.2, 0.3]
    for frame, quat, gyro, why in (("imu", (math.nan, 0, 0, 1), (0, 0, 0), "non-finite"),
                                   ("imu", (1, 0, 0, 0), (0, math.inf, 0), "non-finite"),
                                   ("imu", (0, 0, 0, 0), (0, 0, 0), "norm"),
                                   ("imu", (2, 0, 0, 0), (0, 0, 0), "norm"),
                                   ("base_link", (1, 0, 0, 0), (0, 0, 0), "frame"),
                                   ("imu", (1, 0, 0), (0, 0, 0), "4-value")):
        with pytest.raises(ValueError, match=why):
            validate_imu(frame, "imu", quat, gyro)
    assert validate_load("l_sole", "l_sole", 12.5) == 12.5
    with pytest.raises(ValueError, match="non-finite"):
        validate_load("l_sole", "l_sole", math.nan)
    with pytest.raises(ValueError, match="frame"):
        validate_load("r_sole", "l_sole", 1.0)


def test_pathway_list_names_the_problem():
    paper = ("lateral", "pendulum", "reset")
    assert set(paper) <= set(PATHWAYS) and pathway_list(list(paper)) == paper
    for bad, why in ((["lateral", "sideways"], "sideways"), ([], "at least one"),
                     (["reset", "reset"], "twice")):
        with pytest.raises(ValueError, match=why):
            pathway_list(bad)


def test_schedule_text_and_where_it_landed():
    from cpg_walker.experiments.walk_graph import landed, parse_schedule

    assert parse_schedule("12,1.2,1; 8,0.8,1.1;") == [(8.0, 0.8, 1.1), (12.0, 1.2, 1.0)]
    assert parse_schedule("8,3.0,1") == [(8.0, 3.0, 1.0)]  # out of range: sent, refused, recorded (refused)
    for bad, why in (("8,1.2", "time,zeta,alpha"), ("8,x,1", "three numbers"), ("-1,1,1", ">= 0"),
                     ("8,nan,1", "finite")):
        with pytest.raises(ValueError, match=why):
            parse_schedule(bad)
    sent = [{"t_s": 8.0, "zeta": 1.2, "alpha": 0.9, "sent_at_sim_s": 8.0, "accepted": True, "reason": "",
             "sent_wall": 0.0}]
    log = ("[cpg]: commanded zeta=1.2, alpha=1 after sim 8.044 s\n"  # zeta's callback, alpha not yet set
           "[cpg]: commanded zeta=1.2, alpha=0.9 after sim 8.044 s\n")
    assert landed(sent, log)[0]["applied_after_sim_s"] == 8.044 and "sent_wall" not in landed(sent, log)[0]


# -------------------------------------------------------------------------------- through DDS

def _diag_values(msg) -> tuple[float, dict] | None:
    for s in msg.status:
        if s.name == "cpg_walker/cpg":
            t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            return t, {kv.key: kv.value for kv in s.values}
    return None


class StandIn:
    """The sim's sensor side, published from the test: /clock every ``dt`` sim s with /imu and both
    /foot_load samples of the same stamp (``imu`` False: the /imu sample is left out)."""

    def __init__(self, probe, dt: float = 0.01):
        from geometry_msgs.msg import WrenchStamped
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Imu

        self.node, self.dt, self.k = probe.node, dt, 0
        self.clock = self.node.create_publisher(Clock, ifc.CLOCK, 10)
        self.imu = self.node.create_publisher(Imu, ifc.IMU, 10)
        self.feet = [self.node.create_publisher(WrenchStamped, ifc.foot_load_topic(s), 10)
                     for s in ifc.FOOT_LOAD_SIDES]
        self.Clock, self.Imu, self.Wrench = Clock, Imu, WrenchStamped
        self.send_imu = True
        self.bad_imu: str | None = None  # "nan" | "frame": send one malformed /imu instead of the good one

    def now(self) -> float:
        return self.k * self.dt

    def tick(self) -> None:
        sec, nsec = divmod(round(self.k * self.dt * 1e9), 1_000_000_000)
        clock = self.Clock()
        clock.clock.sec, clock.clock.nanosec = sec, nsec
        self.clock.publish(clock)
        if self.send_imu:
            imu = self.Imu()
            imu.header.stamp.sec, imu.header.stamp.nanosec = sec, nsec
            imu.header.frame_id = "imu"
            imu.orientation.w = 1.0
            if self.bad_imu == "nan":
                imu.orientation.x = math.nan
            elif self.bad_imu == "frame":
                imu.header.frame_id = "base_link"
            self.bad_imu = None
            self.imu.publish(imu)
        for pub, frame in zip(self.feet, ("l_sole", "r_sole"), strict=True):
            w = self.Wrench()
            w.header.stamp.sec, w.header.stamp.nanosec = sec, nsec
            w.header.frame_id = frame
            w.wrench.force.z = 20.0
            pub.publish(w)
        self.k += 1


@pytest.mark.ros
@pytest.mark.slow
def test_feedback_parameters_and_stale_sensor_fade(graph, probe):
    """One cpg_node fed by a stand-in sim. Parameters: every FeedbackConfig field is a ``feedback.<field>``
    parameter with config/feedback.yaml's value; bad values are refused with the reason (FeedbackConfig's
    own for a value it refuses); a good set takes effect (diagnostics). Sensors: with fresh samples the
    feedback is active at weight 1; malformed /imu samples are dropped and counted; when /imu stops, the
    diagnostics say fading, then stale at weight 0 with the sensor age; when it returns, active at 1."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from sensor_msgs.msg import JointState

    from cpg_walker.graph.ros2cli import from_parameter_value

    cpg = graph.start("cpg_node", feedback_fade=0.3, sensor_timeout=0.05)
    probe.listen(ifc.DIAGNOSTICS, DiagnosticArray, 500)
    probe.listen(ifc.JOINT_TARGETS, JointState, 500)

    def value(kind: int, **kw) -> ParameterValue:
        return ParameterValue(type=kind, **kw)

    names = [f"feedback.{f.name}" for f in fields(FeedbackConfig)]
    got = {n: from_parameter_value(v) for n, v in zip(names, probe.get_params("cpg", names), strict=True)}
    default = FeedbackConfig.load()
    for f in fields(FeedbackConfig):
        assert got[f"feedback.{f.name}"] == getattr(default, f.name), f.name
    strings = ParameterType.PARAMETER_STRING_ARRAY
    for name, bad, why in (
            ("feedback_pathways", value(strings, string_array_value=["lateral", "sideways"]), "sideways"),
            ("feedback.gain_scale", value(ParameterType.PARAMETER_DOUBLE, double_value=math.nan),
             "feedback.gain_scale must be finite"),
            ("feedback.reset_strength", value(ParameterType.PARAMETER_DOUBLE, double_value=1.5),
             "reset_strength"),
            ("feedback.lateral_mode", value(ParameterType.PARAMETER_STRING, string_value="sideways"),
             "lateral_mode"),
            ("sensor_timeout", value(ParameterType.PARAMETER_DOUBLE, double_value=-1.0), "sensor_timeout"),
            ("feedback", value(ParameterType.PARAMETER_STRING, string_value="yes"), "")):
        result = probe.set_param("cpg", name, bad)
        assert not result.successful and why in result.reason and result.reason, (name, result.reason)
    try:  # FeedbackConfig's own wording comes back (whatever the core says about the value)
        FeedbackConfig.load(reset_strength=1.5)
    except ValueError as exc:
        assert str(exc) in probe.set_param("cpg", "feedback.reset_strength", value(
            ParameterType.PARAMETER_DOUBLE, double_value=1.5)).reason
    only_lateral = value(strings, string_array_value=["lateral"])
    assert probe.set_param("cpg", "feedback_pathways", only_lateral).successful
    assert probe.set_param("cpg", "feedback.gain_scale", 0.02).successful
    assert from_parameter_value(probe.get_params("cpg", ["feedback.gain_scale"])[0]) == 0.02

    stand_in = StandIn(probe)
    probe.wait_endpoints(ifc.CLOCK, 1, 1)
    probe.wait_endpoints(ifc.IMU, 1, 1)
    diags = lambda: [d for _, m in probe.received[ifc.DIAGNOSTICS] if (d := _diag_values(m))]  # noqa: E731

    def until(pred, what: str) -> tuple[float, dict]:
        probe.wait(lambda: any(pred(t, v) for t, v in diags()), lambda: f"{what}: {diags()[-3:]}\n"
                   f"{cpg.log()[-1500:]}", START_S, each=stand_in.tick)
        return next((t, v) for t, v in diags() if pred(t, v))

    t, v = until(lambda t, v: v["feedback"] == "active" and float(v["feedback_weight"]) == 1.0,
                 "active at weight 1")
    assert v["feedback_pathways"] == "lateral" and t >= 0.3 - 1e-9  # faded in over feedback_fade
    stand_in.bad_imu = "nan"
    until(lambda t, v: int(v["sensors_dropped"]) >= 1, "a NaN /imu dropped")
    stand_in.bad_imu = "frame"
    until(lambda t, v: int(v["sensors_dropped"]) >= 2, "a wrong-frame /imu dropped")
    stand_in.send_imu = False
    t_stop = stand_in.now()
    until(lambda t, v: t > t_stop and v["feedback"] == "fading", "fading")
    t_stale, v = until(lambda t, v: t > t_stop and v["feedback"] == "stale", "stale")
    assert float(v["feedback_weight"]) == 0.0 and float(v["sensor_age_s"]) > 0.05
    assert t_stale - t_stop == pytest.approx(0.05 + 0.3, abs=0.15)  # timeout, then the fade
    stand_in.send_imu = True
    t_back = stand_in.now()
    until(lambda t, v: t > t_back and v["feedback"] == "active" and float(v["feedback_weight"]) == 1.0,
          "active again at weight 1")
    log = cpg.log()
    assert "dropped /imu: non-finite" in log and "dropped /imu: frame 'base_link'" in log, log[-2000:]
    assert "feedback active -> fading" in log and "fading -> stale" in log
    targets = [m for _, m in probe.received[ifc.JOINT_TARGETS]]
    assert targets and all(np.isfinite(m.position).all() and np.isfinite(m.velocity).all() for m in targets)


@pytest.mark.ros
@pytest.mark.slow
def test_a_re_sent_tick_is_answered_again_the_first_one_too(graph, probe):
    """A lockstep sim re-sends an unanswered state; cpg_node answers a re-sent tick with its target again,
    identical. The first tick too: it has no lookahead target before it, and a lost first target (a
    relay's drop, a subscriber still being matched) left pid_node waiting its whole startup_wait. A
    /clock stamped before 0 is dropped with a warning (it ended the node once, in the fuzz test)."""
    from sensor_msgs.msg import JointState

    cpg = graph.start("cpg_node", feedback=False)
    probe.listen(ifc.JOINT_TARGETS, JointState, 500)
    stand_in = StandIn(probe, dt=0.002)
    probe.wait_endpoints(ifc.CLOCK, 1, 1)
    probe.wait_endpoints(ifc.JOINT_TARGETS, 1, 1)

    def answers(k: int) -> list:
        return [m for _, m in probe.received[ifc.JOINT_TARGETS] if m.header.stamp.sec == 0
                and m.header.stamp.nanosec == round(k * stand_in.dt * 1e9)]

    def send(k: int) -> None:
        stand_in.k = k
        stand_in.tick()

    # tick 0 until cpg_node answers it (its /clock subscription comes last in its start-up), then again:
    # each re-sent tick 0 is answered again, and so is a re-sent tick 1
    probe.wait(lambda: len(answers(0)) >= 1, lambda: f"tick 0 answered\n{cpg.log()[-1500:]}", START_S,
               each=lambda: send(0))
    for k, extra in ((0, 2), (1, 2)):
        for _ in range(extra + (k == 1)):
            n = len(answers(k))
            send(k)
            probe.wait(lambda k=k, n=n: len(answers(k)) > n, lambda k=k: f"tick {k} answered again\n"
                       f"{cpg.log()[-1500:]}", START_S)
    for k in (0, 1):
        first, *again = answers(k)
        assert again and all(list(m.position) == list(first.position) for m in again), k
    # a /clock before 0 (rclpy's own use_sim_time TimeSource raises on it) is dropped, not the node's end
    bad = stand_in.Clock()
    bad.clock.sec = -5
    for _ in range(3):
        stand_in.clock.publish(bad)
    probe.wait(lambda: "dropped a message rclpy could not take" in cpg.log(), lambda: cpg.log()[-1500:],
               START_S)
    n = len(answers(1))
    send(1)
    probe.wait(lambda: len(answers(1)) > n, lambda: f"alive after the bad /clock\n{cpg.log()[-1500:]}",
               START_S)
    assert cpg.popen.poll() is None


@pytest.mark.ros
@pytest.mark.slow
def test_lockstep_walk_with_feedback_is_bit_identical_and_a_schedule_lands(tmp_path, ros_domain):
    """Two 9 s lockstep walks through sim_node + pid_node + cpg_node with feedback on (the CPG has taken
    over at 6.6 s; a phase reset comes before 8 s), the second with ``--schedule 8,1.2,1``: the change
    is sent through cpg_node's SetParameters service once the sim reaches 8 s and lands within a few
    ticks of it; up to the tick it landed after, both runs are bit-identical (lockstep: every target
    depends on the samples stamped one period before it), after it they part."""
    from cpg_walker.experiments.walk_graph import run_graph_walk
    from cpg_walker.robot.run_record import RunRecord

    runs = {}
    for tag, schedule in (("plain", None), ("scheduled", [(8.0, 1.2, 1.0)])):
        with SimWatchdog(ros_domain):
            runs[tag] = run_graph_walk(tmp_path / tag, duration=9.0, feedback=True, schedule=schedule,
                                       timeout=sim_deadline(9.0))
    for tag, report in runs.items():
        assert not report["fell"] and report["feedback"] is True, (tag, report)
        fb = report["cpg_feedback"]
        assert fb["enabled"] and fb["state"] == "active" and fb["weight"] == 1.0, fb
        assert fb["wait_timeouts"] == 0 and fb["dropped"] == 0, fb  # every tick had its own samples
        assert report["graph"]["torque_age_s"]["max"] == 0.0
    resets = runs["plain"]["cpg_feedback"]["phase_reset_times_s"]
    assert any(6.6 < t < 8.0 for t in resets), resets  # feedback acted before the change
    (entry,) = runs["scheduled"]["schedule"]
    assert entry["accepted"] and entry["sent_at_sim_s"] >= 8.0, entry
    landed_s = entry["applied_after_sim_s"]
    assert 8.0 <= landed_s <= 8.5, entry
    a, b = (RunRecord.load(tmp_path / tag / "graph_record.json") for tag in ("plain", "scheduled"))
    t = np.asarray(a.t)
    assert np.asarray(b.t).tolist() == t.tolist()
    same = t <= landed_s
    qa, qb = np.asarray(a.q), np.asarray(b.q)
    np.testing.assert_array_equal(qa[same], qb[same])  # bit-identical up to the change
    np.testing.assert_array_equal(np.asarray(a.base_xy)[same], np.asarray(b.base_xy)[same])
    assert not np.array_equal(qa[-1], qb[-1])  # ... and apart after it
