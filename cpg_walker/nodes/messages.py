"""ROS message building and reading for the nodes (message types only; no rclpy node machinery); a message
type's class from its name (``message_class``).

The builders of the messages published every control period return the message *serialized*: rclpy's
``Publisher.publish`` takes bytes as they are, which skips its field-by-field Python-to-C conversion
(10-25 us a message here, more than the rest of a publish). Each builder has the middleware serialize
one message of its fixed layout (fixed joint names, array lengths and frame ids) with marker values in the
variable fields, finds the markers in the bytes, and from then on writes the numbers into a copy of those
bytes. The layout is therefore the middleware's own (no CDR rules restated here); test/test_ros_units.py
deserializes the output and compares it, field by field and bit for bit, with the message built directly.
"""

from __future__ import annotations

import array
import importlib
import struct
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from cpg_walker.errors import InputError, ToolError
from cpg_walker.nodes.validation import (
    JointCommand,
    from_ns,
    to_ns,
    validate_joint_command,
    validate_joint_trajectory,
)
from cpg_walker.robot.frames import BASE_LINK, ODOM_FRAME, Transform
from cpg_walker.robot.frames import FOOT_LOAD_FRAMES as FOOT_LOAD_FRAMES  # /foot_load/<side>: (side, frame)
from cpg_walker.robot.frames import IMU_FRAME as IMU_FRAME  # frame of /imu (the chest IMU site)
from cpg_walker.robot.trajectory import Trajectory

#: Marker stamp (sec, nanosec) and the marker doubles' base: values no message field holds by chance.
_MARK_SEC, _MARK_NSEC = 0x5EC05EC0, 0x0DD5EED5
_MARK_BASE = -1.2345678901234567e-200
_STAMP = struct.Struct("=iI")  # builtin_interfaces/Time, native byte order as the middleware writes it


def message_class(type_name: str) -> type:
    """``sensor_msgs/msg/JointState`` (or ``sensor_msgs/JointState``, as ros2 accepts) -> the generated
    Python class."""
    parts = type_name.split("/")
    if len(parts) == 2:
        parts.insert(1, "msg")
    if len(parts) != 3 or not all(parts):
        raise InputError(f"not a message type: {type_name!r} (expected pkg/msg/Type)")
    try:
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError) as exc:
        raise ToolError(f"message type {type_name} is not installed in this Python ({exc})") from None


def darray(x: np.ndarray) -> array.array:
    """A float64 numpy array as array('d') (the fast path of the generated message setters)."""
    out = array.array("d")
    out.frombytes(np.ascontiguousarray(x, dtype=np.float64).tobytes())
    return out


def stamp(ns: int) -> Time:
    sec, nanosec = from_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns(msg) -> int:
    """The header stamp of a stamped message as integer nanoseconds."""
    s = msg.header.stamp
    return to_ns(s.sec, s.nanosec)


def read_joint_command(msg: JointState, require: str = "position") -> JointCommand:
    """Validate a JointState as a command (see validation.validate_joint_command)."""
    return validate_joint_command(msg.name, msg.position, msg.velocity, msg.effort, require=require)


class _Serialized:
    """A message's serialized bytes (``buf``, patched in place) and the offsets of its variable fields.

    ``marks(n)`` hands out marker doubles for the caller to put into the message's variable fields;
    ``locate(msg, fields)`` serializes it and finds each field (name -> its marker values, or the marker
    stamp for ``"stamp"``) as a contiguous run of native doubles (int32 + uint32 for the stamp)."""

    def __init__(self) -> None:
        self._next = 0
        self.buf = bytearray()
        self.at: dict[str, int] = {}

    def marks(self, n: int) -> list[float]:
        out = [_MARK_BASE * (1.0 + (self._next + k) * 2.0**-30) for k in range(n)]
        self._next += n
        return out

    def locate(self, msg, fields: dict[str, list[float] | None]) -> None:
        from rclpy.serialization import serialize_message

        data = serialize_message(msg)
        for name, marks in fields.items():
            pattern = (_STAMP.pack(_MARK_SEC, _MARK_NSEC) if marks is None
                       else struct.pack(f"={len(marks)}d", *marks))
            if data.count(pattern) != 1:
                raise RuntimeError(f"{type(msg).__name__}: field {name!r} is not one contiguous run in the "
                                   "middleware's serialization; cannot publish it pre-serialized")
            self.at[name] = data.index(pattern)
        self.buf = bytearray(data)

    def stamp(self, ns: int) -> None:
        _STAMP.pack_into(self.buf, self.at["stamp"], *from_ns(ns))

    def doubles(self, name: str, values, n: int) -> None:
        a = np.ascontiguousarray(values, dtype=np.float64)
        if a.size != n:
            raise ValueError(f"{name} has {a.size} values, expected {n}")
        o = self.at[name]
        self.buf[o:o + 8 * n] = a.tobytes()

    def put(self, name: str, *values: float) -> None:
        struct.pack_into(f"={len(values)}d", self.buf, self.at[name], *values)


