"""Multi-process tests of the ROS graph: real node processes over real DDS, each test on a DDS domain of
its own (reserved machine-wide) with localhost-only discovery; every process is stopped (SIGINT, then
SIGKILL) by the fixture's teardown even when the test fails (fixtures ``graph``, ``probe``: conftest.py).
Waits are for conditions, with hang-guard deadlines; rates are checked in sim time (ros_helpers.py)."""

from __future__ import annotations

import json
import math
import os
import re
import signal

import numpy as np
import pytest
from ros_helpers import ANSWER_S, START_S, Probe, double, sim_deadline, string

from cpg_walker.graph.processes import Graph
from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.messages import stamp_ns
from cpg_walker.robot.joints import JOINT_NAMES

pytestmark = [pytest.mark.ros, pytest.mark.slow]

HEAD = JOINT_NAMES.index("head_joint_1")
CONTROL_NS = 2_000_000  # the sim's control period (default control_period 0.002 s)
#: The sim waits for each period's torque and pid_node answers every state with its latest target: the
#: robot's loop then has no wall-clock delays (in real time pacing a loaded machine delays the torques,
#: and the head's servo rings), while targets still come from the test at wall-clock times.
CLOSED_LOOP = "lockstep"


def _wait_matched(probe: Probe, *publishers) -> None:
    """Wait until every publisher has a matched subscriber (messages sent before are lost)."""
    probe.wait(lambda: all(p.get_subscription_count() > 0 for p in publishers), "subscribers matched",
               START_S)


def _head(probe: Probe) -> float:
    return float(probe.received[ifc.JOINT_STATES][-1][1].position[HEAD])


def _settled(probe: Probe, q: float, tol: float, sim_s: float = 0.5) -> bool:
    """The head has been within ``tol`` of ``q`` in every state received over the last ``sim_s`` sim s."""
    states = probe.received[ifc.JOINT_STATES]
    if not states:
        return False
    since = _sim_now(probe) - round(sim_s * 1e9)
    recent = [m for _, m in states if stamp_ns(m) >= since]
    return (stamp_ns(states[0][1]) <= since
            and all(abs(m.position[HEAD] - q) < tol for m in recent))


def _sim_now(probe: Probe) -> int:
    """The latest /joint_states stamp received (ns of sim time)."""
    return stamp_ns(probe.received[ifc.JOINT_STATES][-1][1])


def _span_ns(received: list) -> int:
    """Sim time between the first and the last stamped message received (0 with fewer than two)."""
    return stamp_ns(received[-1][1]) - stamp_ns(received[0][1]) if received else 0


def _assert_every_period(stamps: list[int], period_ns: int, topic: str) -> None:
    """Published once per ``period_ns`` of sim time: stamps never go back, the distinct ones step in
    whole periods and some two received in a row are one period apart. Robust to messages the probe
    missed (a miss lengthens a step, it cannot make one shorter; a publisher at a lower sim rate has no
    one-period step) and to the sim's re-sends of a state its controller has not answered yet (the same
    stamp again)."""
    stamps = np.asarray(stamps, dtype=np.int64)
    assert len(stamps) > 1 and (np.diff(stamps) >= 0).all(), (topic, stamps[:20])
    steps = np.diff(np.unique(stamps))
    assert len(steps) > 0 and (steps % period_ns == 0).all() and steps.min() == period_ns, \
        (topic, np.unique(steps)[:10])


