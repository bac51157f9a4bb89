"""Pure helpers of the ROS nodes (no rclpy, no message types): joint-command validation and stamps.

A joint command names any subset of the HOAP-2 joints and gives one value per name in each non-empty
array (the ``sensor_msgs/JointState`` convention). ``validate_joint_command`` turns one into index and
value arrays or raises ValueError with the reason, so a bad message never reaches the robot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpg_walker.robot.joints import JOINT_NAMES

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
    if not everything:
        if not names:
            raise ValueError("no joint names")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"duplicate joint name(s) {dup}")
        index = _INDEX if known is JOINT_NAMES else {n: i for i, n in enumerate(known)}
        unknown = [n for n in names if n not in index]
        if unknown:
            raise ValueError(f"unknown joint name(s) {unknown[:5]}{' ...' if len(unknown) > 5 else ''}")
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
    idx = _ALL_INDEX if everything else np.array([index[n] for n in names], dtype=int)
    return JointCommand(idx, fields["position"], fields["velocity"], fields["effort"])


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
