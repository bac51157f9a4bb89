"""Bad input everywhere, property-based (hypothesis) against the real nodes over DDS: the packaged graph
(sim_node in real time, pid_node, cpg_node; each started once for the module, on a domain of its own) gets
random parameter values of every type through the nodes' real set_parameters services, and malformed
messages on every topic they subscribe to. Whatever comes: no node dies, every refusal names the parameter,
read-only parameters are refused, accepted values read back, nothing non-finite reaches the simulation
(its /joint_states and /odom stay finite) and afterwards the graph still runs (the sim steps, cpg_node
publishes finite /joint_targets). Examples are derandomized (reproducible in CI) and bounded in number."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpg_walker.nodes import interface as ifc
from cpg_walker.robot.joints import JOINT_NAMES

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: Fuzzed nodes: executable -> ROS node name.
NODES = {"sim_node": "sim", "pid_node": "pid", "cpg_node": "cpg"}
#: The topics the nodes subscribe to, each fuzzed with MESSAGES_PER_TOPIC messages.
TOPICS = (ifc.JOINT_TARGETS, ifc.JOINT_TORQUES, ifc.IMU, ifc.FOOT_LOAD_LEFT, ifc.FOOT_LOAD_RIGHT, ifc.CLOCK,
          ifc.CMD_VEL, ifc.JOINT_TRAJECTORY, ifc.SIM_SERVO_HOLD)
MESSAGES_PER_TOPIC = 12
#: frame_id of the probe's own fuzzed /joint_targets (a JointState's frame is not read by pid_node), so the
#: finiteness check reads cpg_node's targets only
PROBE_FRAME = "fuzz_probe"
#: Wild values (any type) sent to randomly drawn parameters of each node (each parameter also gets one
#: value of a type other than its declared one).
RANDOM_VALUES = 15
FUZZ = settings(max_examples=15, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(
    [0.0, -0.0, 1.0, -1.0, 1e-300, 1e300, -1e300, 1e9, math.nan, math.inf, -math.inf]))
INTS = st.one_of(st.integers(-2**63, 2**63 - 1), st.integers(-3, 3))
TEXT = st.one_of(st.text(max_size=20), st.sampled_from(["", "torso", "realtime", "lockstep", "nan",
                                                        "/nonexistent.yaml", "x" * 5000]))


class Walking:
    """The module's graph: the processes, a probe on its domain and what the probe received."""

    def __init__(self, graph, probe, lock):
        self.graph, self.probe, self.lock = graph, probe, lock

    @property
    def got(self) -> dict:
        return self.probe.received

    def alive(self) -> None:
        for exe, proc in self.graph.procs.items():
            assert proc.popen.poll() is None, f"{exe} died:\n{proc.log()[-3000:]}"
            assert "Traceback" not in proc.log(), f"{exe}:\n{proc.log()[-3000:]}"

    def newest_ns(self, topic: str) -> int:
        from cpg_walker.nodes.messages import stamp_ns

        msgs = self.got[topic]
        return stamp_ns(msgs[-1][1]) if msgs else -1

    def still_runs(self) -> None:
        """The sim steps (a /joint_states newer than any so far) and cpg_node publishes /joint_targets."""
        from ros_helpers import ANSWER_S

        self.alive()
        states, targets = len(self.got[ifc.JOINT_STATES]), len(self.got[ifc.JOINT_TARGETS])
        self.probe.wait(lambda: len(self.got[ifc.JOINT_STATES]) > states + 50
                        and len(self.got[ifc.JOINT_TARGETS]) > targets + 50,
                        "50 more /joint_states and /joint_targets", ANSWER_S)
        self.alive()


