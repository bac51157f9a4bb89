"""Recording the graph (nodes/recorder_node.py, nodes/recording.py) and plotting it (experiments/plot_bag.py).

One short lockstep walk through the graph with ``record=True`` (what ``cpg-walker walk --record`` runs) and a
zeta change through cpg_node's SetParameters service, read back with rosbags and with the plain ``mcap``
reader, and decoded message for message by stock rosbags, mcap_ros2 and Foxglove's deserializer (Node.js,
installed by npm into .venv/npm); beside it ``cpg-walker record --duration`` records the same graph from
another process. Counts are derived from config/sim.yaml (control and odometry periods) and the walk's
duration. The unit tests at the end need no graph."""

from __future__ import annotations

import dataclasses
import functools
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.recording import BAG_NAME, read_topics
from cpg_walker.paths import ros_parameters

#: sim s of the walk, the time of its zeta change (sent through /cpg/set_parameters), the side recording.
DURATION_S, ZETA_AT_S, ZETA_TO, SIDE_S = 2.0, 0.5, 0.8, 1.0
#: Control periods at the start whose target/torque the recorder may miss (the counts test): 1 seen.
START_TICKS = 10
SIM = ros_parameters("sim.yaml", "sim")
TYPES = {
    ifc.CLOCK: "rosgraph_msgs/msg/Clock", ifc.JOINT_STATES: "sensor_msgs/msg/JointState",
    ifc.IMU: "sensor_msgs/msg/Imu", ifc.TF: "tf2_msgs/msg/TFMessage", ifc.TF_STATIC: "tf2_msgs/msg/TFMessage",
    ifc.JOINT_TARGETS: "sensor_msgs/msg/JointState", ifc.JOINT_TORQUES: "sensor_msgs/msg/JointState",
    ifc.PARAMETER_EVENTS: "rcl_interfaces/msg/ParameterEvent", ifc.ODOM_GROUND_TRUTH: "nav_msgs/msg/Odometry",
    ifc.FOOT_LOAD_LEFT: "geometry_msgs/msg/WrenchStamped",
    ifc.FOOT_LOAD_RIGHT: "geometry_msgs/msg/WrenchStamped",
    ifc.DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray", ifc.CPG_STATE: "std_msgs/msg/Float64MultiArray",
    "/rosout": "rcl_interfaces/msg/Log", ifc.SIM_FALLEN: "std_msgs/msg/Bool",
}


