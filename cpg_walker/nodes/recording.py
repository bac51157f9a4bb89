"""A recording of the ROS graph as one rosbag2 MCAP file (ROS 2 CDR), written with rosbags' rosbag2 Writer.

``BagRecorder`` takes the messages as the middleware delivered them (serialized CDR, never re-encoded),
writes them as they come, and at ``close`` adds ``/tf`` and ``/tf_static`` computed from the simulation's
exact poses: the MuJoCo model posed from each ``/odom/ground_truth`` (the floating base, double precision)
and the ``/joint_states`` of the same stamp (every joint), its links' transforms from robot/frames.py.
The bag directory is built in a hidden temporary directory and its two files (``recording.mcap`` and
rosbag2's ``metadata.yaml``) are moved into the output directory when the bag is complete.

Time base: the graph runs on sim time, so a message's bag time (MCAP log and publish time; rosbags
writes one) is sim time: its stamp when its type starts with one (a std_msgs/Header or a
builtin_interfaces/Time: /joint_states, /imu, /odom/ground_truth, /clock, /parameter_events ...) that is
set and not ahead of the newest /clock by more than ``WALL_STAMP_AHEAD_NS`` (a wall-clock stamp, e.g.
/rosout's), else the newest /clock received (what ``ros2 bag record --use-sim-time`` records as the
receive time). A graph without sim time (``sim_time=False``) is recorded at the wall-clock receive time.
"""

from __future__ import annotations

import shutil
import struct
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cpg_walker.errors import InputError

#: File name (without suffix) of the bag in its directory: DIR/recording.mcap + DIR/metadata.yaml.
BAG_NAME = "recording"
CLOCK_TOPIC = "/clock"
ODOM_TOPIC = "/odom/ground_truth"
JOINT_STATES_TOPIC = "/joint_states"
TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: A stamp this far ahead of the newest /clock is a wall-clock one, not sim time (1 s).
WALL_STAMP_AHEAD_NS = 1_000_000_000
_STAMPED_FIRST = ("std_msgs/msg/Header", "builtin_interfaces/msg/Time")
_TIME_LE, _TIME_BE = struct.Struct("<iI"), struct.Struct(">iI")


