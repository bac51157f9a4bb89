"""`cpg-walker node list|info`, `param describe|dump`, `topic info|pub`: ros2cli's verbs and output formats
without ros2cli, run as real subprocesses against a real node (pid_node) and the test's probe node on the
test's own DDS domain. Discovery is per process (no ros2 daemon): a listing is repeated until it shows
what the probe already sees, within a deadline that only guards against hangs."""

from __future__ import annotations

import re
import time

import pytest
from ros_helpers import ANSWER_S, START_S
from test_ros_cli import DISCOVERY, cli

from cpg_walker.nodes import interface as ifc


def until(ok, *args: str) -> object:
    """Run the CLI with ``args`` until ``ok(result)`` or ANSWER_S wall s have passed; the last result."""
    end = time.monotonic() + ANSWER_S
    while True:
        r = cli(*args)
        if ok(r) or time.monotonic() > end:
            return r


def sections(text: str) -> dict[str, list[str]]:
    """`node info`'s text -> section -> its ``name: type`` lines (checking the layout on the way)."""
    lines = text.split("\n")
    out: dict[str, list[str]] = {}
    current = None
    for line in lines[1:]:
        if re.fullmatch(r"  [A-Z][A-Za-z ]+:", line):
            current = line.strip()[:-1]
            out[current] = []
        elif line.startswith("    "):
            assert current is not None and re.fullmatch(r"    /\S+: \S+/\S+/\S+", line), line
            out[current].append(line.strip())
        else:
            assert line == "", f"unexpected line {line!r} in:\n{text}"  # an empty section, as ros2 prints
    return out


def test_dump_yaml_reads_back_through_rclpy_even_where_a_name_prefixes_another(tmp_path):
    """cpg_node has ``feedback`` and ``feedback.<gain>``: no nesting below a name that is a parameter."""
    from rclpy.parameter import parameter_dict_from_yaml_file

    from cpg_walker.graph.ros2cli import from_parameter_value, parameters_yaml

    values = {"feedback": True, "feedback.gain": 0.5, "feedback.sub.n": 3, "kp.leg": 100.0, "kp.arm": 30.0,
              "zeta": 0.8, "names": ["a", "b"], "gains": [1.0, 2.5]}
    text = parameters_yaml("cpg", values)
    assert text.startswith("/cpg:\n  ros__parameters:\n") and "    kp:\n      arm: 30.0\n" in text, text
    path = tmp_path / "dump.yaml"
    path.write_text(text)
    loaded = parameter_dict_from_yaml_file(str(path))
    assert {k: from_parameter_value(p.value) for k, p in loaded.items()} == values


