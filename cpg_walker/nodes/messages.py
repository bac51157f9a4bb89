"""ROS message building and reading for the nodes (message types only; no rclpy node machinery).

Builders keep one message object each and refill it, so a 500 Hz loop does not rebuild 25-name lists.
Float arrays are handed to the messages as ``array.array('d')``, which the generated setters take without
checking element by element.
"""

from __future__ import annotations

import array
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from cpg_walker.nodes.validation import (
    JointCommand,
    from_ns,
    to_ns,
    validate_joint_command,
    validate_joint_trajectory,
)
from cpg_walker.robot.trajectory import Trajectory


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
    """A JointState over fixed ``names``; ``fill`` sets the stamp and whichever arrays are given."""

    def __init__(self, names: Sequence[str], frame_id: str = ""):
        self.msg = JointState()
        self.msg.name = list(names)
        self.msg.header.frame_id = frame_id

    def fill(self, ns: int, position=None, velocity=None, effort=None) -> JointState:
        sec, nanosec = from_ns(ns)
        self.msg.header.stamp.sec, self.msg.header.stamp.nanosec = sec, nanosec
        if position is not None:
            self.msg.position = darray(position)
        if velocity is not None:
            self.msg.velocity = darray(velocity)
        if effort is not None:
            self.msg.effort = darray(effort)
        return self.msg


class ClockBuilder:
    def __init__(self):
        self.msg = Clock()

    def fill(self, ns: int) -> Clock:
        self.msg.clock.sec, self.msg.clock.nanosec = from_ns(ns)
        return self.msg


class ImuBuilder:
    """sensor_msgs/Imu from Hoap2Sim.imu(); covariances are diagonal, fixed at construction."""

    def __init__(self, frame_id: str, orientation_var: float, gyro_var: float, accel_var: float):
        m = Imu()
        m.header.frame_id = frame_id
        m.orientation_covariance = np.diag([orientation_var] * 3).reshape(-1)
        m.angular_velocity_covariance = np.diag([gyro_var] * 3).reshape(-1)
        m.linear_acceleration_covariance = np.diag([accel_var] * 3).reshape(-1)
        self.msg = m

    def fill(self, ns: int, gyro: np.ndarray, accel: np.ndarray, quat_wxyz: np.ndarray) -> Imu:
        m = self.msg
        m.header.stamp.sec, m.header.stamp.nanosec = from_ns(ns)
        o = m.orientation
        o.w, o.x, o.y, o.z = (float(v) for v in quat_wxyz)
        w, a = m.angular_velocity, m.linear_acceleration
        w.x, w.y, w.z = (float(v) for v in gyro)
        a.x, a.y, a.z = (float(v) for v in accel)
        return m


class WrenchBuilder:
    def __init__(self, frame_id: str):
        self.msg = WrenchStamped()
        self.msg.header.frame_id = frame_id

    def fill(self, ns: int, force: np.ndarray, torque: np.ndarray) -> WrenchStamped:
        m = self.msg
        m.header.stamp.sec, m.header.stamp.nanosec = from_ns(ns)
        f, t = m.wrench.force, m.wrench.torque
        f.x, f.y, f.z = (float(v) for v in force)
        t.x, t.y, t.z = (float(v) for v in torque)
        return m


class OdometryBuilder:
    """Ground-truth nav_msgs/Odometry: pose in ``frame_id``, twist in the base frame ``child_frame_id``
    (ROS convention). Covariances are zero: the values are exact (ground truth, not an estimate)."""

    def __init__(self, frame_id: str = "world", child_frame_id: str = "torso"):
        self.msg = Odometry()
        self.msg.header.frame_id = frame_id
        self.msg.child_frame_id = child_frame_id

    def fill(self, ns: int, pos: np.ndarray, quat_wxyz: np.ndarray, lin_world: np.ndarray,
             ang_world: np.ndarray) -> Odometry:
        m = self.msg
        m.header.stamp.sec, m.header.stamp.nanosec = from_ns(ns)
        p, o = m.pose.pose.position, m.pose.pose.orientation
        p.x, p.y, p.z = (float(v) for v in pos)
        w, x, y, z = (float(v) for v in quat_wxyz)
        o.w, o.x, o.y, o.z = w, x, y, z
        R = _quat_to_matrix(w, x, y, z)
        lin, ang = R.T @ lin_world, R.T @ ang_world
        tl, ta = m.twist.twist.linear, m.twist.twist.angular
        tl.x, tl.y, tl.z = (float(v) for v in lin)
        ta.x, ta.y, ta.z = (float(v) for v in ang)
        return m


def _quat_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
