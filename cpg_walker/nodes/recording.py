"""A recording of the ROS graph as one rosbag2 MCAP file (ROS 2 CDR), written with rosbags' rosbag2 Writer.

``BagRecorder`` takes the messages as the middleware delivered them (serialized CDR, never re-encoded),
writes them as they come (without the unset bytes Fast DDS sends after some messages' last field:
``canonical_cdr``, so that stock rosbags, mcap_ros2 and Foxglove all decode them), and at ``close``
adds ``/tf`` and ``/tf_static`` computed from the simulation's exact poses: the MuJoCo model posed from
each ``/odom/ground_truth`` (the floating base, double precision) and the ``/joint_states`` of the same
stamp (every joint), its links' transforms from robot/frames.py.
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
from cpg_walker.nodes import interface as ifc

#: File name (without suffix) of the bag in its directory: DIR/recording.mcap + DIR/metadata.yaml.
BAG_NAME = "recording"
CLOCK_TOPIC = ifc.CLOCK
ODOM_TOPIC = ifc.ODOM_GROUND_TRUTH
JOINT_STATES_TOPIC = ifc.JOINT_STATES
TF_TOPIC, TF_STATIC_TOPIC = ifc.TF, ifc.TF_STATIC
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
    """A CDR message as rosbags' message object (``store.deserialize_cdr`` of its ``canonical_cdr``: a
    recording of ``ros2 bag record``, or of this recorder before it trimmed, has Fast DDS's unset end
    bytes, which rosbags rejects)."""
    return store.deserialize_cdr(canonical_cdr(store, data, msgtype), msgtype)


# ------------------------------------------------------------------------------------ canonical CDR
# Fast DDS (rmw_fastrtps, Jazzy) sizes a message's buffer as if each EMPTY sequence of 8-byte numbers
# (float64[], int64[], uint64[]) were aligned to 8 after its length, which its serializer does not do for
# an empty one, and sends the whole buffer: 4 unset bytes (old memory) after the last field for each such
# sequence that ends off the 8-byte grid (/joint_targets' empty effort: 4, /joint_torques' empty position
# and velocity: 8). CDR readers stop at the last field; rosbags' deserialize_cdr also checks that no more
# than 3 bytes (the end's 4-byte alignment) follow and rejects these messages. rclpy's serialize_message
# writes the same bytes (same typesupport). The recorder cuts them: each message of a type with such a
# sequence is walked to its last field (``cdr_end``: lengths only, nothing decoded) and written up to there,
# zero-padded to 4 bytes, when more than 3 bytes follow; every byte it keeps is as received.

_U32 = (struct.Struct(">I").unpack_from, struct.Struct("<I").unpack_from)  # by the encapsulation's LE bit
_SIZES = {"bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4,
          "uint32": 4, "float32": 4, "int64": 8, "uint64": 8, "float64": 8}


def _walk_lines(store: Any, desc: tuple, lines: list[str], ind: str, depth: int) -> None:
    """Python lines that advance ``p`` (offset in the CDR body) over one value of field type ``desc``
    (rosbags' fielddefs: (Nodetype, ...)); KeyError for a type the walk does not know (wstring)."""
    from rosbags.interfaces import Nodetype

    kind, arg = desc
    if kind == Nodetype.NAME:
        for _, field in store.fielddefs[arg][1]:
            _walk_lines(store, field, lines, ind, depth)
    elif kind == Nodetype.BASE:
        if arg[0] == "string":
            lines += [f"{ind}p = (p + 3) & -4", f"{ind}p += 4 + u32(b, p + 4)[0]"]
        else:
            size = _SIZES[arg[0]]
            lines += [f"{ind}p = (p + {size - 1}) & -{size}"] if size > 1 else []
            lines += [f"{ind}p += {size}"]
    else:  # ARRAY (fixed length) or SEQUENCE (uint32 length first)
        (ekind, earg), length = arg
        n = f"n{depth}"
        if kind == Nodetype.SEQUENCE:
            lines += [f"{ind}p = (p + 3) & -4", f"{ind}{n} = u32(b, p + 4)[0]", f"{ind}p += 4"]
        else:
            lines += [f"{ind}{n} = {length}"]
        if ekind == Nodetype.BASE and earg[0] != "string":
            size = _SIZES[earg[0]]
            lines += [f"{ind}if {n}:", f"{ind}    p = ((p + {size - 1}) & -{size}) + {n} * {size}"]
        else:
            lines += [f"{ind}for _ in range({n}):"]
            _walk_lines(store, (ekind, earg), lines, ind + "    ", depth + 1)


def _has_long_sequence(store: Any, msgtype: str) -> bool:
    """Whether ``msgtype`` has (at any depth) a sequence of 8-byte numbers: the messages Fast DDS can end
    with unset bytes."""
    from rosbags.interfaces import Nodetype

    def walk(desc: tuple) -> bool:
        kind, arg = desc
        if kind == Nodetype.NAME:
            return any(walk(f) for _, f in store.fielddefs[arg][1])
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (ekind, earg), _ = arg
            if kind == Nodetype.SEQUENCE and ekind == Nodetype.BASE and _SIZES.get(earg[0]) == 8:
                return True
            return walk((ekind, earg))
        return False

    return walk((Nodetype.NAME, msgtype))


_ENDS: dict[tuple[int, str], tuple[Any, Any]] = {}  # (id(store), msgtype): (store, end)


def cdr_end(store: Any, msgtype: str) -> Any:
    """``end(data) -> offset`` just past the last field of a CDR message of ``msgtype`` (encapsulation
    header included), for the types Fast DDS can end with unset bytes; None for the others (and for a type
    with a wstring, which the walk does not know). Generated Python, like rosbags' own deserializers."""
    from rosbags.interfaces import Nodetype

    key = (id(store), msgtype)
    if key not in _ENDS:
        func = None
        if _has_long_sequence(store, msgtype):
            lines = ["def end(b):", "    u32 = U32[b[1] & 1]", "    p = 0"]
            try:
                _walk_lines(store, (Nodetype.NAME, msgtype), lines, "    ", 0)
            except KeyError:
                lines = []
            if lines:
                namespace: dict[str, Any] = {"U32": _U32}
                exec("\n".join([*lines, "    return p + 4"]), namespace)
                func = namespace["end"]
        _ENDS[key] = (store, func)  # the store kept: its id is not reused while cached
    return _ENDS[key][1]


def canonical_cdr(store: Any, data: bytes | memoryview, msgtype: str) -> bytes | memoryview:
    """``data`` without the unset bytes Fast DDS can send after the last field (more than the 0-3 bytes
    of CDR's end alignment: cut there, zero-padded to 4 bytes); every other message unchanged (the same
    object). A message shorter than its fields say (corrupt) is left as it is."""
    return _trimmed(cdr_end(store, msgtype), data)


def _trimmed(end: Any, data: bytes | memoryview) -> bytes | memoryview:
    if end is None or len(data) < 8 or data[0] != 0 or data[1] > 1:  # plain CDR (XCDR1) BE/LE only
        return data
    try:
        n = end(data)
    except (struct.error, IndexError):
        return data
    if len(data) - n <= 3 or n > len(data):
        return data
    return bytes(data[:n]) + bytes(-n % 4)


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
    end: Any = None  # cdr_end of its type: its messages are written without Fast DDS's unset end bytes


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
        self.topics[topic] = _Topic(conn, stamped, end=cdr_end(self.store, msgtype))
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
        """One message of an added topic, serialized (CDR) as received (``canonical_cdr``: without Fast
        DDS's unset bytes after the last field); False if its bag time is past ``until_ns`` (then it is
        not written)."""
        t = self.topics[topic]
        if t.end is not None:
            data = _trimmed(t.end, data)
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


#: Length of the MCAP file magic (b"\x89MCAP0\r\n"); a file no longer than it has no record.
MCAP_MAGIC_BYTES = 8


def _read_rosbag2(d: Path, topics: list[str] | None) -> dict[str, list[tuple[int, Any]]]:
    from rosbags.rosbag2 import Reader, ReaderError
    from rosbags.serde import SerdeError

    store = typestore()
    out: dict[str, list[tuple[int, Any]]] = {}
    for f in d.glob("*.mcap"):  # only MCAP's magic left: rosbags fails there with a TypeError (ord(''))
        if f.is_file() and f.stat().st_size <= MCAP_MAGIC_BYTES:
            raise InputError(f"{d}: not a readable rosbag2 recording (truncated or corrupt: {f.name} has "
                             f"{f.stat().st_size} bytes, no record after the MCAP magic)")
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