@pytest.fixture(scope="module")
def walking():
    """sim_node (real time), pid_node and cpg_node from their packaged files, started once for the module
    on a domain reserved for it, with a probe listening to their outputs; all stopped at the end."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from ros_helpers import START_S, Probe, kill_nodes, reserve_domain
    from sensor_msgs.msg import JointState

    from cpg_walker.graph.processes import Graph

    domain, lock = reserve_domain()
    graph = Graph(Path(tempfile.mkdtemp(prefix="fuzz_logs_")), domain_id=domain)
    probe = Probe(domain)
    try:
        for topic, cls in ((ifc.JOINT_STATES, JointState), (ifc.JOINT_TARGETS, JointState),
                           (ifc.JOINT_TORQUES, JointState), (ifc.DIAGNOSTICS, DiagnosticArray),
                           (ifc.ODOM_GROUND_TRUTH, Odometry)):
            probe.listen(topic, cls, 1000)
        graph.start("pid_node")
        graph.start("cpg_node")
        graph.start("sim_node")
        probe.wait(lambda: len(probe.received[ifc.JOINT_TARGETS]) > 10
                   and len(probe.received[ifc.JOINT_STATES]) > 10, "the graph running", START_S)
        yield Walking(graph, probe, lock)
    finally:
        probe.close()
        graph.stop_all(timeout=5.0)
        kill_nodes(domain)
        lock.close()


# ------------------------------------------------------------------------------------- parameters

def _values():
    """A ParameterValue of any type (the declared one or not), with wild contents."""
    from rcl_interfaces.msg import ParameterType as T
    from rcl_interfaces.msg import ParameterValue

    def pv(kind, **kw):
        return ParameterValue(type=kind, **kw)

    arrays = st.lists(FLOATS, max_size=6)
    return st.one_of(
        FLOATS.map(lambda x: pv(T.PARAMETER_DOUBLE, double_value=x)),
        INTS.map(lambda x: pv(T.PARAMETER_INTEGER, integer_value=x)),
        st.booleans().map(lambda x: pv(T.PARAMETER_BOOL, bool_value=x)),
        TEXT.map(lambda x: pv(T.PARAMETER_STRING, string_value=x)),
        arrays.map(lambda x: pv(T.PARAMETER_DOUBLE_ARRAY, double_array_value=x)),
        st.lists(INTS, max_size=4).map(lambda x: pv(T.PARAMETER_INTEGER_ARRAY, integer_array_value=x)),
        st.lists(st.booleans(), max_size=4).map(lambda x: pv(T.PARAMETER_BOOL_ARRAY, bool_array_value=x)),
        st.lists(TEXT, max_size=3).map(lambda x: pv(T.PARAMETER_STRING_ARRAY, string_array_value=x)),
        st.binary(max_size=8).map(lambda x: pv(T.PARAMETER_BYTE_ARRAY, byte_array_value=list(x))),
        st.just(pv(T.PARAMETER_NOT_SET)),
    )


def _describe(probe, node: str) -> dict:
    """name -> (ParameterDescriptor, current ParameterValue) of every parameter of /node."""
    from rcl_interfaces.srv import DescribeParameters, ListParameters

    names = list(_call(probe, ListParameters, f"/{node}/list_parameters",
                       ListParameters.Request()).result.names)
    described = _call(probe, DescribeParameters, f"/{node}/describe_parameters",
                      DescribeParameters.Request(names=names)).descriptors
    values = probe.get_params(node, names)
    return {d.name: (d, v) for d, v in zip(described, values, strict=True)}


def _call(probe, srv_type, name: str, request):
    """``request`` to the service ``name``; its response."""
    from ros_helpers import START_S

    client = probe.node.create_client(srv_type, name)
    assert client.wait_for_service(timeout_sec=START_S), f"service {name} not available"
    future = client.call_async(request)
    probe.wait(future.done, f"an answer from {name}")
    return future.result()


def _same(a, b) -> bool:
    from cpg_walker.graph.ros2cli import from_parameter_value

    x, y = from_parameter_value(a), from_parameter_value(b)
    return a.type == b.type and (x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)))


@pytest.mark.parametrize("exe", list(NODES))
def test_random_parameter_values_are_refused_with_a_reason_or_read_back(walking, exe):
    node = NODES[exe]
    params = _describe(walking.probe, node)
    assert params, node
    names = sorted(n for n in params if n != "use_sim_time")  # flipping the clock source is not fuzzed

    def check(name, value):
        desc, original = params[name]
        result = walking.probe.set_param(node, name, value)
        if result.successful:
            assert not desc.read_only, (node, name, "a read-only parameter was changed")
            (back,) = walking.probe.get_params(node, [name])
            assert _same(back, value), (node, name, back, value)
            restored = walking.probe.set_param(node, name, original)
            assert restored.successful, (node, name, restored.reason)
        else:
            assert result.reason.strip(), (node, name, value, "refused without a reason")
            assert name in result.reason, (node, name, result.reason)

    from rcl_interfaces.msg import ParameterType as T
    from rcl_interfaces.msg import ParameterValue

    for name in names:  # every parameter: a value of another type is refused, naming it
        desc = params[name][0]
        if desc.type == T.PARAMETER_STRING:
            wrong = ParameterValue(type=T.PARAMETER_DOUBLE, double_value=math.nan)
        else:
            wrong = ParameterValue(type=T.PARAMETER_STRING, string_value="wild")
        result = walking.probe.set_param(node, name, wrong)
        assert not result.successful and name in result.reason, (node, name, result.reason)

    # then wild values of any type on randomly drawn parameters: refused with a reason, or read back
    settings(FUZZ, max_examples=RANDOM_VALUES)(given(name=st.sampled_from(names), value=_values())(check))()
    # every parameter still holds its value from before, and the graph still runs
    now = _describe(walking.probe, node)
    for name in names:
        assert _same(now[name][1], params[name][1]), (node, name, now[name][1], params[name][1])
    walking.still_runs()


# --------------------------------------------------------------------------------------- messages

def _stamps():
    """(sec, nanosec) of a header stamp: zero, now-ish, far past or future, the extremes of the fields."""
    return st.tuples(st.one_of(st.integers(-2**31, 2**31 - 1), st.sampled_from([0, 1, 5, -1, 2**31 - 1])),
                     st.one_of(st.integers(0, 2**32 - 1), st.just(0)))


def _names():
    from cpg_walker.robot.frames import IMU_FRAME

    known = st.sampled_from([*JOINT_NAMES, "no_such_joint", "", IMU_FRAME])
    return st.one_of(st.just(list(JOINT_NAMES)), st.lists(known, max_size=30),
                     st.lists(st.sampled_from(JOINT_NAMES), min_size=1, max_size=25, unique=True))


def _sized(names: list[str]):
    """Values for ``names``: as many, one more or fewer, none; floats of any kind."""
    n = len(names)
    return st.sampled_from(sorted({0, n, n + 1, max(n - 1, 0)})).flatmap(
        lambda k: st.lists(FLOATS, min_size=k, max_size=k))


def _joint_state(draw) -> object:
    from sensor_msgs.msg import JointState

    names = draw(_names())
    msg = JointState(name=names, position=draw(_sized(names)), velocity=draw(_sized(names)),
                     effort=draw(_sized(names)))
    msg.header.stamp.sec, msg.header.stamp.nanosec = draw(_stamps())
    return msg


@st.composite
def _messages(draw, topic: str | None = None) -> tuple[str, object]:
    """(topic, message) for ``topic`` (None: any of TOPICS), with malformed or wild contents."""
    from geometry_msgs.msg import Twist, WrenchStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Bool
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from cpg_walker.robot.frames import FOOT_LOAD_FRAMES, IMU_FRAME

    topic = topic or draw(st.sampled_from(TOPICS))
    if topic in (ifc.JOINT_TARGETS, ifc.JOINT_TORQUES):
        msg = _joint_state(draw)
    elif topic == ifc.IMU:
        msg = Imu()
        msg.header.frame_id = draw(st.one_of(st.just(IMU_FRAME), TEXT))
        o, w = msg.orientation, msg.angular_velocity
        o.x, o.y, o.z, o.w = draw(st.one_of(st.tuples(FLOATS, FLOATS, FLOATS, FLOATS),
                                            st.just((0.0, 0.0, 0.0, 1.0))))
        w.x, w.y, w.z = draw(st.tuples(FLOATS, FLOATS, FLOATS))
    elif topic.startswith("/foot_load/"):
        msg = WrenchStamped()
        frames = [frame for _, frame in FOOT_LOAD_FRAMES]
        msg.header.frame_id = draw(st.one_of(st.sampled_from(frames), TEXT))
        f = msg.wrench.force
        f.x, f.y, f.z = draw(st.tuples(FLOATS, FLOATS, FLOATS))
    elif topic == ifc.CLOCK:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = draw(_stamps())
        return topic, msg
    elif topic == ifc.SIM_SERVO_HOLD:  # a Bool cannot be malformed: a wild sequence (re-entries, no crash)
        return topic, Bool(data=draw(st.booleans()))
    elif topic == ifc.CMD_VEL:
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = draw(st.tuples(FLOATS, FLOATS, FLOATS))
        return topic, msg
    else:
        msg = JointTrajectory(joint_names=draw(_names()))
        for _ in range(draw(st.integers(0, 4))):
            point = JointTrajectoryPoint(positions=draw(_sized(msg.joint_names)),
                                         velocities=draw(_sized(msg.joint_names)))
            point.time_from_start.sec, point.time_from_start.nanosec = draw(_stamps())
            msg.points.append(point)
    msg.header.stamp.sec, msg.header.stamp.nanosec = draw(_stamps())
    return topic, msg


def _finite_state(msg) -> bool:
    return all(math.isfinite(x) for x in (*msg.position, *msg.velocity, *msg.effort))


def _finite_odom(msg) -> bool:
    p, q, v, w = (msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist.linear,
                  msg.twist.twist.angular)
    return all(math.isfinite(x) for x in (p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z))


def _cpg_diagnostics(walking) -> dict:
    """The newest /diagnostics key-values of cpg_node (those with ``cmd_vel_dropped``)."""
    for _, msg in reversed(walking.got[ifc.DIAGNOSTICS]):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "cmd_vel_dropped" in values:
                return values
    return {}


def test_malformed_messages_on_every_topic_never_reach_the_simulation(walking):
    from geometry_msgs.msg import Twist, WrenchStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import Bool
    from trajectory_msgs.msg import JointTrajectory

    types = {ifc.JOINT_TARGETS: JointState, ifc.JOINT_TORQUES: JointState, ifc.IMU: Imu,
             ifc.FOOT_LOAD_LEFT: WrenchStamped, ifc.FOOT_LOAD_RIGHT: WrenchStamped, ifc.CLOCK: Clock,
             ifc.CMD_VEL: Twist, ifc.JOINT_TRAJECTORY: JointTrajectory, ifc.SIM_SERVO_HOLD: Bool}
    latched = ifc.latched_qos()  # as the sim's
    probe = walking.probe
    pubs = {topic: probe.node.create_publisher(cls, topic, latched if cls is Bool else 10)
            for topic, cls in types.items()}
    for topic in types:
        probe.wait_endpoints(topic, subscribers=1)
    # matched, not only seen in the graph: once, with two suites side by side, cpg_node heard none of this
    # probe's /cmd_vel and /sim/servo_hold (0 received in 90 s) while its /imu arrived
    matched = lambda: {topic: pub.get_subscription_count() for topic, pub in pubs.items()}  # noqa: E731
    probe.wait(lambda: min(matched().values()) >= 1, lambda: f"every publisher matched: {matched()}")
    sent: dict[str, int] = {}

    def check(item):
        topic, msg = item
        if topic == ifc.JOINT_TARGETS:  # marked: the probe hears its own, late now and then (1000/s of
            msg.header.frame_id = PROBE_FRAME  # cpg_node's queue ahead of them)
        pubs[topic].publish(msg)
        sent[topic] = sent.get(topic, 0) + 1
        probe.spin_for(0.005)

    for topic in TOPICS:  # every topic its share of examples
        settings(FUZZ, max_examples=MESSAGES_PER_TOPIC)(given(item=_messages(topic))(check))()
    probe.spin_for(0.5)
    walking.got[ifc.JOINT_TARGETS].clear()  # the probe's own ones: from here on only cpg_node's
    # a NaN /cmd_vel and a NaN /imu are dropped and counted in cpg_node's diagnostics
    before = _cpg_diagnostics(walking)
    bad_cmd = Twist()
    bad_cmd.linear.x = math.nan
    pubs[ifc.CMD_VEL].publish(bad_cmd)
    bad_imu = Imu()
    bad_imu.orientation.w = math.nan
    pubs[ifc.IMU].publish(bad_imu)
    probe.wait(lambda: int(_cpg_diagnostics(walking).get("cmd_vel_dropped", 0))
               > int(before.get("cmd_vel_dropped", 0))
               and int(_cpg_diagnostics(walking).get("sensors_dropped", 0))
               > int(before.get("sensors_dropped", 0)),
               lambda: f"the drops counted in cpg_node's /diagnostics: {_cpg_diagnostics(walking)}")
    walking.still_runs()
    assert set(sent) == set(types) == set(TOPICS), sent
    sim = [{kv.key: kv.value for kv in st.values} for _, m in walking.got[ifc.DIAGNOSTICS] for st in m.status
           if st.name == "cpg_walker/sim"]
    assert sim and int(sim[-1]["torques_rejected"]) > 0, sim[-1:]  # the sim counts what it refused
    states = [m for _, m in walking.got[ifc.JOINT_STATES]]
    assert states and all(_finite_state(m) for m in states)
    odom = [m for _, m in walking.got[ifc.ODOM_GROUND_TRUTH]]
    assert odom and all(_finite_odom(m) for m in odom)
    targets = [m for _, m in walking.got[ifc.JOINT_TARGETS] if m.header.frame_id != PROBE_FRAME]
    bad = [m for m in targets if not _finite_state(m)]
    assert targets and not bad, bad[:2]
    for exe in walking.graph.procs:  # the refusals were logged, throttled per reason
        assert "rejected" in walking.graph.procs[exe].log() or exe == "cpg_node", exe