def test_topics_types_rates_services_and_fall_status(graph, probe):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import WrenchStamped
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import Bool
    from std_srvs.srv import Trigger

    expected = {
        ifc.CLOCK: Clock, ifc.JOINT_STATES: JointState, ifc.JOINT_TORQUES: JointState, ifc.IMU: Imu,
        ifc.FOOT_LOAD_LEFT: WrenchStamped, ifc.FOOT_LOAD_RIGHT: WrenchStamped,
        ifc.ODOM_GROUND_TRUTH: Odometry, ifc.DIAGNOSTICS: DiagnosticArray,
    }
    for topic, msg_type in expected.items():
        probe.listen(topic, msg_type, qos=2000)
    latched = ifc.latched_qos()
    probe.listen(ifc.SIM_FALLEN, Bool, qos=latched)
    graph.start("pid_node")
    graph.start("sim_node", pacing=CLOSED_LOOP, push__force=[0.0, 120.0, 0.0], push__duration=0.3)
    got = probe.received
    # discovery matches each endpoint pair on its own (occasionally seconds apart): wait for all
    probe.wait(lambda: all(len(got[t]) > 0 for t in [*expected, ifc.SIM_FALLEN]),
               lambda: f"a message on every topic: {({t: len(v) for t, v in got.items()})}", START_S)
    # sim-time rates: collect one sim second of every topic (by stamps, whatever the wall time it takes)
    periodic = {ifc.JOINT_STATES: CONTROL_NS, ifc.JOINT_TORQUES: CONTROL_NS, ifc.IMU: CONTROL_NS,
                ifc.FOOT_LOAD_LEFT: CONTROL_NS, ifc.FOOT_LOAD_RIGHT: CONTROL_NS,
                ifc.ODOM_GROUND_TRUTH: 5 * CONTROL_NS}  # odom_period 0.01 s
    earlier = {t: [stamp_ns(m) for _, m in got[t]] for t in (ifc.JOINT_STATES, ifc.JOINT_TORQUES)}
    for topic in [*periodic, ifc.CLOCK]:
        got[topic].clear()
    probe.wait(lambda: all(_span_ns(got[t]) >= 1_000_000_000 for t in periodic) and got[ifc.CLOCK],
               lambda: f"1 sim s on every topic: {({t: _span_ns(got[t]) / 1e9 for t in periodic})}")
    types = dict(probe.node.get_topic_names_and_types())
    for topic, msg_type in expected.items():
        name = f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"
        assert name in types.get(topic, []), f"{topic}: {types.get(topic)}"
    js = [m for _, m in got[ifc.JOINT_STATES]]
    assert list(js[-1].name) == list(JOINT_NAMES)
    assert len(js[-1].position) == len(js[-1].velocity) == len(js[-1].effort) == 25
    # one state (with its IMU sample, sole loads) per 2 ms control period, odometry at 100 Hz of sim time
    for topic, period in periodic.items():
        _assert_every_period([stamp_ns(m) for _, m in got[topic]], period, topic)
    clock = [m.clock.sec * 1_000_000_000 + m.clock.nanosec for _, m in got[ifc.CLOCK]]
    _assert_every_period(clock, CONTROL_NS, ifc.CLOCK)
    # torques answer states: stamped with the stamps of the states (on the 2 ms grid, every period); over
    # the whole run (a probe that falls behind a fast sim reads each topic's backlog from another point)
    def seen(topic: str) -> set[int]:
        return {*earlier[topic], *(stamp_ns(m) for _, m in got[topic])}

    # the two backlogs may not overlap yet (CI once: every torque seen was newer than every state seen):
    # spin on until they do, the sim going on
    probe.wait(lambda: seen(ifc.JOINT_STATES) & seen(ifc.JOINT_TORQUES),
               lambda: f"a torque stamped as a state seen: states up to {max(seen('/joint_states'))}, "
                       f"torques from {min(seen('/joint_torques'))}")
    assert all(t % CONTROL_NS == 0 for t in seen(ifc.JOINT_TORQUES))
    imu = got[ifc.IMU][-1][1]
    assert imu.header.frame_id == "imu"
    assert imu.linear_acceleration.z == pytest.approx(9.81, abs=1.0)  # standing still, specific force
    assert all(imu.angular_velocity_covariance[i] > 0 for i in (0, 4, 8))
    total = sum(got[ifc.foot_load_topic(s)][-1][1].wrench.force.z for s in ifc.FOOT_LOAD_SIDES)
    assert total == pytest.approx(7.16 * 9.81, rel=0.15)
    odom = got[ifc.ODOM_GROUND_TRUTH][-1][1]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert 0.25 < odom.pose.pose.position.z < 0.32
    assert got[ifc.SIM_FALLEN][-1][1].data is False
    diag = got[ifc.DIAGNOSTICS][-1][1].status[0]
    assert diag.name == "cpg_walker/sim" and diag.level == DiagnosticStatus.OK
    # push (120 N sideways for 0.3 s) topples the robot; the fall is reported, reset stands it up
    assert probe.call(Trigger, "/sim/push").success
    probe.wait(lambda: got[ifc.SIM_FALLEN][-1][1].data, "a fall reported on /sim/fallen")
    # the fall in /diagnostics too, and no report stamped after it says otherwise (messages of different
    # topics may arrive in any order: an older OK report can come in after /sim/fallen)
    errors = lambda: [stamp_ns(m) for _, m in got[ifc.DIAGNOSTICS]  # noqa: E731
                      if m.status[0].level == DiagnosticStatus.ERROR]
    probe.wait(lambda: errors(), "/diagnostics reporting the fall")
    after = [m.status[0] for _, m in got[ifc.DIAGNOSTICS] if stamp_ns(m) >= min(errors())]
    assert all(st.level == DiagnosticStatus.ERROR and st.message == "fallen" for st in after), after
    reset = probe.call(Trigger, "/sim/reset")
    assert reset.success, reset.message
    reset_ns = round(float(re.search(r"at sim time ([0-9.]+) s", reset.message).group(1)) * 1e9)
    probe.wait(lambda: not got[ifc.SIM_FALLEN][-1][1].data, "/sim/fallen false after the reset")
    probe.wait(lambda: stamp_ns(got[ifc.ODOM_GROUND_TRUTH][-1][1]) > reset_ns, "odometry after the reset")
    assert got[ifc.ODOM_GROUND_TRUTH][-1][1].pose.pose.position.z > 0.25


