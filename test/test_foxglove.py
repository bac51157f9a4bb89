"""The Foxglove live view (foxglove_node) as a Foxglove client meets it: a WebSocket client (the
``websockets`` package, the Foxglove WebSocket protocol) connects to the bridge of a running lockstep
graph, sees the channels advertised, subscribes and decodes the robot's transforms, joint states, CPG
state and contacts, and sets cpg_node's zeta from the parameter panel's side: an accepted value really
changes the node's parameter (read back through its parameter service); a refused one leaves it and
shows the node's own reason. Each test on its own DDS domain, every process stopped by the fixtures;
the server on a free port (port 0, read back from the node's log)."""

from __future__ import annotations

import json
import math
import re
import struct
import time

import pytest
from ros_helpers import START_S

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.foxglove_view import READY, SUBPROTOCOL, parse_address
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.walker.controller import DOFS

# ----------------------------------------------------------------------------- protobuf, the few parts

def fields(buf: bytes) -> dict[int, list]:
    """A protobuf message's fields by number (varint: int, fixed64: the 8 bytes, length-delimited: bytes)."""
    out: dict[int, list] = {}
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        num, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(buf, i)
        elif wire == 1:
            value, i = buf[i:i + 8], i + 8
        elif wire == 2:
            n, i = _varint(buf, i)
            value, i = buf[i:i + n], i + n
        elif wire == 5:
            value, i = buf[i:i + 4], i + 4
        else:
            raise ValueError(f"wire type {wire}")
        out.setdefault(num, []).append(value)
    return out


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    shift = result = 0
    while True:
        b = buf[i]
        i += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, i
        shift += 7


def _double(f: dict, num: int) -> float:
    return struct.unpack("<d", f[num][0])[0] if num in f else 0.0


def frame_transforms(buf: bytes) -> dict[str, dict]:
    """foxglove.FrameTransforms -> {child: {parent, translation (x, y, z), rotation (x, y, z, w)}}."""
    out = {}
    for t in fields(buf).get(1, []):
        f = fields(t)
        tr, rot = fields(f.get(4, [b""])[0]), fields(f.get(5, [b""])[0])
        out[f[3][0].decode()] = {"parent": f[2][0].decode(),
                                 "translation": [_double(tr, k) for k in (1, 2, 3)],
                                 "rotation": [_double(rot, k) for k in (1, 2, 3, 4)]}
    return out


def joint_states(buf: bytes) -> dict[str, tuple[float, float]]:
    """foxglove.JointStates -> {name: (position, velocity)}."""
    out = {}
    for j in fields(buf).get(2, []):
        f = fields(j)
        out[f[1][0].decode()] = (_double(f, 2), _double(f, 3))
    return out


def test_the_decoder_reads_what_the_sdk_encodes() -> None:
    from foxglove.messages import (
        FrameTransform,
        FrameTransforms,
        JointState,
        JointStates,
        Quaternion,
        Vector3,
    )

    tf = FrameTransforms(transforms=[FrameTransform(parent_frame_id="odom", child_frame_id="base_link",
                                                    translation=Vector3(x=1.0, y=-2.0, z=0.25),
                                                    rotation=Quaternion(x=0.1, y=0.2, z=0.3, w=0.9))])
    assert frame_transforms(tf.encode()) == {"base_link": {"parent": "odom", "translation": [1.0, -2.0, 0.25],
                                                           "rotation": [0.1, 0.2, 0.3, 0.9]}}
    js = JointStates(joints=[JointState(name="lleg_joint_2", position=-0.5, velocity=2.0, effort=3.0)])
    assert joint_states(js.encode()) == {"lleg_joint_2": (-0.5, 2.0)}


def test_the_address_option() -> None:
    assert parse_address(None) == ("127.0.0.1", 8765)
    assert parse_address("9000") == ("127.0.0.1", 9000)
    assert parse_address("0.0.0.0:8765") == ("0.0.0.0", 8765)
    for bad in ("host:", "70000", "a b:80", "127.0.0.1:x"):
        with pytest.raises(ValueError, match="--foxglove"):
            parse_address(bad)


# ----------------------------------------------------------------------------------------- client

