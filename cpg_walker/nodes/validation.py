"""Pure helpers of the ROS nodes (no rclpy, no message types): joint-command validation and stamps.

A joint command names any subset of the HOAP-2 joints and gives one value per name in each non-empty
array (the ``sensor_msgs/JointState`` convention). ``validate_joint_command`` turns one into index and
value arrays or raises ValueError with the reason, so a bad message never reaches the robot;
``validate_joint_trajectory`` does the same for a horizon of future targets (``JointTrajectory``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.trajectory import Trajectory

_INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}
_ALL_NAMES = list(JOINT_NAMES)
_ALL_INDEX = np.arange(len(JOINT_NAMES))
_ALL_INDEX.setflags(write=False)


@dataclass(frozen=True)
class JointCommand:
    """A validated command: ``index`` into JOINT_NAMES and the values per field (None = field absent)."""

    index: np.ndarray
    position: np.ndarray | None
    velocity: np.ndarray | None
    effort: np.ndarray | None


def validate_joint_command(
    names: Sequence[str],
    position: Sequence[float] = (),
    velocity: Sequence[float] = (),
    effort: Sequence[float] = (),
    require: str = "position",
    known: Sequence[str] = JOINT_NAMES,
) -> JointCommand:
    """Check a JointState-like command; ``require`` names the field that must be present.

    Rejects (ValueError with the reason): no names, duplicate or unknown names, a non-empty array whose
    length differs from the names', a missing required field, NaN or infinite values."""
    names = list(names)
    # every joint in JOINT_NAMES order (what the nodes send, 500 times a second): no name to check
    everything = known is JOINT_NAMES and names == _ALL_NAMES
    idx = _ALL_INDEX if everything else joint_index(names, known)
    fields: dict[str, np.ndarray | None] = {}
    for label, values in (("position", position), ("velocity", velocity), ("effort", effort)):
        arr = np.asarray(values, dtype=float).reshape(-1)
        if arr.size == 0:
            fields[label] = None
            continue
        if arr.size != len(names):
            raise ValueError(f"{label} has {arr.size} values for {len(names)} joint names")
        bad = ~np.isfinite(arr)
        if bad.any():
            which = [names[i] for i in np.flatnonzero(bad)][:5]
            raise ValueError(f"non-finite {label} for joint(s) {which}")
        fields[label] = arr
    if fields.get(require) is None:
        raise ValueError(f"no {require} values")
    return JointCommand(idx, fields["position"], fields["velocity"], fields["effort"])


def joint_index(names: Sequence[str], known: Sequence[str] = JOINT_NAMES) -> np.ndarray:
    """Indices of ``names`` in ``known``; ValueError for no names, duplicate or unknown names."""
    names = list(names)
    if not names:
        raise ValueError("no joint names")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"duplicate joint name(s) {dup}")
    index = _INDEX if known is JOINT_NAMES else {n: i for i, n in enumerate(known)}
    unknown = [n for n in names if n not in index]
    if unknown:
        raise ValueError(f"unknown joint name(s) {unknown[:5]}{' ...' if len(unknown) > 5 else ''}")
    return np.array([index[n] for n in names], dtype=int)


def validate_joint_trajectory(names: Sequence[str], start_ns: int, offsets_ns: Sequence[int],
                              positions: Sequence[Sequence[float]],
                              velocities: Sequence[Sequence[float]]) -> Trajectory:
    """Check a JointTrajectory-like horizon (points at ``start_ns`` + ``offsets_ns``) and return it as a
    `robot.trajectory.Trajectory`. Rejects (ValueError with the reason): bad names (as
    `validate_joint_command`), no points, point times negative or not strictly increasing, a point
    without one position per name, velocities in some points only or of the wrong length, NaN or inf.
    Points without velocities get them by finite differences (one point: 0)."""
    index = joint_index(names)
    n = len(index)
    offs = np.asarray(offsets_ns, dtype=np.int64).reshape(-1)
    if offs.size == 0:
        raise ValueError("no trajectory points")
    if offs[0] < 0 or np.any(np.diff(offs) <= 0):
        raise ValueError("point times (time_from_start) must be >= 0 and strictly increasing")
    q = _point_matrix("positions", positions, offs.size, n)
    if all(len(v) == 0 for v in velocities):
        qd = np.gradient(q, offs * 1e-9, axis=0) if offs.size > 1 else np.zeros_like(q)
    else:
        qd = _point_matrix("velocities", velocities, offs.size, n)
    return Trajectory(int(start_ns), offs, index, q, qd)