def typestore() -> Any:
    """rosbags' typestore of ROS 2 Jazzy (has tf2_msgs, which is not importable here)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def cdr_stamp_ns(data: bytes | memoryview) -> int:
    """The builtin_interfaces/Time a CDR message starts with (after the 4-byte encapsulation header), ns."""
    sec, nsec = (_TIME_LE if data[1] & 1 else _TIME_BE).unpack_from(data, 4)
    return sec * 1_000_000_000 + nsec


def deserialize(store: Any, data: bytes | memoryview, msgtype: str) -> Any:
    """A CDR message as rosbags' message object. Fast DDS (rmw_fastrtps, Jazzy) sizes its buffer with 4
    bytes more for each empty sequence of 8-byte numbers and sends them too, unset (/joint_targets'
    effort, /joint_torques' position and velocity: 4 or 8 bytes after the last field), which rosbags'
    ``deserialize_cdr`` rejects (it allows 3); those messages are read with its generated deserializer
    directly, allowing up to 15 bytes after the last field. The fields read are the same either way."""
    from rosbags.serde import SerdeError

    try:
        return store.deserialize_cdr(data, msgtype)
    except SerdeError:
        msgdef = store.get_msgdef(msgtype)
        func = msgdef.deserialize_cdr_le if data[1] & 1 else msgdef.deserialize_cdr_be
        message, pos = func(data[4:], 0, msgdef.cls, store)
        if len(data) - 4 - pos > 15:
            raise
        return message


def qos_of(profile: Any) -> Any:
    """An rclpy QoSProfile as rosbags' Qos (the bag's offered_qos_profiles: ``ros2 bag play`` replays a
    transient-local topic as one)."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    def t(d: Any) -> QosTime:
        ns = int(getattr(d, "nanoseconds", 0))
        return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)

    return Qos(QosHistory(int(profile.history)), int(profile.depth), QosReliability(int(profile.reliability)),
               QosDurability(int(profile.durability)), t(profile.deadline), t(profile.lifespan),
               QosLiveliness(int(profile.liveliness)), t(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


def _qos(reliable: bool, latched: bool, depth: int) -> Any:
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, depth,
               QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


@dataclass
class _Topic:
    connection: Any
    stamped: bool
    count: int = 0


class BagRecorder:
    """Writes serialized messages to ``out_dir/recording.mcap`` (+ ``metadata.yaml``); a context manager.

    ``add_topic`` once per topic, ``write`` each message as received, ``close`` to add /tf, /tf_static and
    finish the file (the bag is complete only then)."""

    def __init__(self, out_dir: str | Path, sim_time: bool = True) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.sim_time = sim_time
        self.store = typestore()
        self._tmp = Path(tempfile.mkdtemp(prefix=".recording-", dir=self.out_dir))
        self.writer = Writer(self._tmp / BAG_NAME, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.writer.set_custom_data("cpg_walker.time_base",
                                    "sim time" if sim_time else "wall-clock receive time")
        self.topics: dict[str, _Topic] = {}
        self.clock_ns = 0
        self.first_ns: int | None = None
        self.tf = TfPairs()
        self.path: Path | None = None
        self.until_ns: int | None = None  # messages of a later bag time are not written (a duration)

    def add_topic(self, topic: str, msgtype: str, offered_qos: list | None = None) -> str | None:
        """Record ``topic`` of ``msgtype``; None, or why it cannot be recorded (a type unknown to the
        typestore)."""
        if topic in self.topics:
            return None
        if topic in (TF_TOPIC, TF_STATIC_TOPIC):
            return f"{topic} is computed from the simulation's poses at the end, not recorded"
        if msgtype not in self.store.fielddefs:
            return f"type {msgtype} is unknown to the rosbags typestore (ROS 2 Jazzy)"
        fields = self.store.fielddefs[msgtype][1]
        stamped = bool(fields) and fields[0][1][1] in _STAMPED_FIRST
        conn = self.writer.add_connection(topic, msgtype, typestore=self.store,
                                          offered_qos_profiles=list(offered_qos or []))
        self.topics[topic] = _Topic(conn, stamped)
        return None

    def log_time(self, topic: _Topic, data: bytes | memoryview) -> int:
        """The message's bag time (module doc)."""
        if not self.sim_time:
            return time.time_ns()
        if topic.stamped:
            ns = cdr_stamp_ns(data)
            if 0 < ns <= self.clock_ns + WALL_STAMP_AHEAD_NS:
                return ns
        return self.clock_ns

    def write(self, topic: str, data: bytes | memoryview) -> bool:
        """One message of an added topic, serialized (CDR) as received; False if its bag time is past
        ``until_ns`` (then it is not written)."""
        t = self.topics[topic]
        if topic == CLOCK_TOPIC:
            self.clock_ns = max(self.clock_ns, cdr_stamp_ns(data))
        ns = self.log_time(t, data)
        if self.until_ns is not None and ns > self.until_ns:
            return False
        if self.first_ns is None or ns < self.first_ns:
            self.first_ns = ns
        self.writer.write(t.connection, ns, bytes(data))
        t.count += 1
        if topic == ODOM_TOPIC:
            self.tf.odom(cdr_stamp_ns(data), bytes(data))
        elif topic == JOINT_STATES_TOPIC:
            self.tf.joints(cdr_stamp_ns(data), bytes(data))
        return True

    def counts(self) -> dict[str, int]:
        return {name: t.count for name, t in self.topics.items()}

    def close(self) -> Path:
        """Add /tf (one TFMessage per odometry sample) and /tf_static (once, at the bag's first time), finish
        the bag and move it into the output directory; return the .mcap's path."""
        if self.path is not None:
            return self.path
        static, dynamic = tf_messages(self.tf.pairs, self.store)
        conn = self.writer.add_connection(TF_STATIC_TOPIC, TF_TYPE, typestore=self.store,
                                          offered_qos_profiles=[_qos(True, True, 1)])
        self.writer.write(conn, self.first_ns or 0, static)
        self.topics[TF_STATIC_TOPIC] = _Topic(conn, False, 1)
        conn = self.writer.add_connection(TF_TOPIC, TF_TYPE, typestore=self.store,
                                          offered_qos_profiles=[_qos(True, False, 100)])
        for ns, data in dynamic:
            self.writer.write(conn, ns, data)
        self.topics[TF_TOPIC] = _Topic(conn, True, len(dynamic))
        self.writer.close()
        bag_dir = self._tmp / BAG_NAME
        for f in bag_dir.iterdir():
            f.replace(self.out_dir / f.name)
        shutil.rmtree(self._tmp, ignore_errors=True)
        self.path = self.out_dir / f"{BAG_NAME}.mcap"
        return self.path

    def __enter__(self) -> BagRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TfPairs:
    """The /odom/ground_truth and /joint_states messages of the same stamp, as they arrive in any order
    (a joint state is kept until its odometry sample comes; re-sent states are harmless)."""

    KEEP = 256  # recent joint states kept per stamp (odometry comes every few control periods)

    def __init__(self) -> None:
        self.pairs: list[tuple[int, bytes, bytes]] = []  # (stamp ns, odometry, joint state)
        self._joints: dict[int, bytes] = {}
        self._odom: dict[int, bytes] = {}

    def odom(self, ns: int, data: bytes) -> None:
        js = self._joints.get(ns)
        if js is None:
            self._odom[ns] = data
            if len(self._odom) > self.KEEP:
                del self._odom[min(self._odom)]
        else:
            self.pairs.append((ns, data, js))

    def joints(self, ns: int, data: bytes) -> None:
        odom = self._odom.pop(ns, None)
        if odom is not None:
            self.pairs.append((ns, odom, data))
        self._joints[ns] = data
        if len(self._joints) > self.KEEP:
            del self._joints[min(self._joints)]


def _tf_message(store: Any, transforms: list, ns: int) -> bytes:
    """A serialized tf2_msgs/TFMessage of frames.Transform's, stamped ``ns``."""
    T = store.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    TransformStamped, Transform = T["geometry_msgs/msg/TransformStamped"], T["geometry_msgs/msg/Transform"]
    Vector3, Quaternion = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    msgs = []
    for tr in transforms:
        p, q = tr.translation, tr.quat_wxyz
        msgs.append(TransformStamped(
            header=Header(stamp=stamp, frame_id=tr.parent), child_frame_id=tr.child,
            transform=Transform(translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                rotation=Quaternion(x=float(q[1]), y=float(q[2]), z=float(q[3]),
                                                    w=float(q[0])))))
    return bytes(store.serialize_cdr(T[TF_TYPE](transforms=msgs), TF_TYPE))


def tf_messages(pairs: list[tuple[int, bytes, bytes]], store: Any) -> tuple[bytes, list[tuple[int, bytes]]]:
    """(/tf_static's message, [(stamp, /tf message)]) from (stamp, odometry, joint state) samples.

    The model is posed exactly as the sim was: the floating base from the odometry pose, every joint named
    in the joint state at its position; then robot/frames.py gives the transforms: ``odom -> base_link``
    (parent: the odometry's frame_id) and the links that move go to /tf, the welded links and the site
    frames (``imu``) to /tf_static (they do not depend on the pose)."""
    import mujoco

    from cpg_walker.robot import frames
    from cpg_walker.robot.hoap2 import MODEL_PATH

    model = mujoco.MjModel.from_xml_path(str(MODEL_PATH))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    fixed = frames.fixed_links(model)
    static = [t for t in frames.body_transforms(model, data) if t.child in fixed] \
        + frames.site_transforms(model, data)
    static_msg = _tf_message(store, static, 0)
    out = []
    for ns, odom_raw, js_raw in pairs:
        odom = deserialize(store, odom_raw, "nav_msgs/msg/Odometry")
        js = deserialize(store, js_raw, "sensor_msgs/msg/JointState")
        p, o = odom.pose.pose.position, odom.pose.pose.orientation
        frames.set_pose(model, data, (p.x, p.y, p.z), (o.w, o.x, o.y, o.z),
                        zip(js.name, js.position, strict=False))
        mujoco.mj_kinematics(model, data)
        base = frames.odom_transform(model, data)
        base = frames.Transform(odom.header.frame_id or base.parent, base.child, base.translation,
                                base.quat_wxyz)
        moving = [t for t in frames.body_transforms(model, data) if t.child not in fixed]
        out.append((ns, _tf_message(store, [base, *moving], ns)))
    # the static message carries the first sample's stamp (any time is valid for a static transform)
    if pairs:
        static_msg = _tf_message(store, static, pairs[0][0])
    return static_msg, out


# ------------------------------------------------------------------------------------------- reading

def read_topics(path: str | Path, topics: list[str] | None = None) -> dict[str, list[tuple[int, Any]]]:
    """{topic: [(bag time ns, deserialized message), ...]} of a recording (all topics, or ``topics``), in
    time order: a rosbag2 directory (or its .mcap beside metadata.yaml) read with rosbags' Reader, a lone
    ROS 2 .mcap with the mcap reader (its messages decoded with the rosbags typestore). A missing or
    unreadable path: FileNotFoundError naming it."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such recording (a rosbag2 directory or a .mcap file)")
    d = p if p.is_dir() else p.parent
    if (d / "metadata.yaml").exists():
        return _read_rosbag2(d, topics)
    if p.is_file() and p.suffix == ".mcap":
        return _read_mcap(p, topics)
    raise InputError(f"{p}: not a recording (no metadata.yaml in {d}, not a .mcap file)")


def _read_rosbag2(d: Path, topics: list[str] | None) -> dict[str, list[tuple[int, Any]]]:
    from rosbags.rosbag2 import Reader, ReaderError
    from rosbags.serde import SerdeError

    store = typestore()
    out: dict[str, list[tuple[int, Any]]] = {}
    try:
        with Reader(d) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            for conn, ns, raw in reader.messages(connections=conns):
                out.setdefault(conn.topic, []).append((ns, deserialize(store, raw, conn.msgtype)))
    except (ReaderError, SerdeError, OSError, EOFError, ValueError, OverflowError, MemoryError,
            struct.error) as exc:
        raise InputError(f"{d}: not a readable rosbag2 recording (truncated or corrupt: "
                         f"{type(exc).__name__}: {' '.join(str(exc).split())})") from None
    return out


def _read_mcap(p: Path, topics: list[str] | None) -> dict[str, list[tuple[int, Any]]]:
    import struct

    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from rosbags.serde import SerdeError

    store = typestore()
    out: dict[str, list[tuple[int, Any]]] = {}
    with open(p, "rb") as f:
        try:
            for schema, channel, message in make_reader(f).iter_messages(topics=topics, log_time_order=True):
                if channel.message_encoding != "cdr" or schema is None:
                    continue
                out.setdefault(channel.topic, []).append(
                    (message.log_time, deserialize(store, message.data, schema.name)))
        except (OSError, EOFError, ValueError, OverflowError, MemoryError, struct.error, McapError,
                SerdeError, KeyError) as exc:  # KeyError: a schema name unknown to the typestore
            raise InputError(f"{p}: not a readable MCAP recording (truncated or corrupt: "
                             f"{type(exc).__name__}: {exc})") from None
    return out