def _with_mark_stamp(msg):
    msg.header.stamp.sec, msg.header.stamp.nanosec = _MARK_SEC, _MARK_NSEC
    return msg


def read_joint_trajectory(msg: JointTrajectory) -> Trajectory:
    """Validate a JointTrajectory as a horizon of future targets (validation.validate_joint_trajectory):
    point i is at the header stamp + its time_from_start."""
    pts = msg.points
    return validate_joint_trajectory(
        msg.joint_names, stamp_ns(msg),
        [to_ns(p.time_from_start.sec, p.time_from_start.nanosec) for p in pts],
        [p.positions for p in pts], [p.velocities for p in pts])


class JointTrajectoryBuilder:
    """A JointTrajectory over fixed ``names`` and point times ``offsets_ns`` after its stamp; ``fill``
    sets the stamp and every point's positions and velocities ((K, J) arrays)."""

    def __init__(self, names: Sequence[str], offsets_ns: Sequence[int]):
        self.msg = JointTrajectory()
        self.msg.joint_names = list(names)
        points = []
        for off in offsets_ns:
            pt = JointTrajectoryPoint()
            pt.time_from_start.sec, pt.time_from_start.nanosec = from_ns(off)
            points.append(pt)
        self.msg.points = points
        self.points = self.msg.points

    def fill(self, ns: int, positions: np.ndarray, velocities: np.ndarray) -> JointTrajectory:
        self.msg.header.stamp.sec, self.msg.header.stamp.nanosec = from_ns(ns)
        for pt, q, qd in zip(self.points, positions, velocities, strict=True):
            pt.positions = darray(q)
            pt.velocities = darray(qd)
        return self.msg


class JointStateBuilder:
    """A serialized JointState over fixed ``names`` carrying the arrays in ``fields`` (each of len(names)
    values; the others empty). ``fill`` sets the stamp and whichever arrays are given (the rest keep their
    last values) and returns the bytes to publish; ``msg`` is the last filled message (bytes)."""

    def __init__(self, names: Sequence[str], frame_id: str = "",
                 fields: Sequence[str] = ("position", "velocity", "effort")):
        unknown = sorted(set(fields) - {"position", "velocity", "effort"})
        if unknown:
            raise ValueError(f"JointStateBuilder: unknown field(s) {unknown}")
        self.n = len(names)
        self.fields = tuple(fields)
        self._s = _Serialized()
        msg = _with_mark_stamp(JointState(name=list(names)))
        msg.header.frame_id = frame_id
        marks = {}
        for f in self.fields:
            marks[f] = self._s.marks(self.n)
            setattr(msg, f, marks[f])
        self._s.locate(msg, {"stamp": None, **marks})
        for f in self.fields:  # no marker values ever go out
            self._s.doubles(f, np.zeros(self.n), self.n)

    @property
    def msg(self) -> bytes:
        return bytes(self._s.buf)

    def fill(self, ns: int, position=None, velocity=None, effort=None) -> bytes:
        s = self._s
        s.stamp(ns)
        for name, value in (("position", position), ("velocity", velocity), ("effort", effort)):
            if value is not None:
                if name not in s.at:
                    raise ValueError(f"JointStateBuilder carries {self.fields}, not {name}")
                s.doubles(name, value, self.n)
        return bytes(s.buf)


class ClockBuilder:
    """A serialized rosgraph_msgs/Clock."""

    def __init__(self):
        self._s = _Serialized()
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = _MARK_SEC, _MARK_NSEC
        self._s.locate(msg, {"stamp": None})

    def fill(self, ns: int) -> bytes:
        self._s.stamp(ns)
        return bytes(self._s.buf)