def _point_matrix(label: str, rows: Sequence[Sequence[float]], points: int, joints: int) -> np.ndarray:
    if len(rows) != points or any(len(r) != joints for r in rows):
        raise ValueError(f"every trajectory point needs {joints} {label} (one per joint name)")
    arr = np.array([np.asarray(r, dtype=float) for r in rows])
    if not np.isfinite(arr).all():
        raise ValueError(f"non-finite {label} in the trajectory")
    return arr


def reason_key(error: Exception | str) -> str:
    """The kind of a rejection (its first two words, e.g. 'unknown joint', 'position has'), used to
    throttle warnings per reason rather than per message."""
    return " ".join(str(error).split()[:2])


def to_ns(sec: int, nanosec: int) -> int:
    """A ROS stamp (sec, nanosec) as integer nanoseconds."""
    return int(sec) * 1_000_000_000 + int(nanosec)


def from_ns(ns: int) -> tuple[int, int]:
    """Integer nanoseconds as a ROS stamp (sec, nanosec)."""
    return divmod(int(ns), 1_000_000_000)


def period_ns(seconds: float) -> int:
    """A period in seconds as integer nanoseconds (exact stamps: t_k = k * period_ns)."""
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"period must be a positive number of seconds, got {seconds!r}")
    return round(seconds * 1e9)


def check_finite_scalar(name: str, value: object, minimum: float | None = None,
                        maximum: float | None = None) -> float:
    """A parameter value as a finite float within [minimum, maximum], else ValueError with the reason."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name} must be a number, got {type(value).__name__}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x}")
    if minimum is not None and x < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {x}")
    if maximum is not None and x > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {x}")
    return x


#: How far an orientation quaternion's norm may be from 1 and still be read as a rotation.
QUAT_NORM_TOLERANCE = 0.01


def validate_imu(frame_id: str, expected_frame: str, quat_wxyz: Sequence[float],
                 gyro: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """An /imu sample (orientation w, x, y, z and angular velocity rad/s) as two arrays, or ValueError with
    the reason: another frame than ``expected_frame``, a non-finite value, a quaternion whose norm is not
    1 (within QUAT_NORM_TOLERANCE; ROS marks an absent orientation with a zero quaternion)."""
    if frame_id != expected_frame:
        raise ValueError(f"frame {frame_id!r}, expected {expected_frame!r}")
    q = np.asarray(quat_wxyz, dtype=float).reshape(-1)
    w = np.asarray(gyro, dtype=float).reshape(-1)
    if q.size != 4 or w.size != 3:
        raise ValueError(f"expected a 4-value orientation and a 3-value angular velocity, got {q.size} "
                         f"and {w.size}")
    if not (np.isfinite(q).all() and np.isfinite(w).all()):
        raise ValueError("non-finite orientation or angular velocity")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOLERANCE:
        raise ValueError(f"orientation quaternion of norm {norm:.4g}, not a rotation")
    return q / norm, w


def validate_load(frame_id: str, expected_frame: str, force_z: float) -> float:
    """A /foot_load sample's vertical force (N, the sole load) as a float, or ValueError with the reason
    (another frame than ``expected_frame``, a non-finite force)."""
    if frame_id != expected_frame:
        raise ValueError(f"frame {frame_id!r}, expected {expected_frame!r}")
    f = float(force_z)
    if not math.isfinite(f):
        raise ValueError(f"non-finite force {f}")
    return f