class Client:
    """A Foxglove WebSocket client: the server's text ops by kind, message data by channel topic."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.ops: list[dict] = []
        self.channels: dict[str, dict] = {}
        self.subs: dict[int, str] = {}
        self.data: dict[str, list[bytes]] = {}

    def pump(self, until, what: str, timeout: float = START_S) -> None:
        """Receive until ``until()``; AssertionError ``what`` after ``timeout`` wall s (a hang guard)."""
        end = time.monotonic() + timeout
        while not until():
            left = end - time.monotonic()
            assert left > 0, f"not within {timeout:g} s: {what}"
            try:
                raw = self.ws.recv(timeout=min(left, 1.0))
            except TimeoutError:
                continue
            if isinstance(raw, str):
                op = json.loads(raw)
                self.ops.append(op)
                if op["op"] == "advertise":
                    self.channels.update({c["topic"]: c for c in op["channels"]})
            elif raw[0] == 1:  # message data: subscription id, log time, payload
                sub_id, _log_time = struct.unpack_from("<IQ", raw, 1)
                self.data.setdefault(self.subs[sub_id], []).append(raw[13:])

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, topic in enumerate(topics, start=len(self.subs) + 1):
            self.subs[i] = topic
            subs.append({"id": i, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def request(self, op: dict, answer: str) -> dict:
        """Send ``op`` (with an id) and wait for the server's ``answer`` op with that id."""
        self.ws.send(json.dumps(op))
        self.pump(lambda: any(o["op"] == answer and o.get("id") == op["id"] for o in self.ops),
                  f"{answer} for {op}")
        return next(o for o in self.ops if o["op"] == answer and o.get("id") == op["id"])

    def set_param(self, name: str, value: object, rid: str) -> dict[str, object]:
        op = {"op": "setParameters", "parameters": [{"name": name, "value": value}], "id": rid}
        answer = self.request(op, "parameterValues")
        return {p["name"]: p["value"] for p in answer["parameters"]}


CHANNELS = {ifc.TF: "foxglove.FrameTransforms", ifc.JOINT_STATES: "foxglove.JointStates",
            ifc.JOINT_TARGETS: "foxglove.JointStates", ifc.CPG_STATE: "cpg_walker.CpgState",
            ifc.CONTACT: "cpg_walker.Contact", ifc.CONTACT_TOUCHDOWN: "cpg_walker.Touchdown",
            ifc.DIAGNOSTICS: "cpg_walker.Diagnostics", ifc.ROBOT_DESCRIPTION: "std_msgs/msg/String",
            ifc.CPG_TEACH_STATE: "cpg_walker.TeachState"}


@pytest.mark.ros
@pytest.mark.slow
def test_foxglove_client_sees_the_robot_and_sets_zeta(graph, probe) -> None:
    graph.start("foxglove_node", port=0)
    graph.start("pid_node", lockstep=True, wait_for_targets=True)
    graph.start("cpg_node", lockstep=True)
    graph.start("sim_node", pacing="lockstep", duration=0.0)
    graph.wait_for_log("foxglove_node", READY, START_S)
    port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", graph.procs["foxglove_node"].log()).group(1))
    from websockets.sync.client import connect

    with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None,
                 open_timeout=START_S) as ws:
        client = Client(ws)
        client.pump(lambda: bool(client.ops), "serverInfo")
        info = client.ops[0]
        assert info["op"] == "serverInfo" and "parameters" in info["capabilities"], info
        client.pump(lambda: set(CHANNELS) <= set(client.channels), f"channels {sorted(CHANNELS)}")
        assert {t: client.channels[t]["schemaName"] for t in CHANNELS} == CHANNELS

        wanted = [ifc.TF, ifc.JOINT_STATES, ifc.JOINT_TARGETS, ifc.CPG_STATE, ifc.CONTACT,
                  ifc.ROBOT_DESCRIPTION]
        client.subscribe(wanted)
        client.pump(lambda: all(client.data.get(t) for t in wanted),
                    f"a message on each of {wanted}")

        tf = frame_transforms(client.data[ifc.TF][-1])
        assert {"base_link", "l_sole", "r_sole", "imu"} <= set(tf), sorted(tf)
        assert tf["base_link"]["parent"] == "odom"
        assert 0.1 < tf["base_link"]["translation"][2] < 0.5, tf["base_link"]  # the torso above the floor
        assert all(abs(math.hypot(*t["rotation"]) - 1.0) < 1e-6 for t in tf.values())

        for topic in (ifc.JOINT_STATES, ifc.JOINT_TARGETS):
            js = joint_states(client.data[topic][-1])
            assert set(js) == set(JOINT_NAMES), topic
            assert all(math.isfinite(q) and abs(q) < math.pi for q, _ in js.values()), topic

        state = json.loads(client.data[ifc.CPG_STATE][-1])
        assert list(state["dofs"]) == list(DOFS)
        for dof in state["dofs"].values():
            assert dof["phase_rad"] and all(0 <= p < 2 * math.pi for p in dof["phase_rad"])
            assert all(a >= 0 for a in dof["amplitude_rad"]) and all(f > 0 for f in dof["frequency_hz"])

        contact = json.loads(client.data[ifc.CONTACT][-1])
        assert contact["left_load_n"] + contact["right_load_n"] > 0  # the weight is on the soles
        assert "<robot" in json.loads(client.data[ifc.ROBOT_DESCRIPTION][-1])["data"]

        get = {"op": "getParameters", "parameterNames": ["/cpg.zeta", "/cpg.alpha"], "id": "g"}
        got = client.request(get, "parameterValues")
        assert {p["name"]: p["value"] for p in got["parameters"]} == {"/cpg.zeta": 1.0, "/cpg.alpha": 1.0}

        assert client.set_param("/cpg.zeta", 0.8, "ok") == {"/cpg.zeta": 0.8}
        assert [v.double_value for v in probe.get_params("cpg", ["zeta"])] == [0.8]

        n_status = sum(o["op"] == "status" for o in client.ops)
        assert client.set_param("/cpg.zeta", 5, "bad") == {"/cpg.zeta": 0.8}
        reason = probe.set_param("cpg", "zeta", 5.0).reason  # what the node itself says
        assert reason
        client.pump(lambda: sum(o["op"] == "status" for o in client.ops) > n_status, "a status message")
        status = [o for o in client.ops if o["op"] == "status"][n_status]
        assert status["level"] == 2, status  # error
        assert "/cpg.zeta" in status["message"] and reason in status["message"], (status, reason)
        assert [v.double_value for v in probe.get_params("cpg", ["zeta"])] == [0.8]
        assert "refused by /cpg" in graph.procs["foxglove_node"].log()