def test_realtime_pacing_publishes_every_period_of_sim_time(graph, probe):
    """In real-time pacing the sim keeps its schedule in sim time whatever the wall clock does: a state and
    a clock tick per 2 ms period, its pacing and achieved speed in the diagnostics. (How close to real time
    it runs, and how much of it reaches another process: the benchmark's graph section.)"""
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    probe.listen(ifc.JOINT_STATES, JointState, 2000)
    probe.listen(ifc.CLOCK, Clock, 2000)
    probe.listen(ifc.DIAGNOSTICS, DiagnosticArray, 50)
    graph.start("pid_node")
    graph.start("sim_node", pacing="realtime")
    got = probe.received
    probe.wait(lambda: len(got[ifc.JOINT_STATES]) > 0, ifc.JOINT_STATES, START_S)
    got[ifc.JOINT_STATES].clear()
    def sim_diagnostics() -> list[dict]:
        """The sim's diagnostics sent after it had run (the one sent at start-up reports 0 s and speed 0)."""
        sent = [{kv.key: kv.value for kv in m.status[0].values} for _, m in list(got[ifc.DIAGNOSTICS])]
        return [v for v in sent if "pacing" in v and float(v["sim_time_s"]) > 0]

    probe.wait(lambda: _span_ns(got[ifc.JOINT_STATES]) >= 1_000_000_000 and got[ifc.CLOCK]
               and sim_diagnostics(), "1 sim s of /joint_states, /clock, and /diagnostics after t = 0")
    _assert_every_period([stamp_ns(m) for _, m in got[ifc.JOINT_STATES]], CONTROL_NS, ifc.JOINT_STATES)
    clock = [m.clock.sec * 1_000_000_000 + m.clock.nanosec for _, m in got[ifc.CLOCK]]
    _assert_every_period(clock, CONTROL_NS, ifc.CLOCK)
    values = sim_diagnostics()[-1]
    assert values["pacing"] == "realtime" and float(values["real_time_factor"]) > 0, values


def _lockstep_run(graph: Graph, probe: Probe, tmp_path, tag: str, duration: float) -> dict:
    record = tmp_path / f"record_{tag}.json"
    try:
        # target_wait: pid_node's wall-clock watchdog would answer a period without its target if the
        # player stalled half a second on a loaded machine; a wall-clock event, not lockstep's determinism
        graph.start("pid_node", lockstep=True, wait_for_targets=True, target_wait=ANSWER_S,
                    startup_wait=START_S)
        graph.start("target_player_node")
        probe.wait_endpoints(ifc.JOINT_TARGETS)  # player -> pid, and the player's /clock subscription
        probe.wait_endpoints(ifc.CLOCK, publishers=0)
        graph.start("sim_node", pacing="lockstep", duration=duration, record_path=str(record),
                    record_period=0.002)
        assert graph.wait("sim_node", timeout=sim_deadline(duration)) == 0
    finally:
        graph.stop_all()
    return json.loads(record.read_text())


def test_lockstep_runs_are_identical(graph, probe, tmp_path):
    first = _lockstep_run(graph, probe, tmp_path, "a", 1.5)
    # the first graph's nodes gone from the graph before the second's start (or the waits see them)
    probe.wait(lambda: probe.node.count_subscribers(ifc.JOINT_TARGETS) == 0
               and probe.node.count_publishers(ifc.JOINT_TARGETS) == 0, "the first graph gone")
    second = _lockstep_run(Graph(tmp_path / "logs_b", domain_id=graph.domain_id), probe, tmp_path, "b", 1.5)
    qa, qb = np.array(first["q"]), np.array(second["q"])
    assert qa.shape == qb.shape == (750, 25)
    assert np.ptp(qa[:, JOINT_NAMES.index("lleg_joint_3")]) > 0.05  # the robot really moved
    np.testing.assert_array_equal(qa, qb)  # bit-identical joint trajectories
    np.testing.assert_array_equal(np.array(first["base_xy"]), np.array(second["base_xy"]))
    assert first["stats"]["torque_age_s"]["max"] == 0.0  # every period used its own command