def _ns(t_s: float) -> int:
    return round(t_s * 1e9)


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """The recorded walk (and the side recording), once for the module, on a domain of its own."""
    from ros_helpers import ANSWER_S, kill_nodes, reserve_domain, sim_deadline

    import cpg_walker.graph.processes as graph_module
    from cpg_walker.experiments.walk_graph import run_graph_walk
    from cpg_walker.graph.processes import isolated_env

    out = tmp_path_factory.mktemp("walk")
    side = out / "side"
    domain, lock = reserve_domain()
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(graph_module, "quiet_domain_id", lambda attempts=5: domain)
            with open(out / "side_record.log", "wb") as log:
                rec = subprocess.Popen(
                    [sys.executable, "-m", "cpg_walker.cli.main", "record", "--out", str(side),
                     "--duration", str(SIDE_S)], env=isolated_env(domain), stdout=log,
                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
            try:
                report = run_graph_walk(out, duration=DURATION_S, schedule=[(ZETA_AT_S, ZETA_TO, 1.0)],
                                        record=True, timeout=sim_deadline(DURATION_S))
                side_status = rec.wait(timeout=ANSWER_S)
            finally:
                if rec.poll() is None:
                    rec.kill()
                    rec.wait()
    finally:
        kill_nodes(domain)
        lock.close()
    return SimpleNamespace(out=out, report=report, side=side, side_status=side_status,
                           side_log=(out / "side_record.log").read_text(errors="replace"),
                           data=read_topics(out))


def _stamps(samples: list) -> list[int]:
    return sorted({ns for ns, _ in samples})


@pytest.mark.ros
@pytest.mark.slow
def test_the_bag_holds_every_topic_with_its_type(walk):
    from rosbags.rosbag2 import Reader

    bags = list(walk.out.glob("*.mcap"))
    assert [p.name for p in bags] == [f"{BAG_NAME}.mcap"] and walk.report["bag"] == str(bags[0].resolve())
    with Reader(walk.out) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert {t: types.get(t) for t in TYPES} == TYPES
    assert not walk.report["fell"]


@pytest.mark.ros
@pytest.mark.slow
def test_counts_follow_the_sim_time_and_the_control_period(walk):
    """Every control period of the walk is in the bag once per sensor topic (re-sent lockstep states
    repeat a stamp), each message at its stamp's bag time; odometry and /tf every odom_period. The
    controllers' targets and torques of every tick from the first recorded one: like ``ros2 bag record``,
    the recorder subscribes to a topic once it has seen its publisher, so the very first target and torque
    (sent as soon as the sim's first state arrives) can go out before the recorder's subscription is
    matched (the sim then holds its second state until the recorder has subscribed to them); the sim's
    state topics are complete from t = 0: the sim holds its first state until the recorder has
    subscribed to them (sim_node's wait_for_subscriber)."""
    period, odom_period = SIM["control_period"], SIM["odom_period"]
    ticks = [_ns(k * period) for k in range(round(DURATION_S / period))]
    d = walk.data
    for topic in (ifc.CLOCK, ifc.JOINT_STATES, ifc.IMU, ifc.FOOT_LOAD_LEFT, ifc.FOOT_LOAD_RIGHT):
        assert _stamps(d[topic]) == ticks, topic
    for topic in (ifc.JOINT_TARGETS, ifc.JOINT_TORQUES):
        stamps = _stamps(d[topic])
        assert stamps[0] <= ticks[START_TICKS] and {t for t in ticks if t >= stamps[0]} <= set(stamps), topic
    for topic in (ifc.JOINT_STATES, ifc.IMU, ifc.ODOM_GROUND_TRUTH):
        assert all(ns == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for ns, m in d[topic]), topic
    odom = _stamps(d[ifc.ODOM_GROUND_TRUTH])
    assert all(ns % _ns(odom_period) == 0 for ns in odom) and len(odom) >= DURATION_S / odom_period - 1
    assert _stamps(d[ifc.TF]) == odom and len(d[ifc.TF]) == len(odom)
    assert len(d[ifc.TF_STATIC]) == 1


def _matrix(transform) -> np.ndarray:
    import mujoco

    q, p = transform.rotation, transform.translation
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, np.array([q.w, q.x, q.y, q.z]))
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r.reshape(3, 3), (p.x, p.y, p.z)
    return out