def test_graph_spec_starts_the_bridge_with_its_address_and_overrides() -> None:
    from cpg_walker.graph.runner import GraphSpec

    spec = GraphSpec(foxglove="0.0.0.0:9001", params=[("foxglove_node", "display_rate", 20.0)])
    assert spec.node_params()["foxglove_node"] == {"host": "0.0.0.0", "port": 9001, "display_rate": 20.0}
    assert GraphSpec(foxglove="").node_params()["foxglove_node"] == {"host": "127.0.0.1", "port": 8765}
    assert "foxglove_node" not in GraphSpec().node_params()
    with pytest.raises(ValueError, match="--foxglove"):
        GraphSpec(foxglove="localhost:99999").node_params()


def test_cpg_state_by_dof_name_and_touchdowns_from_paired_loads() -> None:
    from std_msgs.msg import MultiArrayDimension

    from cpg_walker.nodes.foxglove_view import Contacts, cpg_layout, cpg_state

    dims = [MultiArrayDimension(label="dof:a,b", size=2, stride=18),
            MultiArrayDimension(label="o", size=3, stride=9),
            MultiArrayDimension(label="v", size=3, stride=3)]
    names, n = cpg_layout(dims)
    data = [[[7.0, 0.5, 0.1], [-1.0, 1.0, 0.2], [0.3, 0.4, 0.05]],
            [[0.0, 0.5, 0.0], [1.0, 1.0, 0.0], [0, 0, 0]]]
    state = cpg_state(names, n, [x for dof in data for row in dof for x in row], 1_500_000_000)
    assert state["timestamp"] == {"sec": 1, "nsec": 500_000_000}
    assert state["dofs"]["a"]["phase_rad"] == pytest.approx([7.0 - 2 * math.pi, 2 * math.pi - 1.0])
    assert state["dofs"]["a"]["amplitude_rad"] == [0.1, 0.2] and state["dofs"]["a"]["target_rad"] == 0.3
    with pytest.raises(ValueError):
        cpg_layout(dims[:2])

    c = Contacts()
    step = 2_000_000  # 2 ms samples; the left foot lifts for 0.4 s, then lands
    for k in range(600):
        left = 0.0 if 100 <= k < 300 else 30.0
        c.add("right", k * step, 30.0)
        if k != 50:  # a lost left sample: that stamp is never paired
            c.add("left", k * step, left)
    assert c.touchdowns == [("left", 300 * step)]
    assert c.state()["left_touchdowns"] == 1 and c.state()["left_down"] and c.state()["right_load_n"] == 30.0