def test_watchdog_holds_the_last_target_posture(graph, probe):
    from sensor_msgs.msg import JointState

    probe.listen(ifc.JOINT_STATES, JointState, qos=100)
    pub = probe.node.create_publisher(JointState, ifc.JOINT_TARGETS, 10)
    graph.start("pid_node", target_timeout=0.05)
    graph.start("sim_node", pacing=CLOSED_LOOP)
    probe.wait(lambda: len(probe.received[ifc.JOINT_STATES]) > 10, ifc.JOINT_STATES, START_S)
    _wait_matched(probe, pub)
    target = JointState(name=["head_joint_1"], position=[0.4])
    probe.wait(lambda: _settled(probe, 0.4, 0.05), lambda: f"head settled at 0.4: {_head(probe)}",
               each=lambda: pub.publish(target))
    pid = graph.procs["pid_node"]
    last_target_ns = _sim_now(probe)
    # no more targets: once 1 sim s (20x the timeout) has passed, the watchdog has tripped (its last word
    # is a trip, not "targets resumed": with the sim this fast it may trip between the test's targets too)
    probe.wait(lambda: _sim_now(probe) > last_target_ns + 1_000_000_000, "1 sim s without targets")
    events = lambda: re.findall(r"targets (stale|still stale|resumed)", pid.log())  # noqa: E731
    probe.wait(lambda: events() and events()[-1] != "resumed", lambda: f"a trip: {pid.log()[-1500:]}")
    assert "holding the last target posture" in pid.log()
    assert _settled(probe, 0.4, 0.05), _head(probe)  # held, not back to the default posture (0)
    assert graph.procs["sim_node"].popen.poll() is None
    for proc in graph.procs.values():  # SIGTERM: a clean exit, status 0, no traceback
        os.kill(proc.pid, signal.SIGTERM)
    for proc in graph.procs.values():
        assert proc.popen.wait(timeout=ANSWER_S) == 0, proc.log()[-1500:]
        assert "Traceback" not in proc.log()


def test_bad_messages_never_reach_the_robot(graph, probe):
    from sensor_msgs.msg import JointState

    probe.listen(ifc.JOINT_STATES, JointState, qos=100)
    targets = probe.node.create_publisher(JointState, ifc.JOINT_TARGETS, 10)
    torques = probe.node.create_publisher(JointState, ifc.JOINT_TORQUES, 10)
    graph.start("pid_node")
    graph.start("sim_node", pacing=CLOSED_LOOP)
    probe.wait(lambda: len(probe.received[ifc.JOINT_STATES]) > 10, ifc.JOINT_STATES, START_S)
    _wait_matched(probe, targets, torques)
    rest, bad_from = _head(probe), _sim_now(probe)
    bad = [
        JointState(name=["head_joint_1", "head_joint_2"], position=[0.6, math.nan]),
        JointState(name=["head_joint_1", "tail_joint"], position=[0.6, 0.0]),
        JointState(name=["head_joint_1", "head_joint_2"], position=[0.6]),
        JointState(name=["head_joint_1"], position=[0.6], velocity=[math.inf]),
    ]
    reasons = ("non-finite position", "unknown joint", "position has 1 values for 2", "non-finite velocity")
    pid, sim = graph.procs["pid_node"], graph.procs["sim_node"]

    def send_bad() -> None:
        for msg in bad:
            targets.publish(msg)
        torques.publish(JointState(name=["head_joint_1"], effort=[math.nan]))

    def repeated(reason: str) -> list[int]:
        """How many rejections each repeated warning of ``reason`` says it stood for besides itself."""
        pattern = rf"rejected /joint_targets: {re.escape(reason)}[^\n]*\((\d+) more since"
        return [int(n) for n in re.findall(pattern, pid.log())]

    def throttled(reason: str) -> bool:
        """The warnings of ``reason`` stand for more rejections than they are (counted in the repeats)."""
        return sum(repeated(reason)) > pid.log().count(f"rejected /joint_targets: {reason}")

    # every reason rejected, and rejected again after the throttle's period: warnings with counts, which
    # (throttled per reason) stand for more rejections than there are warnings — however slowly the
    # bad messages go out on a busy machine (a slow sender had 1 repeat behind 2 warnings)
    probe.wait(lambda: all(throttled(r) for r in reasons)
               and "rejected /joint_torques: non-finite effort" in sim.log(),
               lambda: f"every rejection, repeated: {pid.log()[-1500:]}\n{sim.log()[-500:]}", each=send_bad)
    moved = [(stamp_ns(m), m.position[HEAD]) for _, m in probe.received[ifc.JOINT_STATES]
             if stamp_ns(m) >= bad_from and abs(m.position[HEAD] - rest) >= 0.02]
    assert not moved, moved[:10]  # the head stayed at rest all along
    good = JointState(name=["head_joint_1"], position=[0.6])
    probe.wait(lambda: _settled(probe, 0.6, 0.05),  # the channel works: only bad input was dropped
               lambda: f"head settled at 0.6: {_head(probe)}", each=lambda: targets.publish(good))