@pytest.mark.ros
@pytest.mark.slow
def test_tf_is_the_simulated_pose(walk):
    """/tf + /tf_static form one tree over every link of the model and the imu, rooted at the odometry's
    frame; its base transform is the odometry pose of the same stamp, bit for bit; and a loaded sole
    (load above the touchdown threshold) is on the floor: its frame as high as when the robot stands."""
    import mujoco

    from cpg_walker.robot import frames
    from cpg_walker.robot.contact import CONTACT_ON_N
    from cpg_walker.robot.hoap2 import Hoap2Sim

    d = walk.data
    sim = Hoap2Sim()
    mujoco.mj_kinematics(sim.model, sim.data)
    standing_z = {side: float(sim.data.xpos[sim.model.body(body).id][2])
                  for side, body in (("left", "lleg_sole"), ("right", "rleg_sole"))}
    links = {frames.link_name(sim.model.body(b).name) for b in range(1, sim.model.nbody)}
    static = {t.child_frame_id: t for t in d[ifc.TF_STATIC][0][1].transforms}
    odom = dict(d[ifc.ODOM_GROUND_TRUTH])
    loads = {side: dict(d[ifc.foot_load_topic(side)]) for side in ifc.FOOT_LOAD_SIDES}
    checked = 0
    for ns, msg in d[ifc.TF]:
        tree = {t.child_frame_id: t for t in msg.transforms}
        assert not set(tree) & set(static)
        tree.update(static)
        pose = odom[ns].pose.pose
        base = tree[frames.BASE_LINK]
        assert base.header.frame_id == odom[ns].header.frame_id
        assert (base.transform.translation.x, base.transform.translation.y, base.transform.translation.z,
                base.transform.rotation.w, base.transform.rotation.x, base.transform.rotation.y,
                base.transform.rotation.z) == (pose.position.x, pose.position.y, pose.position.z,
                                               pose.orientation.w, pose.orientation.x, pose.orientation.y,
                                               pose.orientation.z)
        assert set(tree) == links | {frames.IMU_FRAME}
        for side, sole in (("left", frames.LEFT_SOLE), ("right", frames.RIGHT_SOLE)):
            if loads[side][ns].wrench.force.z <= CONTACT_ON_N:
                continue
            world, frame = np.eye(4), sole
            while frame in tree:
                world = _matrix(tree[frame].transform) @ world
                frame = tree[frame].header.frame_id
            assert frame == odom[ns].header.frame_id
            assert world[2, 3] == pytest.approx(standing_z[side], abs=0.003), (ns, side)
            checked += 1
    assert checked >= len(d[ifc.TF])  # at least one foot carries the robot at every sample


@pytest.mark.ros
@pytest.mark.slow
def test_the_zeta_change_is_in_the_parameter_events(walk):
    changes = [(ns, p.value.double_value) for ns, ev in walk.data[ifc.PARAMETER_EVENTS] if ev.node == "/cpg"
               for p in ev.changed_parameters if p.name == "zeta"]
    assert len(changes) == 1
    ns, value = changes[0]
    assert value == ZETA_TO and ns >= _ns(ZETA_AT_S)
    assert walk.report["schedule"][0]["accepted"]


@pytest.mark.ros
@pytest.mark.slow
def test_the_plain_mcap_reader_reads_the_file(walk, tmp_path):
    """The .mcap alone (no metadata.yaml): the mcap library reads it, ordered by time, with the counts
    rosbags reads; read_topics decodes it the same way."""
    import shutil

    from mcap.reader import make_reader

    with open(walk.out / f"{BAG_NAME}.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        counts = {c.topic: n for c in summary.channels.values()  # a channel without messages (e.g. no
                  if (n := summary.statistics.channel_message_counts[c.id])}  # teacher): nothing to read
        assert reader.get_header().profile == "ros2"
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert counts == {t: len(v) for t, v in walk.data.items()}
    assert len(times) == sum(counts.values()) and times == sorted(times)
    alone = shutil.copy(walk.out / f"{BAG_NAME}.mcap", tmp_path / "alone.mcap")
    data = read_topics(alone, [ifc.JOINT_STATES, ifc.TF])
    for topic in (ifc.JOINT_STATES, ifc.TF):
        assert [ns for ns, _ in data[topic]] == [ns for ns, _ in walk.data[topic]]
    last, expected = data[ifc.JOINT_STATES][-1][1], walk.data[ifc.JOINT_STATES][-1][1]
    assert last.position.tolist() == expected.position.tolist()


@pytest.mark.ros
@pytest.mark.slow
def test_cpg_walker_record_stops_after_its_duration(walk):
    """``cpg-walker record --duration`` beside the walk: it ends by itself with a complete bag of that much
    sim time, from its first /clock."""
    assert walk.side_status == 0, walk.side_log[-2000:]
    d = read_topics(walk.side)
    clock = _stamps(d[ifc.CLOCK])
    assert clock[-1] - clock[0] == _ns(SIDE_S)
    assert len(d[ifc.TF]) >= 1 and len(d[ifc.TF_STATIC]) == 1