@pytest.mark.ros
@pytest.mark.slow
def test_the_bridge_takes_its_packaged_file_and_refuses_what_it_cannot_forward(graph, probe) -> None:
    """Started without --params-file (``ros2 run``), on a free port: every other value is its packaged
    file's; a set of a parameter it does not forward, of the read-only URDF, and of a node that is not
    running each come back with a reason and without a crash."""
    import subprocess
    import sys

    from ros_helpers import ANSWER_S

    from cpg_walker.nodes.params import params_file
    from cpg_walker.paths import ros_parameters

    log = graph.log_dir / "foxglove_node.bare.log"
    graph.log_dir.mkdir(parents=True, exist_ok=True)
    with open(log, "wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "cpg_walker.nodes.foxglove_node", "--ros-args",
                                 "-p", "port:=0", "-p", "service_timeout:=0.5"], env=graph.env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        expected = {k: v for k, v in ros_parameters("foxglove.yaml", "foxglove").items()
                    if k not in ("port", "service_timeout")}
        values = probe.get_params("foxglove", list(expected))
        from rclpy.parameter import parameter_value_to_python

        got = {k: parameter_value_to_python(v) for k, v in zip(expected, values, strict=True)}
        assert got == expected
        end = time.monotonic() + ANSWER_S
        while READY not in log.read_text():
            assert time.monotonic() < end and proc.poll() is None, log.read_text()
            time.sleep(0.05)
        port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", log.read_text()).group(1))
        from websockets.sync.client import connect

        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=ANSWER_S) as ws:
            client = Client(ws)
            answer = client.set_param(ifc.ROBOT_DESCRIPTION, "<robot/>", "ro")
            assert answer[ifc.ROBOT_DESCRIPTION].startswith("<?xml")
            assert client.set_param("/sim.pacing", "fast", "unknown") == {}
            assert client.set_param("/cpg.zeta", 0.5, "absent") == {}  # no cpg node: no value to give
            client.pump(lambda: sum(o["op"] == "status" for o in client.ops) >= 3, "three status messages")
            text = " | ".join(o["message"] for o in client.ops if o["op"] == "status")
            assert "read-only" in text and "not a forwarded parameter" in text and "/cpg/" in text, text
        assert proc.poll() is None
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    text = log.read_text()
    assert str(params_file("foxglove")) in text and "Traceback" not in text


def test_the_shipped_layout_is_the_generated_one() -> None:
    """docs/foxglove_layout.json == a fresh ``python -m cpg_walker.graph.foxglove_layout``; its plots name
    channels the bridge serves."""
    from pathlib import Path

    from cpg_walker.graph.foxglove_layout import layout_json

    shipped = Path(__file__).resolve().parent.parent / "docs" / "foxglove_layout.json"
    assert shipped.read_text() == layout_json(), "regenerate: python -m cpg_walker.graph.foxglove_layout"
    paths = re.findall(r'"value": "(/[^."\[]+(?:/[^."\[]+)*)', shipped.read_text())
    assert paths and set(paths) <= set(CHANNELS), set(paths) - set(CHANNELS)


def test_teach_state_is_keyed_by_joint_and_a_foreign_layout_refused() -> None:
    """/cpg/teach/state as cpg_node lays it out (nodes/cpg_node.py teach_state_layout), by DOF name."""
    from cpg_walker.nodes.cpg_node import TEACH_STATE_VALUES, teach_state_layout
    from cpg_walker.nodes.foxglove_view import teach_state

    data = [float(10 * b + k) for b in range(len(DOFS)) for k in range(len(TEACH_STATE_VALUES))]
    view = teach_state(teach_state_layout(DOFS).dim, data, 3_000_000_001)
    assert view["timestamp"] == {"sec": 3, "nsec": 1} and list(view["dofs"]) == list(DOFS)
    assert view["dofs"][DOFS[2]] == {"learned_frequency_hz": 20.0, "amplitude_rad": 21.0, "error_deg": 22.0}
    with pytest.raises(ValueError, match="layout"):
        teach_state(teach_state_layout(DOFS).dim, data[:-1], 0)


def test_sole_load_read_straight_from_the_cdr_equals_rclpy_deserialization() -> None:
    import random

    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message

    from cpg_walker.nodes.foxglove_view import wrench_load

    rng = random.Random(13)
    for k in range(200):
        m = WrenchStamped()
        m.header.frame_id = "x" * rng.randint(0, 12)  # every alignment of the doubles after it
        m.header.stamp.sec, m.header.stamp.nanosec = rng.randint(0, 10**6), rng.randint(0, 10**9 - 1)
        m.wrench.force.x, m.wrench.force.z, m.wrench.torque.z = 7.0, rng.uniform(-100, 100), 3.0
        data = serialize_message(m)
        back = deserialize_message(data, WrenchStamped)
        assert wrench_load(data) == (back.header.stamp.sec * 10**9 + back.header.stamp.nanosec,
                                     back.wrench.force.z), k
    with pytest.raises(ValueError):
        wrench_load(serialize_message(m)[:30])


@pytest.mark.ros
def test_a_taken_port_is_one_clear_error_and_starts_nothing(ros_domain, tmp_path) -> None:
    """``cpg-walker graph --foxglove PORT`` on a port in use: the bridge (started first) fails, the graph
    stops before the sim starts, and the error names the address."""
    import io
    import socket

    from cpg_walker.graph.runner import GraphSpec, run_foreground

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = io.StringIO()
        spec = GraphSpec(foxglove=f"127.0.0.1:{port}", duration=1.0, log_dir=str(tmp_path / "logs"))
        with pytest.raises(ValueError, match=rf"did not start: .*127\.0\.0\.1:{port}"):
            run_foreground(spec, out=out)  # raises before it returns (status, fall)
    assert not (tmp_path / "logs" / "sim_node.log").exists()