def test_pub_values_fill_nested_messages_and_refuse_what_does_not_fit():
    """`topic pub`'s VALUES: nested dicts, lists of messages, ints for floats; a bad one names its field."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point

    from cpg_walker.graph.ros2cli_pub import build_message, qos_profile

    _, traj, stamps = build_message("trajectory_msgs/JointTrajectory",
                                    "{header: auto, joint_names: [a], points: [{positions: [1], "
                                    "time_from_start: {sec: 2}}, {positions: [0.5]}]}")
    assert list(traj.joint_names) == ["a"] and [list(p.positions) for p in traj.points] == [[1.0], [0.5]]
    assert traj.points[0].time_from_start.sec == 2 and len(stamps) == 1
    stamps[0](Time(sec=7))  # 'auto': the publish loop stamps the header of each message
    assert traj.header.stamp.sec == 7
    _, marker, _ = build_message("visualization_msgs/msg/Marker", "{points: [{x: 1}, {y: 2.5}], id: 3}")
    assert list(marker.points) == [Point(x=1.0), Point(y=2.5)] and marker.id == 3
    for type_name, values, error in (
            ("std_msgs/msg/Float64", "{data: true}", "field 'data' is a double, got True"),
            ("std_msgs/msg/Int32", "{data: 1.5}", "field 'data' is a int32, got 1.5"),
            ("std_msgs/msg/UInt8", "{data: 300}", "field 'data' is a uint8: 300 is outside [0, 255]"),
            ("sensor_msgs/msg/Imu", "{orientation_covariance: [1, 2]}",
             "field 'orientation_covariance' is a double[9]: exactly 9 items, got 2"),
            ("sensor_msgs/msg/JointState", "{position: [1, x]}", "field 'position[1]' is a double, got 'x'"),
            ("trajectory_msgs/msg/JointTrajectory", "{points: [{positons: [1]}]}",
             "no field 'points[0].positons' in trajectory_msgs/msg/JointTrajectoryPoint"),
            ("std_msgs/msg/Bool", "data: [", "the values are not YAML"),
            ("std_msgs/Strin", "{}", "std_msgs/Strin"),
            ("not_a_type", "{}", "not a message type")):
        with pytest.raises(ValueError, match=re.escape(error)):
            build_message(type_name, values)
    assert qos_profile("sensor_data", reliability="reliable", depth=3).depth == 3
    with pytest.raises(ValueError, match=r"--qos-durability 'latched' is not one of: .*transient_local"):
        qos_profile(durability="latched")


@pytest.mark.ros
@pytest.mark.slow
def test_node_param_and_topic_info_against_a_running_node(graph, probe, tmp_path):
    import yaml
    from rcl_interfaces.srv import ListParameters
    from rclpy.parameter import parameter_dict_from_yaml_file
    from sensor_msgs.msg import JointState

    from cpg_walker.graph.ros2cli import from_parameter_value
    from cpg_walker.nodes.specs import GAIN_RANGES

    graph.start("pid_node")
    probe.listen(ifc.JOINT_TORQUES, JointState)
    probe.wait_endpoints(ifc.JOINT_TORQUES, 1, 1)  # pid's publisher, the probe's subscription
    probe.wait(lambda: probe.node.count_subscribers(ifc.JOINT_TARGETS) >= 1, "pid subscribed", START_S)

    # node list: fully qualified, sorted, this tool's own node hidden
    listed = until(lambda r: {"/pid", "/probe"} <= set(r.stdout.split()), "node", "list")
    assert listed.returncode == 0, listed.stderr
    names = listed.stdout.splitlines()
    assert {"/pid", "/probe"} <= set(names) and names == sorted(names), listed.stdout
    assert not [n for n in names if n.rsplit("/", 1)[1].startswith("_")], names
    counted = until(lambda r: r.stdout.strip().isdigit() and int(r.stdout) >= 2, "node", "list", "-c")
    assert int(counted.stdout) >= 2, counted

    # node info: ros2's six sections in order, "name: type" lines at 4 spaces
    want_subs = {"/clock: rosgraph_msgs/msg/Clock", "/joint_states: sensor_msgs/msg/JointState",
                 "/joint_targets: sensor_msgs/msg/JointState",
                 "/joint_trajectory: trajectory_msgs/msg/JointTrajectory"}  # not lockstep: the horizon too
    info = until(lambda r: want_subs <= {x.strip() for x in r.stdout.splitlines()}, "node", "info", "/pid",
                 *DISCOVERY)
    assert info.returncode == 0, info.stderr
    assert info.stdout.startswith("/pid\n  Subscribers:\n"), info.stdout
    sec = sections(info.stdout)
    assert list(sec) == ["Subscribers", "Publishers", "Service Servers", "Service Clients", "Action Servers",
                         "Action Clients"], info.stdout
    assert set(sec["Subscribers"]) == want_subs, info.stdout
    assert {"/joint_torques: sensor_msgs/msg/JointState", "/rosout: rcl_interfaces/msg/Log",
            "/parameter_events: rcl_interfaces/msg/ParameterEvent"} <= set(sec["Publishers"]), info.stdout
    assert {"/pid/get_parameters: rcl_interfaces/srv/GetParameters",
            "/pid/set_parameters: rcl_interfaces/srv/SetParameters",
            "/pid/describe_parameters: rcl_interfaces/srv/DescribeParameters"} <= set(sec["Service Servers"])
    assert sec["Service Clients"] == sec["Action Servers"] == sec["Action Clients"] == [], info.stdout
    missing = cli("node", "info", "/nonexistent", "--timeout", "1")
    assert missing.returncode == 1 and "Unable to find node '/nonexistent'" in missing.stderr, missing

    # param describe: the declared descriptors in ros2's block
    described = cli("param", "describe", "/pid", "kp.leg", "realtime_priority", "lockstep", *DISCOVERY)
    assert described.returncode == 0, described.stderr
    blocks = described.stdout.split("Parameter name: ")[1:]
    assert blocks[0] == ("kp.leg\n  Type: double\n  Description: kp of the leg joint(s)\n  Constraints:\n"
                         f"    Min value: 0.0\n    Max value: {GAIN_RANGES['kp']}\n"), described.stdout
    assert blocks[1].startswith("realtime_priority\n  Type: integer\n  Description: SCHED_FIFO priority")
    assert blocks[1].endswith("  Constraints:\n    Read only: true\n    Min value: 0\n    Max value: 99\n"
                              "    Step: 1\n"), blocks[1]
    assert blocks[2].startswith("lockstep\n  Type: boolean\n") and blocks[2].endswith(
        "  Constraints:\n    Read only: true\n"), blocks[2]
    undeclared = cli("param", "describe", "/pid", "kp.leg", "no_such_gain", *DISCOVERY)
    assert undeclared.returncode == 1 and "no parameter no_such_gain" in undeclared.stderr, undeclared

    # param dump: ros__parameters YAML of every parameter, nested at the dots, equal to the node's values
    dumped = cli("param", "dump", "/pid", *DISCOVERY)
    assert dumped.returncode == 0, dumped.stderr
    assert dumped.stdout.startswith("/pid:\n  ros__parameters:\n"), dumped.stdout[:200]
    data = yaml.safe_load(dumped.stdout)
    assert list(data) == ["/pid"] and list(data["/pid"]) == ["ros__parameters"]
    assert isinstance(data["/pid"]["ros__parameters"]["kp"], dict)  # kp.leg ... nested under kp
    path = tmp_path / "pid_dump.yaml"
    path.write_text(dumped.stdout)
    loaded = parameter_dict_from_yaml_file(str(path))  # rclpy's own params-file reader
    listed_names = probe.call(ListParameters, "/pid/list_parameters").result.names
    assert sorted(loaded) == sorted(listed_names) and "kp.leg" in loaded, (sorted(loaded), listed_names)
    actual = probe.get_params("pid", sorted(loaded))
    for name, value in zip(sorted(loaded), actual, strict=True):
        assert from_parameter_value(loaded[name].value) == from_parameter_value(value), name

    # topic info: counts, then -v's endpoint blocks (rclpy's TopicEndpointInfo text)
    want = "Type: sensor_msgs/msg/JointState\nPublisher count: 1\nSubscription count: 1\n"
    plain = until(lambda r: r.stdout == want, "topic", "info", ifc.JOINT_TORQUES, *DISCOVERY)
    assert plain.returncode == 0 and plain.stdout == want, plain
    verbose = until(lambda r: "\n\nPublisher count: 1\n\n" in r.stdout and "\n\nSubscription count: 1\n\n"
                    in r.stdout, "topic", "info", "-v", ifc.JOINT_TORQUES, *DISCOVERY)
    assert verbose.returncode == 0, verbose.stderr
    parts = verbose.stdout.split("\n\n")
    assert parts[0] == "Type: sensor_msgs/msg/JointState" and parts[1] == "Publisher count: 1", parts
    assert parts[3] == "Subscription count: 1" and parts[5] == "", parts
    pub, sub = parts[2].split("\n"), parts[4].split("\n")
    assert pub[:3] == ["Node name: pid", "Node namespace: /", "Topic type: sensor_msgs/msg/JointState"], pub
    assert "Endpoint type: PUBLISHER" in pub and "QoS profile:" in pub, pub
    assert re.fullmatch(r"GID: [0-9a-f]{2}(\.[0-9a-f]{2})+", next(x for x in pub if x.startswith("GID"))), pub
    assert {"  Reliability: RELIABLE", "  Durability: VOLATILE"} <= set(pub), pub
    assert sub[0] == "Node name: probe" and "Endpoint type: SUBSCRIPTION" in sub, sub
    unknown = cli("topic", "info", "/no_such_topic", "--timeout", "1")
    assert unknown.returncode == 1 and "Unknown topic '/no_such_topic'" in unknown.stderr, unknown


@pytest.mark.ros
@pytest.mark.slow
def test_topic_pub_delivers_the_exact_message_and_refuses_bad_fields(probe):
    from geometry_msgs.msg import Twist, Vector3
    from sensor_msgs.msg import JointState

    probe.listen(ifc.CMD_VEL, Twist)
    probe.listen("/pub_states", JointState)
    got = probe.received[ifc.CMD_VEL]
    keep = ("--keep-alive", "1")  # wall s for a reliable resend should the probe match late

    once = cli("topic", "pub", ifc.CMD_VEL, "geometry_msgs/msg/Twist",
               "{linear: {x: 0.1}, angular: {z: -0.2}}", "-1", *keep)
    assert once.returncode == 0, once.stderr
    waited = "Waiting for at least 1 matching subscription(s)...\n"  # -1 waits for one by default
    shown = ("publishing #1: geometry_msgs.msg.Twist(linear=geometry_msgs.msg.Vector3(x=0.1, y=0.0, z=0.0), "
             "angular=geometry_msgs.msg.Vector3(x=0.0, y=0.0, z=-0.2))")  # the message's repr, as ros2
    assert once.stdout.replace(waited, "") == f"publisher: beginning loop\n{shown}\n\n", once.stdout
    probe.wait(lambda: len(got) >= 1, "the -1 message")
    probe.spin_for(0.5)
    assert [m for _, m in got] == [Twist(linear=Vector3(x=0.1), angular=Vector3(z=-0.2))]

    times = cli("topic", "pub", ifc.CMD_VEL, "geometry_msgs/Twist", "{angular: {z: 0.3}}", "-t", "3",
                "-r", "20", "-p", "2", *keep)
    assert times.returncode == 0, times.stderr
    assert re.findall(r"publishing #(\d+)", times.stdout) == ["2"], times.stdout  # -p 2: every 2nd shown
    probe.wait(lambda: len(got) >= 4, "the -t 3 messages")
    probe.spin_for(0.5)
    assert [m for _, m in got[1:]] == [Twist(angular=Vector3(z=0.3))] * 3

    states = cli("topic", "pub", "/pub_states", "sensor_msgs/msg/JointState",
                 "{header: auto, name: [a, b], position: [1, 2.5]}", "-1", *keep)
    assert states.returncode == 0, states.stderr
    probe.wait(lambda: probe.received["/pub_states"], "the JointState")
    js = probe.received["/pub_states"][0][1]
    assert list(js.name) == ["a", "b"] and list(js.position) == [1.0, 2.5], js
    assert js.header.stamp.sec > 0  # 'auto': stamped at publication

    # refused before publishing, naming the field (the other refusals: the unit test above)
    bad = cli("topic", "pub", ifc.CMD_VEL, "geometry_msgs/msg/Twist", "{linar: {x: 0.1}}", "-1")
    assert bad.returncode == 2 and "no field 'linar' in geometry_msgs/msg/Twist" in bad.stderr, bad
    assert "publisher: beginning loop" not in bad.stdout, bad
    probe.spin_for(0.5)
    assert len(got) == 4  # nothing published by the refused one
