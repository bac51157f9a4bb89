"""Leg odometry of the HOAP-2 from what the robot itself senses: joint angles, the chest IMU and the sole
loads (no ground truth). The estimate is ``odom -> base_link`` (REP-105; base_link = the ``torso`` body).

* **Orientation.** Roll and pitch are the IMU's (a real IMU's gravity-referenced fusion gives them
  without drift); yaw is integrated from the gyro (Euler rate of the ZYX angles, trapezoidal), because
  the HOAP-2 has no magnetometer and a real IMU's yaw drifts. The simulated IMU's quaternion carries the
  exact world yaw: it is used once, at the first sample, as the heading the odom frame starts with (so
  the estimate and /odom/ground_truth share a frame), never after.
* **Position.** Leg kinematics from the MJCF (hoap2.xml, a private MjData: free joint at the origin, the
  joint angles set, ``mj_kinematics``) give each sole (``lleg_sole``/``rleg_sole`` bodies) in the base
  frame, ``p_i(q)``. A foot on the ground (the robot layer's contact hysteresis, robot/contact.py) is held
  at an anchor in the odom frame; the base is ``a_i - R p_i`` averaged over the anchored feet, weighted by
  each sole's load above the lift threshold (a blend in double support, continuous as a foot unloads).
  A foot that touches down is anchored where the estimate puts it at that instant, so re-anchoring never
  moves the base (with ``flat_floor``, its anchor's height is set to the floor's: a prior of a flat
  floor, which stops the height from drifting). With no foot on the ground the last anchors hold.
* **Twist** (base frame): the position's rate of change, low-passed (``velocity_filter``), and the gyro.
* **Covariance**: grows with the distance walked and the angle turned, each summed from one left
  touchdown to the next (a stride: the torso's sway within it cancels; standing adds nothing), at the
  rates measured against ground truth (config/odom.yaml; docs/odometry.md).

Constants: config/odom.yaml (``OdometryConfig.load``), the file odom_node gets as its parameters. Bad
input (non-finite values, unknown or missing joints, time going back) raises ValueError with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import mujoco
import numpy as np

from cpg_walker.robot.contact import CONTACT_OFF_N, CONTACT_ON_N
from cpg_walker.robot.hoap2 import MODEL_PATH, SOLES

#: odom_node's name: its parameters file (config/odom.yaml) holds the estimator's constants too.
ODOM_NODE = "odom"
BASE_BODY = "torso"
IMU_SITE = "imu"


#: OdometryConfig field -> its key in config/odom.yaml (flattened like ROS)
CONFIG_KEYS: dict[str, str] = {
    "flat_floor": "flat_floor", "velocity_filter": "velocity_filter",
    **{f: f"covariance.{f}" for f in (
        "position_sigma0", "position_per_m", "position_per_rad", "z_sigma0", "z_per_m", "tilt_sigma",
        "yaw_sigma0", "yaw_per_rad", "yaw_per_m", "linear_velocity_sigma", "angular_velocity_sigma")}}


@dataclass(frozen=True)
class OdometryConfig:
    """The estimator's constants (config/odom.yaml, ``ros__parameters``, flattened like ROS). Standard
    deviations: m and rad; rates per m walked and per rad turned; times in s."""

    flat_floor: bool
    velocity_filter: float
    position_sigma0: float
    position_per_m: float
    position_per_rad: float
    z_sigma0: float
    z_per_m: float
    tilt_sigma: float
    yaw_sigma0: float
    yaw_per_rad: float
    yaw_per_m: float
    linear_velocity_sigma: float
    angular_velocity_sigma: float

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "flat_floor":
                if not isinstance(v, bool):
                    raise ValueError(f"odometry: flat_floor must be true or false, got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
                raise ValueError(f"odometry: {CONFIG_KEYS[f.name]} must be a finite number >= 0, got {v!r}")

    @classmethod
    def from_params(cls, params: dict) -> OdometryConfig:
        """From flattened parameters (node parameters or the file's); other keys are ignored."""
        missing = [k for k in CONFIG_KEYS.values() if k not in params]
        if missing:
            raise ValueError(f"odometry: missing parameter(s) {', '.join(missing)}")
        return cls(**{f: params[k] for f, k in CONFIG_KEYS.items()})

    @classmethod
    def load(cls, path: str | Path | None = None, **overrides: object) -> OdometryConfig:
        """config/odom.yaml's values (or ``path``'s), with ``overrides`` by field name."""
        from cpg_walker.paths import ros_parameters

        params = ros_parameters("odom.yaml" if path is None else Path(path), ODOM_NODE)
        for name, value in overrides.items():
            if name not in CONFIG_KEYS:
                raise ValueError(f"odometry: unknown setting {name!r}")
            params[CONFIG_KEYS[name]] = value
        return cls.from_params(params)


@dataclass(frozen=True)
class OdometryEstimate:
    """The estimate at sim time ``t``: base position (m) and orientation (w, x, y, z) in odom, twist in
    the base frame (m/s, rad/s), 6x6 covariances (x, y, z, rot x, rot y, rot z; REP-105 order), the feet
    anchored (left, right), the distance walked (m) and angle turned (rad) the covariance grew with."""

    t: float
    position: np.ndarray
    quat_wxyz: np.ndarray
    linear: np.ndarray
    angular: np.ndarray
    pose_covariance: np.ndarray
    twist_covariance: np.ndarray
    anchored: tuple[bool, bool]
    distance_m: float
    turned_rad: float


def zyx_angles(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation matrix, ZYX convention: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    return roll, pitch, yaw


def zyx_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def quat_matrix(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q, dtype=float))
    return m.reshape(3, 3)


def matrix_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return q


class LegKinematics:
    """The soles' positions in the base frame from joint angles, by the MJCF model's forward kinematics."""

    def __init__(self, model_path: str | Path = MODEL_PATH):
        m = self.model = mujoco.MjModel.from_xml_path(str(model_path))
        self.data = mujoco.MjData(m)
        base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY)
        free = int(m.body_jntadr[base])
        if base < 0 or m.body_jntnum[base] != 1 or m.jnt_type[free] != mujoco.mjtJoint.mjJNT_FREE:
            raise ValueError(f"{model_path}: body {BASE_BODY!r} needs one free joint")
        a = int(m.jnt_qposadr[free])
        self.data.qpos[a:a + 7] = (0, 0, 0, 1, 0, 0, 0)  # the base at the odom origin: x* = base frame
        self.soles = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, s) for s in SOLES]
        # the hinges between the base and each sole: the joints the estimate needs
        chain: list[str] = []
        for b in self.soles:
            while b != base:
                for j in range(int(m.body_jntadr[b]), int(m.body_jntadr[b] + m.body_jntnum[b])):
                    chain.append(m.joint(j).name)
                b = int(m.body_parentid[b])
        self.required = frozenset(chain)
        self.qadr = {m.joint(j).name: int(m.jnt_qposadr[j]) for j in range(m.njnt)
                     if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}
        sole_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, SOLES[0])
        #: height of a sole body's origin above the floor it stands on (half the plate's thickness)
        self.sole_height = float(m.geom_size[sole_geom, 2])
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, IMU_SITE)
        if site < 0 or int(m.site_bodyid[site]) != base:
            raise ValueError(f"{model_path}: the IMU site {IMU_SITE!r} must be on body {BASE_BODY!r}")
        #: the IMU's orientation in the base frame
        self.imu_in_base = quat_matrix(m.site_quat[site])
        self._names: tuple[str, ...] | None = None
        self._adr = np.zeros(0, dtype=int)

    def addresses(self, names: Sequence[str]) -> np.ndarray:
        """qpos addresses of ``names`` (cached for the last list); ValueError for an unknown name or a leg
        joint missing."""
        names = tuple(names)
        if names != self._names:
            unknown = [n for n in names if n not in self.qadr]
            if unknown:
                raise ValueError(f"unknown joint name(s) {unknown}")
            if len(set(names)) != len(names):
                raise ValueError("duplicate joint names")
            missing = sorted(self.required - set(names))
            if missing:
                raise ValueError(f"joint(s) {missing} missing: the legs' kinematics needs them")
            self._adr = np.array([self.qadr[n] for n in names], dtype=int)
            self._names = names
        return self._adr

    def soles_in_base(self, names: Sequence[str], positions: Sequence[float]) -> np.ndarray:
        """(2, 3): the left and right sole bodies' origins in the base frame (m) at joint angles
        ``positions`` (rad) of the joints ``names``."""
        adr = self.addresses(names)
        q = np.asarray(positions, dtype=float)
        if q.shape != adr.shape:
            raise ValueError(f"{len(adr)} joint names but {q.size} positions")
        if not np.isfinite(q).all():
            raise ValueError("non-finite joint position")
        self.data.qpos[adr] = q
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.xpos[self.soles].copy()