def test_replay_through_the_graph_walks(tmp_path):
    from cpg_walker.experiments.replay_graph import run_graph_replay

    report = run_graph_replay(tmp_path / "out", duration=6.0, pacing="lockstep", timeout=sim_deadline(6.0))
    saved = json.loads((tmp_path / "out" / "replay.json").read_text())
    for key in ("fell", "fall_time_s", "duration_s", "distance_m", "lateral_drift_m",
                "heading_change_deg", "mean_speed_mps", "steps", "real_time_factor"):
        assert key in saved
    assert report["fell"] is False and report["duration_s"] == pytest.approx(6.0, abs=0.02)
    assert report["distance_m"] > 0.3 and report["steps"] >= 3
    assert abs(report["lateral_drift_m"]) < 0.1


def test_pid_gains_are_runtime_parameters_and_validated(graph, probe):
    graph.start("pid_node")
    for bad in (math.nan, -1.0, 1e9):
        result = probe.set_param("pid", "kp.leg", double(bad))
        assert not result.successful and result.reason, bad
    wrong_type = probe.set_param("pid", "kd.arm", string("x"))
    assert not wrong_type.successful
    assert probe.set_param("pid", "kp.leg", double(120.0)).successful
    values = probe.get_params("pid", ["kp.leg", "target_timeout"])
    assert values[0].double_value == 120.0 and values[1].double_value == pytest.approx(0.1)
    # the harness sees this graph on its domain, so another graph would not pick it
    from cpg_walker.graph.processes import domain_is_quiet

    assert not domain_is_quiet(graph.domain_id, wait=ANSWER_S)


def test_lockstep_pid_stops_waiting_for_a_first_target_that_never_comes(graph, probe):
    """No target source: pid_node (lockstep, wait_for_targets) waits `startup_wait` for the first target,
    then holds the posture and answers, although the sim re-sends the state more often than that (a re-sent
    state must not restart the wait: it did, and the graph hung at 0 s)."""
    graph.start("pid_node", lockstep=True, wait_for_targets=True, startup_wait=1.0, target_wait=1.0)
    graph.start("sim_node", pacing="lockstep", duration=0.1, lockstep_resend=0.05)
    assert graph.wait("sim_node", timeout=sim_deadline(0.1)) == 0, graph.procs["sim_node"].log()[-2000:]
    pid = graph.procs["pid_node"]
    probe.wait(lambda: "targets stale" in pid.log(), "pid_node's 'targets stale' warning")


def test_robot_description_reaches_a_late_subscriber(graph, probe):
    """sim_node publishes the shipped URDF once, transient local: a subscriber that joins after it was
    published still gets it (as robot_state_publisher's and RViz's do), and it parses to the same robot.
    The sim waits for a controller (none here): the description is there before the first period."""
    import xml.etree.ElementTree as ET

    from std_msgs.msg import String

    from cpg_walker.robot.urdf import read_urdf

    graph.start("sim_node", pacing="lockstep")
    probe.wait(lambda: probe.node.count_publishers(ifc.ROBOT_DESCRIPTION) > 0,
               "sim_node's /robot_description", START_S)
    assert probe.node.count_subscribers(ifc.ROBOT_DESCRIPTION) == 0  # nobody listened when it was published
    latched = ifc.latched_qos()
    probe.listen(ifc.ROBOT_DESCRIPTION, String, qos=latched)
    probe.wait(lambda: probe.received[ifc.ROBOT_DESCRIPTION], "the URDF on /robot_description")
    text = probe.received[ifc.ROBOT_DESCRIPTION][0][1].data
    assert text == read_urdf()
    robot = ET.fromstring(text)
    assert robot.get("name") == "hoap2" and robot.find("link").get("name") == "base_link"
    assert {j.get("name") for j in robot.findall("joint") if j.get("type") != "fixed"} == set(JOINT_NAMES)
    assert graph.procs["sim_node"].popen.poll() is None