@pytest.mark.ros
@pytest.mark.slow
def test_plot_writes_the_pngs(walk, tmp_path):
    import json

    from cpg_walker.cli.main import main

    assert main(["plot", str(walk.out / f"{BAG_NAME}.mcap"), "--out", str(tmp_path)]) == 0
    names = ["targets_vs_states.png", "tilt.png", "sole_loads.png", "modulation.png", "cpg_phases.png"]
    summary = json.loads((tmp_path / "plot.json").read_text())
    assert summary["files"] == names and summary["not_plotted"] == {}
    for name in names:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.ros
@pytest.mark.slow
def test_robot_description_is_recorded(walk):
    """Needs sim_node's /robot_description (the urdf branch): latched, so recorded once, a URDF."""
    msgs = walk.data.get(ifc.ROBOT_DESCRIPTION, [])
    assert len(msgs) == 1
    assert "<robot" in msgs[0][1].data


# ------------------------------------------------------- stock readers: rosbags, mcap_ros2, Foxglove's

JS_DIR = Path(__file__).parent / "js"
READERS = ("rosbags", "mcap_ros2", "foxglove")


@functools.cache
def _store():
    from cpg_walker.nodes.recording import typestore

    return typestore()


def _plain(v):
    """A decoded message as plain values (dicts, lists, str, int, float; non-finite floats as their repr),
    whichever library decoded it: rosbags' dataclasses and numpy arrays, mcap_ros2's namespaces and bytes,
    Foxglove's JSON (int64 as {"$int": ...}, non-finite floats as {"$float": ...}: decode_ros2.cjs)."""
    if dataclasses.is_dataclass(v):  # rosbags': its fields (not the type's constants, which it has too)
        return {name: _plain(getattr(v, name)) for name, _ in _store().fielddefs[v.__msgtype__][1]}
    if isinstance(v, SimpleNamespace):
        return {k: _plain(getattr(v, k)) for k in type(v).__slots__}
    if isinstance(v, dict):
        if set(v) == {"$int"}:
            return int(v["$int"])
        if set(v) == {"$float"}:
            return _plain(float(v["$float"]))
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, np.ndarray):
        return v.tolist() if v.dtype.kind != "f" or np.isfinite(v).all() else _plain(v.tolist())
    if isinstance(v, np.generic):
        return _plain(v.item())
    if isinstance(v, bytes | bytearray):
        return list(v)
    if isinstance(v, list | tuple):
        if all(type(x) is int or type(x) is str or (type(x) is float and math.isfinite(x)) for x in v):
            return list(v)
        return [_plain(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)
    return v


@pytest.fixture(scope="module")
def foxglove_decoder():
    """The command that runs test/js/decode_ros2.cjs with Foxglove's deserializer, installed by ``npm ci``
    from test/js/package-lock.json into .venv/npm (once per venv and lock file)."""
    import shutil

    npm, node = shutil.which("npm"), shutil.which("node")
    if npm is None or node is None:
        pytest.skip("npm / Node.js not installed: Foxglove's deserializer (@foxglove/rosmsg2-serialization, "
                    "an npm package) cannot run")
    dest = Path(sys.prefix) / "npm"
    lock = (JS_DIR / "package-lock.json").read_bytes()
    installed = dest / "node_modules" / "@foxglove" / "rosmsg2-serialization"
    if not installed.is_dir() or not (dest / "package-lock.json").exists() \
            or (dest / "package-lock.json").read_bytes() != lock:
        dest.mkdir(parents=True, exist_ok=True)
        for name in ("package.json", "package-lock.json"):
            shutil.copy(JS_DIR / name, dest / name)
        done = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--prefix", str(dest)],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"npm ci of Foxglove's deserializer failed:\n{done.stderr[-2000:]}"
    return [node, str(JS_DIR / "decode_ros2.cjs")], {"NODE_PATH": str(dest / "node_modules")}


def _foxglove_message(result: dict) -> dict:
    if "error" in result:
        raise ValueError(result["error"])
    return result["message"]


@pytest.fixture(scope="module")
def stock_decoded(walk, foxglove_decoder):
    """Every message of the recording decoded by each reader as a user's script would: rosbags' AnyReader
    (``reader.deserialize``), mcap_ros2's decoder (``iter_decoded_messages``), Foxglove's MessageReader.
    {reader: {topic: [(log time, raw CDR, plain message)]}} sorted by (time, raw); rejections in
    ``errors`` ({reader: {topic: (count, first error)}}), Foxglove's bytes after the last field in
    ``trailing`` ({topic: most})."""
    import base64
    import json
    import os

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    path = walk.out / f"{BAG_NAME}.mcap"
    out: dict[str, dict[str, list]] = {r: {} for r in READERS}
    errors: dict[str, dict[str, tuple[int, str]]] = {r: {} for r in READERS}

    def keep(reader: str, topic: str, ns: int, raw: bytes, decode) -> None:
        try:
            msg = _plain(decode())
        except Exception as exc:  # any rejection is counted and shown
            n, first = errors[reader].get(topic, (0, f"{type(exc).__name__}: {exc}"))
            errors[reader][topic] = (n + 1, first)
            return
        out[reader].setdefault(topic, []).append((ns, bytes(raw), msg))

    with AnyReader([walk.out]) as reader:
        for conn, ns, raw in reader.messages():
            keep("rosbags", conn.topic, ns, raw, lambda r=reader, c=conn, d=raw: r.deserialize(d, c.msgtype))
    lines, meta, seen, decoders = [], [], set(), {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if schema.id not in decoders:
                decoders[schema.id] = DecoderFactory().decoder_for(channel.message_encoding, schema)
            keep("mcap_ros2", channel.topic, message.log_time, message.data,
                 functools.partial(decoders[schema.id], message.data))
            line = {"topic": channel.topic, "data": base64.b64encode(message.data).decode()}
            if channel.topic not in seen:
                seen.add(channel.topic)
                line["schema"] = schema.data.decode()
            lines.append(json.dumps(line))
            meta.append((message.log_time, bytes(message.data)))
    cmd, env = foxglove_decoder
    done = subprocess.run(cmd, input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=120,
                          env={**os.environ, **env})
    assert done.returncode == 0, done.stderr[-2000:]
    results = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(results) == len(meta)
    trailing: dict[str, int] = {}
    for (ns, raw), res in zip(meta, results, strict=True):
        if "error" not in res:
            trailing[res["topic"]] = max(trailing.get(res["topic"], 0), res["trailing"])
        keep("foxglove", res["topic"], ns, raw, functools.partial(_foxglove_message, res))
    for topics in out.values():
        for samples in topics.values():
            samples.sort(key=lambda s: (s[0], s[1]))
    counts = {c.topic: n for c in summary.channels.values()  # the channels with messages to decode
              if (n := summary.statistics.channel_message_counts[c.id])}
    return SimpleNamespace(messages=out, errors={r: e for r, e in errors.items() if e}, trailing=trailing,
                           counts=counts)


@pytest.mark.ros
@pytest.mark.slow
def test_stock_readers_decode_every_message_alike(walk, stock_decoded):
    """A user's script reads the recording with stock rosbags (AnyReader.deserialize), mcap_ros2's
    decoder or Foxglove's deserializer: each decodes every message of every topic (none rejected, no
    more than the 3 bytes of CDR's end alignment after the last field), and the three agree field for
    field, message for message (non-finite floats by their repr), with what read_topics reads too."""
    d = stock_decoded
    assert d.errors == {}
    assert {t: n for t, n in d.trailing.items() if n > 3} == {}
    for reader in READERS:
        assert {t: len(v) for t, v in d.messages[reader].items()} == d.counts, reader
    assert set(d.counts) >= set(TYPES)
    for topic in d.counts:
        ref = d.messages["rosbags"][topic]
        for reader in READERS[1:]:
            other = d.messages[reader][topic]
            bad = [i for i, (a, b) in enumerate(zip(ref, other, strict=True)) if a != b]
            assert not bad, (topic, reader, ref[bad[0]], other[bad[0]])
    targets = [m for _, _, m in d.messages["foxglove"][ifc.JOINT_TARGETS]]
    ours = [m for _, m in walk.data[ifc.JOINT_TARGETS]]
    assert [t["name"] for t in targets] == [list(m.name) for m in ours]
    assert [t["position"] for t in targets] == [m.position.tolist() for m in ours]
    assert all(len(t["position"]) == len(t["name"]) > 0 and t["effort"] == [] for t in targets)
    torques = [m for _, _, m in d.messages["mcap_ros2"][ifc.JOINT_TORQUES]]
    assert [t["effort"] for t in torques] == [m.effort.tolist() for _, m in walk.data[ifc.JOINT_TORQUES]]


# ------------------------------------------------------------------------------ no graph needed

def _serialized(msg) -> bytes:
    from rclpy.serialization import serialize_message

    return bytes(serialize_message(msg))


def test_bag_times_are_stamps_or_the_newest_clock(tmp_path):
    """Stamped messages at their stamp, unstamped ones (and wall-clock stamps) at the newest /clock."""
    from builtin_interfaces.msg import Time
    from rcl_interfaces.msg import Log
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from cpg_walker.nodes.recording import BagRecorder

    with BagRecorder(tmp_path) as bag:
        for topic, msgtype in ((ifc.CLOCK, "rosgraph_msgs/msg/Clock"), ("/js", "sensor_msgs/msg/JointState"),
                               ("/x", "std_msgs/msg/Float64MultiArray"),
                               ("/rosout", "rcl_interfaces/msg/Log")):
            assert bag.add_topic(topic, msgtype) is None
        assert "unknown" in bag.add_topic("/y", "no_msgs/msg/Nothing")
        bag.write(ifc.CLOCK, _serialized(Clock(clock=Time(sec=1, nanosec=500))))
        js = JointState(name=["a"], position=[1.0])
        js.header.stamp = Time(sec=1, nanosec=2_000_500)  # a target sent one period ahead
        bag.write("/js", _serialized(js))
        bag.write("/x", _serialized(Float64MultiArray(data=[1.0])))
        bag.write("/rosout", _serialized(Log(stamp=Time(sec=1_700_000_000))))
    got = {topic: [ns for ns, _ in v] for topic, v in read_topics(tmp_path).items()}
    assert got[ifc.CLOCK] == [1_000_000_500] and got["/js"] == [1_002_000_500]
    assert got["/x"] == [1_000_000_500] and got["/rosout"] == [1_000_000_500]
    assert ifc.TF not in got  # no odometry: no /tf sample (the static transforms do not need one)
    assert len(got[ifc.TF_STATIC]) == 1


def test_odometry_and_joint_states_pair_by_stamp_in_any_order():
    from cpg_walker.nodes.recording import TfPairs

    pairs = TfPairs()
    pairs.joints(10, b"j10")
    pairs.odom(20, b"o20")
    pairs.odom(10, b"o10")
    pairs.joints(20, b"j20")
    pairs.joints(20, b"j20")  # re-sent: its odometry is already paired
    assert pairs.pairs == [(10, b"o10", b"j10"), (20, b"o20", b"j20")]


_floats = st.lists(st.floats(allow_nan=False, width=64), max_size=4)
_names = st.lists(st.text(st.characters(codec="ascii", exclude_characters="\0"), max_size=5), max_size=4)


@st.composite
def _fast_dds_messages(draw):
    """(rclpy message, type): the types of the graph with sequences of float64 / int64, any of them empty."""
    from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    kind = draw(st.sampled_from(["js", "traj", "array", "event"]))
    if kind == "js":
        msg = JointState(name=draw(_names), position=draw(_floats), velocity=draw(_floats),
                         effort=draw(_floats))
        msg.header.frame_id = draw(st.sampled_from(["", "a", "base_link"]))
        return msg, "sensor_msgs/msg/JointState"
    if kind == "traj":
        points = [JointTrajectoryPoint(positions=draw(_floats), velocities=draw(_floats),
                                       effort=draw(_floats)) for _ in range(draw(st.integers(0, 3)))]
        return JointTrajectory(joint_names=draw(_names), points=points), "trajectory_msgs/msg/JointTrajectory"
    if kind == "array":
        return Float64MultiArray(data=draw(_floats)), "std_msgs/msg/Float64MultiArray"
    value = ParameterValue(type=ParameterType.PARAMETER_INTEGER_ARRAY,
                           integer_array_value=draw(st.lists(st.integers(-2**63, 2**63 - 1), max_size=3)))
    event = ParameterEvent(node=draw(st.sampled_from(["/cpg", "/x"])),
                           changed_parameters=[Parameter(name="p", value=value)])
    return event, "rcl_interfaces/msg/ParameterEvent"


@given(_fast_dds_messages())
@settings(max_examples=40, deadline=None)
def test_fast_dds_unset_end_bytes_are_cut(case):
    """rclpy's serialize_message (Fast DDS's typesupport, as on the wire) sizes an empty float64/int64
    sequence as if 8-aligned and leaves the difference unset after the last field; canonical_cdr cuts it
    where rosbags' own deserializer ends, keeps every byte before, and stock rosbags then reads the
    message, equal to what rclpy reads."""
    from rclpy.serialization import deserialize_message

    from cpg_walker.nodes.recording import canonical_cdr, cdr_end, typestore

    msg, msgtype = case
    store = typestore()
    raw = _serialized(msg)
    out = canonical_cdr(store, raw, msgtype)
    msgdef = store.get_msgdef(msgtype)
    end = 4 + msgdef.deserialize_cdr_le(raw[4:], 0, msgdef.cls, store)[1]
    assert cdr_end(store, msgtype)(raw) == end
    if len(raw) - end > 3:
        assert out == raw[:end] + bytes(-end % 4)
    else:
        assert out is raw
    assert canonical_cdr(store, out, msgtype) is out
    theirs = deserialize_message(raw, type(msg))
    ours = store.deserialize_cdr(out, msgtype)  # stock: at most 3 bytes after the last field
    if msgtype == "sensor_msgs/msg/JointState":
        assert (list(ours.name), ours.position.tolist(), ours.velocity.tolist(), ours.effort.tolist()) \
            == (list(theirs.name), list(theirs.position), list(theirs.velocity), list(theirs.effort))
    elif msgtype == "trajectory_msgs/msg/JointTrajectory":
        assert [(p.positions.tolist(), p.velocities.tolist(), p.effort.tolist()) for p in ours.points] \
            == [(list(p.positions), list(p.velocities), list(p.effort)) for p in theirs.points]
    elif msgtype == "std_msgs/msg/Float64MultiArray":
        assert ours.data.tolist() == list(theirs.data)
    else:
        assert ours.changed_parameters[0].value.integer_array_value.tolist() \
            == list(theirs.changed_parameters[0].value.integer_array_value)


def test_the_recorder_writes_what_stock_rosbags_reads(tmp_path):
    """BagRecorder writes a /joint_targets- and a /joint_torques-like message (as Fast DDS sends them) that
    rosbags' AnyReader.deserialize reads; a type that cannot carry the unset bytes is written byte for
    byte as received, and read_topics reads a bag written before the cut (or by ``ros2 bag record``)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from sensor_msgs.msg import Imu, JointState

    from cpg_walker.nodes.recording import BagRecorder, typestore

    targets = _serialized(JointState(name=["a", "b"], position=[1.0, 2.0], velocity=[3.0, 4.0]))
    torques = _serialized(JointState(name=["a", "b"], effort=[5.0, 6.0]))
    imu = _serialized(Imu())
    js = "sensor_msgs/msg/JointState"
    with BagRecorder(tmp_path / "new") as bag:
        for topic, msgtype in ((ifc.JOINT_TARGETS, js), (ifc.JOINT_TORQUES, js),
                               (ifc.IMU, "sensor_msgs/msg/Imu")):
            bag.add_topic(topic, msgtype)
        for topic, raw in ((ifc.JOINT_TARGETS, targets), (ifc.JOINT_TORQUES, torques), (ifc.IMU, imu)):
            bag.write(topic, raw)
    with AnyReader([tmp_path / "new"]) as reader:
        got = {c.topic: (raw, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()}
    assert got[ifc.JOINT_TARGETS][1].position.tolist() == [1.0, 2.0]
    assert got[ifc.JOINT_TORQUES][1].effort.tolist() == [5.0, 6.0]
    assert len(got[ifc.JOINT_TARGETS][0]) == len(targets) - 4  # the 4 unset bytes after the empty effort
    assert len(got[ifc.JOINT_TORQUES][0]) == len(torques) - 8
    assert got[ifc.IMU][0] == imu
    store = typestore()
    old = Writer(tmp_path / "old", version=9, storage_plugin=StoragePlugin.MCAP)
    old.open()
    old.write(old.add_connection(ifc.JOINT_TORQUES, js, typestore=store), 1, torques)
    old.close()
    assert read_topics(tmp_path / "old")[ifc.JOINT_TORQUES][0][1].effort.tolist() == [5.0, 6.0]


def test_a_missing_bag_is_one_clear_error(tmp_path):
    from cpg_walker.cli.main import main

    assert main(["plot", str(tmp_path / "nope"), "--out", str(tmp_path)]) == 2
    assert main(["plot", str(tmp_path), "--out", str(tmp_path / "p")]) == 2


def test_a_recorded_joint_state_topic_is_a_teaching_recording(walk):
    """`cpg-walker teach --bag DIR`: the walk's /joint_states as a recording (experiments/teach.py
    bag_gait), uniform at the control period, every joint, streamed by TeachingStream (no stride in 2 s:
    all of it over and over, for cpg_node to judge)."""
    from cpg_walker.experiments.teach import StreamTeacher, bag_gait
    from cpg_walker.robot.joints import JOINT_NAMES

    gait = bag_gait(walk.out)
    assert set(gait.names) == set(JOINT_NAMES) and gait.dt == pytest.approx(SIM["control_period"], rel=1e-6)
    assert gait.duration == pytest.approx(DURATION_S - SIM["control_period"], abs=1e-6)
    states = [m for _, m in walk.data[ifc.JOINT_STATES]]
    k = 100  # the 100th state, at its stamp
    t = (states[k].header.stamp.sec + states[k].header.stamp.nanosec * 1e-9) - \
        (states[0].header.stamp.sec + states[0].header.stamp.nanosec * 1e-9)
    np.testing.assert_allclose(gait.at(t), np.asarray(states[k].position), atol=1e-12)
    teacher = StreamTeacher(gait, 1.0)
    assert not teacher.stream.periodic and teacher.frequency_hz is None
    samples = list(teacher.until(3.0))  # past the end: it starts over
    assert len(samples) == 301 and samples[0][1] == list(teacher.stream.names)
    np.testing.assert_allclose(samples[300][2], teacher.stream.at(3.0))