class ImuBuilder:
    """A serialized sensor_msgs/Imu from Hoap2Sim.imu(); covariances are diagonal, fixed at construction."""

    def __init__(self, frame_id: str, orientation_var: float, gyro_var: float, accel_var: float):
        s = self._s = _Serialized()
        m = _with_mark_stamp(Imu())
        m.header.frame_id = frame_id
        m.orientation_covariance = np.diag([orientation_var] * 3).reshape(-1)
        m.angular_velocity_covariance = np.diag([gyro_var] * 3).reshape(-1)
        m.linear_acceleration_covariance = np.diag([accel_var] * 3).reshape(-1)
        marks = {"orientation": s.marks(4), "gyro": s.marks(3), "accel": s.marks(3)}
        o, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
        o.x, o.y, o.z, o.w = marks["orientation"]  # the message's field order: x, y, z, w
        w.x, w.y, w.z = marks["gyro"]
        a.x, a.y, a.z = marks["accel"]
        s.locate(m, {"stamp": None, **marks})
        self.fill(0, np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

    def fill(self, ns: int, gyro: np.ndarray, accel: np.ndarray, quat_wxyz: np.ndarray) -> bytes:
        s = self._s
        s.stamp(ns)
        w, x, y, z = (float(v) for v in quat_wxyz)
        s.put("orientation", x, y, z, w)
        s.doubles("gyro", gyro, 3)
        s.doubles("accel", accel, 3)
        return bytes(s.buf)


class WrenchBuilder:
    """A serialized geometry_msgs/WrenchStamped in ``frame_id``."""

    def __init__(self, frame_id: str):
        s = self._s = _Serialized()
        m = _with_mark_stamp(WrenchStamped())
        m.header.frame_id = frame_id
        marks = s.marks(6)
        f, t = m.wrench.force, m.wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = marks
        s.locate(m, {"stamp": None, "wrench": marks})
        s.doubles("wrench", np.zeros(6), 6)

    def fill(self, ns: int, force: np.ndarray, torque: np.ndarray) -> bytes:
        s = self._s
        s.stamp(ns)
        f0, f1, f2 = force.tolist()
        t0, t1, t2 = torque.tolist()
        s.put("wrench", f0, f1, f2, t0, t1, t2)
        return bytes(s.buf)


class OdometryBuilder:
    """Ground-truth nav_msgs/Odometry, serialized: pose in ``frame_id``, twist in the base frame
    ``child_frame_id`` (ROS convention). Covariances are zero: the values are exact (ground truth, not
    an estimate)."""

    def __init__(self, frame_id: str = ODOM_FRAME, child_frame_id: str = BASE_LINK):
        s = self._s = _Serialized()
        m = _with_mark_stamp(Odometry())
        m.header.frame_id = frame_id
        m.child_frame_id = child_frame_id
        marks = {"pose": s.marks(7), "twist": s.marks(6)}
        p, o = m.pose.pose.position, m.pose.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = marks["pose"]
        tl, ta = m.twist.twist.linear, m.twist.twist.angular
        tl.x, tl.y, tl.z, ta.x, ta.y, ta.z = marks["twist"]
        s.locate(m, {"stamp": None, **marks})
        self.fill(0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3))

    def fill(self, ns: int, pos: np.ndarray, quat_wxyz: np.ndarray, lin_world: np.ndarray,
             ang_world: np.ndarray) -> bytes:
        s = self._s
        s.stamp(ns)
        w, x, y, z = (float(v) for v in quat_wxyz)
        px, py, pz = (float(v) for v in pos)
        s.put("pose", px, py, pz, x, y, z, w)
        R = _quat_to_matrix(w, x, y, z)
        s.doubles("twist", np.concatenate([R.T @ lin_world, R.T @ ang_world]), 6)
        return bytes(s.buf)


def transform_stamped(ns: int, t: Transform) -> TransformStamped:
    """A /tf entry: ``t.child``'s pose in ``t.parent`` (robot.frames.Transform), stamped ``ns``."""
    msg = TransformStamped()
    msg.header.stamp = stamp(ns)
    msg.header.frame_id, msg.child_frame_id = t.parent, t.child
    tr, q = msg.transform.translation, msg.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in t.translation)
    q.w, q.x, q.y, q.z = (float(v) for v in t.quat_wxyz)
    return msg


def _quat_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