class LegOdometry:
    """The estimator (module docstring). ``update`` once per sensor sample, ``estimate`` any time after."""

    def __init__(self, config: OdometryConfig | None = None, kinematics: LegKinematics | None = None):
        self.config = OdometryConfig.load() if config is None else config
        self.kin = LegKinematics() if kinematics is None else kinematics
        self.t: float | None = None
        self.base = np.zeros(3)
        self.R = np.eye(3)
        self.yaw = 0.0
        self.yaw_rate = 0.0
        self.anchors = np.zeros((2, 3))
        self.anchored = [False, False]
        self.down = [False, False]
        self.velocity = np.zeros(3)
        self.omega = np.zeros(3)
        self.distance = 0.0
        self.turned = 0.0
        self._stride: tuple[np.ndarray, float] | None = None  # (base xy, yaw) at the last left touchdown

    # ------------------------------------------------------------------------------------------ update
    def update(self, t: float, names: Sequence[str], positions: Sequence[float],
               imu_quat_wxyz: Sequence[float], gyro: Sequence[float], loads: Sequence[float]) -> None:
        """One sample: sim time ``t`` (s), joint angles by name (rad), the IMU's orientation (w, x, y, z)
        and angular velocity (rad/s, IMU frame), the (left, right) sole loads (N)."""
        qi = np.asarray(imu_quat_wxyz, dtype=float).reshape(-1)
        w = np.asarray(gyro, dtype=float).reshape(-1)
        f = np.asarray(loads, dtype=float).reshape(-1)
        if qi.size != 4 or w.size != 3 or f.size != 2:
            raise ValueError(f"expected a 4-value quaternion, 3 gyro and 2 load values, got {qi.size}, "
                             f"{w.size}, {f.size}")
        if not (math.isfinite(t) and np.isfinite(qi).all() and np.isfinite(w).all() and np.isfinite(f).all()):
            raise ValueError("non-finite time, IMU or load value")
        norm = float(np.linalg.norm(qi))
        if abs(norm - 1.0) > 0.01:
            raise ValueError(f"IMU quaternion of norm {norm:.4g}, not a rotation")
        if self.t is not None and t < self.t:
            raise ValueError(f"time went back from {self.t:.6f} s to {t:.6f} s")
        feet = self.kin.soles_in_base(names, positions)  # validates the joints
        # orientation: the IMU's tilt, the heading integrated from the gyro
        R_imu = quat_matrix(qi / norm)
        R_meas = R_imu @ self.kin.imu_in_base.T
        omega = self.kin.imu_in_base @ w  # base frame
        roll, pitch, yaw_meas = zyx_angles(R_meas)
        rate = (math.sin(roll) * omega[1] + math.cos(roll) * omega[2]) / max(math.cos(pitch), 1e-3)
        first = self.t is None
        dt = 0.0 if first else t - self.t
        self.yaw = yaw_meas if first else self.yaw + 0.5 * (rate + self.yaw_rate) * dt
        self.yaw_rate = rate
        self.R = zyx_matrix(roll, pitch, self.yaw)
        self.omega = omega
        r = feet @ self.R.T  # the soles relative to the base, odom axes
        down = self._contacts(f)
        h = self.kin.sole_height
        if first:  # the base above the lower sole resting on the floor, at x = y = 0
            base = np.array([0.0, 0.0, h - float(r[:, 2].min())])
            self.anchors = base + r
            self.anchored = [True, True] if not any(down) else list(down)
        else:
            support = [i for i in (0, 1) if self.anchored[i] and down[i]] or \
                      [i for i in (0, 1) if self.anchored[i]]
            wts = np.array([max(f[i] - CONTACT_OFF_N, 0.0) for i in support])
            wts = wts / wts.sum() if wts.sum() > 0 else np.full(len(support), 1.0 / len(support))
            base = sum(wi * (self.anchors[i] - r[i]) for wi, i in zip(wts, support, strict=True))
            for i in (0, 1):
                if down[i] and not self.anchored[i]:  # touchdown: anchored where the estimate has it now
                    if i == 0:
                        self._accumulate(base)
                    self.anchors[i] = base + r[i]
                    if self.config.flat_floor:
                        self.anchors[i, 2] = h
                    self.anchored[i] = True
                elif self.anchored[i] and not down[i] and any(down):  # lifted: released
                    self.anchored[i] = False
        if not first and dt > 0:
            tau = self.config.velocity_filter
            a = 1.0 if tau <= 0 else min(1.0, dt / tau)
            self.velocity += a * ((base - self.base) / dt - self.velocity)
        self.base = base
        self.t = t

    def _contacts(self, loads: np.ndarray) -> list[bool]:
        """The feet on the ground: on above CONTACT_ON_N, lifted below CONTACT_OFF_N (robot/contact.py)."""
        for i in (0, 1):
            if not self.down[i] and loads[i] > CONTACT_ON_N:
                self.down[i] = True
            elif self.down[i] and loads[i] < CONTACT_OFF_N:
                self.down[i] = False
        return list(self.down)

    def _accumulate(self, base: np.ndarray) -> None:
        """At a left touchdown: the distance walked and the angle turned since the previous one."""
        if self._stride is not None:
            xy0, yaw0 = self._stride
            self.distance += float(np.linalg.norm(base[:2] - xy0))
            self.turned += abs(self.yaw - yaw0)
        self._stride = (base[:2].copy(), self.yaw)

    # ---------------------------------------------------------------------------------------- output
    def estimate(self) -> OdometryEstimate:
        """The current estimate; ValueError before the first ``update``."""
        if self.t is None:
            raise ValueError("no estimate before the first update")
        c = self.config
        d, th = self.distance, self.turned
        s_xy = c.position_sigma0 + c.position_per_m * d + c.position_per_rad * th
        s_z = c.z_sigma0 + c.z_per_m * d
        s_yaw = c.yaw_sigma0 + c.yaw_per_rad * th + c.yaw_per_m * d
        pose_cov = np.diag([s_xy ** 2, s_xy ** 2, s_z ** 2, c.tilt_sigma ** 2, c.tilt_sigma ** 2, s_yaw ** 2])
        twist_cov = np.diag([c.linear_velocity_sigma ** 2] * 3 + [c.angular_velocity_sigma ** 2] * 3)
        return OdometryEstimate(t=self.t, position=self.base.copy(), quat_wxyz=matrix_quat(self.R),
                                linear=self.R.T @ self.velocity, angular=self.omega.copy(),
                                pose_covariance=pose_cov, twist_covariance=twist_cov,
                                anchored=(self.anchored[0], self.anchored[1]), distance_m=d, turned_rad=th)
