"""The simulated HOAP-2: a small class over the MuJoCo model with named, physical accessors (no ROS).

Arrays over "all joints" follow ``joints.JOINT_NAMES``. Torques are applied by ``step(torque, n)``; the
torque is held for the ``n`` physics steps (zero-order hold, as a servo amplifier does between commands).
Frames: world +x forward, +y left, +z up; the base is the torso (its origin on the waist-joint axis).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from cpg_walker.robot.joints import JOINT_NAMES

MODEL_PATH = Path(__file__).resolve().parent / "hoap2.xml"
SOLES = ("lleg_sole", "rleg_sole")


@dataclass(frozen=True)
class Imu:
    """Chest IMU reading: angular velocity (rad/s) and specific force (m/s^2), both in the IMU (torso)
    frame, plus the torso orientation quaternion (w, x, y, z) in the world frame."""

    gyro: np.ndarray
    accel: np.ndarray
    quat: np.ndarray

    def tilt(self) -> tuple[float, float]:
        """(lateral roll, sagittal pitch) of the chest in rad, see ``tilt_from_quat``."""
        return tilt_from_quat(self.quat)


def tilt_from_quat(q: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """(lateral roll, sagittal pitch) in rad from an orientation quaternion (w, x, y, z) of the chest, with
    the heading (yaw) removed: roll > 0 = leaning right (left side up), pitch > 0 = leaning forward — the
    paper's lateral and sagittal tilt. A ROS node computes it from /imu's orientation."""
    w, x, y, z = (float(v) for v in q)
    r00, r10 = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z)  # rotation matrix column 0 (x-axis)
    up = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))  # column 2 (z-axis)
    yaw = math.atan2(r10, r00)
    c, s = math.cos(yaw), math.sin(yaw)
    fx, fy = c * up[0] + s * up[1], -s * up[0] + c * up[1]
    return math.atan2(-fy, up[2]), math.atan2(fx, up[2])


#: Fallen = torso origin below this height (m; the standing crouch is ~0.285 m) ...
MIN_TORSO_HEIGHT_M = 0.18
#: ... or the torso z-axis tilted more than this from vertical (deg).
MAX_TILT_DEG = 50.0
#: The MuJoCo settings ``Hoap2Sim(config=...)`` may override for a sweep (the model's values otherwise).
PHYSICS_KEYS = ("timestep", "integrator", "armature", "joint_damping", "friction", "contact_solref")


@functools.lru_cache(maxsize=1)
def default_standing_posture() -> np.ndarray:
    """The standing posture over all joints: the first row of the recorded walk (crouch, arms down)."""
    from cpg_walker.robot.gait_data import GaitPlayback, load_gait

    gait = load_gait("walk")
    posture = GaitPlayback(gait, cycle=_NoCycle()).standing_posture()
    posture.setflags(write=False)
    return posture


class _NoCycle:
    start, period, end = 0.0, 1.0, float("inf")


class Hoap2Sim:
    """The HOAP-2 in MuJoCo. The physics is hoap2.xml's (its one home); ``config`` overrides some of it
    for a sweep (PHYSICS_KEYS: timestep s, integrator name, armature kg*m^2 and joint_damping N*m*s/rad
    of every hinge, friction of every geom, contact_solref (time constant s, damping ratio) of every geom).
    ``has_fallen``: torso origin below ``min_torso_height`` (m) or its z-axis more than ``max_tilt_deg``
    from vertical."""

    def __init__(self, config: Mapping | None = None, model_path: str | Path = MODEL_PATH,
                 min_torso_height: float = MIN_TORSO_HEIGHT_M, max_tilt_deg: float = MAX_TILT_DEG):
        unknown = sorted(set(config or {}) - set(PHYSICS_KEYS))
        if unknown:
            raise ValueError(f"Hoap2Sim config: unknown key(s) {unknown}; known: {', '.join(PHYSICS_KEYS)}")
        self.config = dict(config or {})
        self.model = mujoco.MjModel.from_xml_path(str(model_path))
        self._apply_config(self.config)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.joint_names: tuple[str, ...] = JOINT_NAMES
        jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in JOINT_NAMES]
        if min(jid) < 0:
            missing = [n for n, i in zip(JOINT_NAMES, jid, strict=True) if i < 0]
            raise ValueError(f"{model_path}: model lacks joint(s) {missing}")
        self._qadr = np.array([m.jnt_qposadr[i] for i in jid])
        self._dadr = np.array([m.jnt_dofadr[i] for i in jid])
        self._act = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in JOINT_NAMES])
        if self._act.min() < 0:
            raise ValueError(f"{model_path}: every joint needs a motor named after it")
        self.joint_range = np.array([m.jnt_range[i] for i in jid])
        self.max_torque = np.array([m.actuator_ctrlrange[a, 1] for a in self._act])
        self._torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "torso")
        self._sole_geoms = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, s) for s in SOLES]
        self._floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self._sensor = {
            n: (m.sensor_adr[i], m.sensor_dim[i])
            for n in ("imu_gyro", "imu_accel", "imu_quat", "lleg_sole_load", "rleg_sole_load")
            for i in [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, n)]
        }
        self.total_mass = float(m.body_subtreemass[self._torso])
        self.min_torso_height = float(min_torso_height)
        self.max_tilt_deg = float(max_tilt_deg)
        self._push_until = -1.0
        self.reset()

    # ----------------------------------------------------------------------------------------- setup
    def _apply_config(self, cfg: Mapping) -> None:
        m = self.model
        m.opt.timestep = float(cfg.get("timestep", m.opt.timestep))
        if "integrator" in cfg:
            m.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{str(cfg['integrator']).upper()}")
        hinge = m.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
        dofs = m.jnt_dofadr[hinge]
        if "armature" in cfg:
            m.dof_armature[dofs] = float(cfg["armature"])
        if "joint_damping" in cfg:
            m.dof_damping[dofs] = float(cfg["joint_damping"])
        if "friction" in cfg:
            m.geom_friction[:, 0] = float(cfg["friction"])
        if "contact_solref" in cfg:
            m.geom_solref[:] = np.asarray(cfg["contact_solref"], dtype=float)

    def physics(self) -> dict:
        """The physics in use (PHYSICS_KEYS; armature, damping: of the first hinge; friction, solref: of
        the floor), read back from the compiled model."""
        m = self.model
        hinge = int(m.jnt_dofadr[np.flatnonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)[0]])
        integrator = mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower()
        return {"timestep": float(m.opt.timestep), "integrator": integrator,
                "armature": float(m.dof_armature[hinge]), "joint_damping": float(m.dof_damping[hinge]),
                "friction": float(m.geom_friction[self._floor, 0]),
                "contact_solref": [float(x) for x in m.geom_solref[self._floor]]}

    @property
    def dt(self) -> float:
        """Physics timestep (s)."""
        return float(self.model.opt.timestep)

    @property
    def time(self) -> float:
        return float(self.data.time)

    def _vector(self, x, label: str) -> np.ndarray:
        if isinstance(x, Mapping):
            arr = np.zeros(len(JOINT_NAMES)) if label == "torque" else self.joint_positions()
            for name, value in x.items():
                if name not in JOINT_NAMES:
                    raise ValueError(f"{label}: unknown joint {name!r}")
                arr[JOINT_NAMES.index(name)] = float(value)
            return arr
        arr = np.asarray(x, dtype=float)
        if arr.shape != (len(JOINT_NAMES),):
            n = len(JOINT_NAMES)
            raise ValueError(f"{label}: expected {n} values (JOINT_NAMES order), got shape {arr.shape}")
        return arr

    def reset(self, posture: Sequence[float] | Mapping[str, float] | None = None) -> None:
        """Zero velocities, joints at ``posture`` (default: the walk's first row), torso turned so the left
        sole is level, lowered until the lower sole just touches the floor at x = y = 0. No settling."""
        m, d = self.model, self.data
        q = default_standing_posture() if posture is None else self._vector(posture, "posture")
        mujoco.mj_resetData(m, d)
        d.qpos[self._qadr] = q
        d.qpos[3:7] = (1, 0, 0, 0)
        mujoco.mj_kinematics(m, d)
        rel = d.geom_xmat[self._sole_geoms[0]].reshape(3, 3)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, rel.T.flatten())
        d.qpos[3:7] = quat
        mujoco.mj_kinematics(m, d)
        lowest = min(self._sole_bottom(g) for g in self._sole_geoms)
        d.qpos[2] -= lowest
        d.qpos[0:2] = 0.0
        self._push_until = -1.0
        mujoco.mj_forward(m, d)

    def _sole_bottom(self, geom: int) -> float:
        d = self.data
        half = self.model.geom_size[geom]
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        world = d.geom_xpos[geom] + corners @ d.geom_xmat[geom].reshape(3, 3).T
        return float(world[:, 2].min())

    # ------------------------------------------------------------------------------------- stepping
    def step(self, torque: Sequence[float] | Mapping[str, float] | None = None, n: int = 1) -> None:
        """Hold ``torque`` (N*m, JOINT_NAMES order or a dict by name; clamped to the motor limits; None =
        keep the last) for ``n`` physics steps."""
        if torque is not None:
            tau = self._vector(torque, "torque")
            if not np.all(np.isfinite(tau)):
                raise ValueError("torque: non-finite value")
            self.data.ctrl[self._act] = np.clip(tau, -self.max_torque, self.max_torque)
        for _ in range(n):
            if self._push_until >= 0 and self.data.time >= self._push_until:
                self.data.xfrc_applied[self._torso, :] = 0.0
                self._push_until = -1.0
            mujoco.mj_step(self.model, self.data)

    def set_torque_unchecked(self, torque: np.ndarray, within_limits: bool = False) -> None:
        """Hold ``torque`` from now on, as ``step(torque, 0)`` would (clamped to the motor limits), without
        its checks: for a loop that hands over a finite float array of len(JOINT_NAMES) it has validated
        itself (walker/loop.py: the PID stepper returns finite torques or raises). ``within_limits``: the
        caller guarantees |torque| <= ``max_torque`` (the clamp would change nothing and is skipped)."""
        if not within_limits:
            mt = self.max_torque
            torque = np.maximum(torque, -mt)
            np.minimum(torque, mt, out=torque)  # = np.clip(torque, -max, max) for finite values
        self.data.ctrl[self._act] = torque

    def apply_push(self, force: Sequence[float], duration: float = 0.1) -> None:
        """Push the torso at its CoM with a world-frame force (N) for ``duration`` s of sim time."""
        f = np.asarray(force, dtype=float)
        if f.shape != (3,) or not np.all(np.isfinite(f)) or not (duration > 0):
            raise ValueError("apply_push: need a finite 3-vector force and a positive duration")
        self.data.xfrc_applied[self._torso, :3] = f
        self._push_until = self.data.time + float(duration)

    # ------------------------------------------------------------------------------------ accessors
    def joint_positions(self, names: Sequence[str] | None = None) -> np.ndarray:
        """Joint angles (rad), JOINT_NAMES order or the given names."""
        return self.data.qpos[self._select(self._qadr, names)].copy()

    def joint_velocities(self, names: Sequence[str] | None = None) -> np.ndarray:
        """Joint velocities (rad/s)."""
        return self.data.qvel[self._select(self._dadr, names)].copy()

    def _select(self, addresses: np.ndarray, names: Sequence[str] | None) -> np.ndarray:
        if names is None:
            return addresses
        try:
            return addresses[[JOINT_NAMES.index(n) for n in names]]
        except ValueError:
            unknown = [n for n in names if n not in JOINT_NAMES]
            raise ValueError(f"unknown joint(s) {unknown}") from None

    def _read(self, name: str) -> np.ndarray:
        adr, dim = self._sensor[name]
        return self.data.sensordata[adr : adr + dim].copy()

    def imu(self) -> Imu:
        """Chest IMU: gyro (rad/s) and accelerometer (m/s^2, reads +9.81 on z standing still) in the torso
        frame, orientation quaternion (w, x, y, z) in the world."""
        return Imu(self._read("imu_gyro"), self._read("imu_accel"), self._read("imu_quat"))

    def torso_upright(self) -> float:
        """Cosine of the angle between the torso's z-axis and the vertical (1 = upright)."""
        return float(self.data.xmat[self._torso][8])

    def sole_loads(self) -> tuple[float, float]:
        """Normal force (N) the floor exerts on the (left, right) sole plate."""
        sd = self.data.sensordata
        return float(sd[self._sensor["lleg_sole_load"][0]]), float(sd[self._sensor["rleg_sole_load"][0]])

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Torso origin position (m) and orientation quaternion (w, x, y, z), world frame."""
        return self.data.qpos[0:3].copy(), self.data.qpos[3:7].copy()

    def base_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Torso origin linear velocity (m/s) and angular velocity (rad/s), world frame."""
        vel = np.zeros(6)
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, self._torso, vel, 0)
        return vel[3:].copy(), vel[:3].copy()

    def heading(self) -> float:
        """Yaw of the torso's x-axis in the world (rad)."""
        R = self.data.xmat[self._torso].reshape(3, 3)
        return math.atan2(R[1, 0], R[0, 0])

    def has_fallen(self) -> bool:
        """Fallen = torso origin lower than ``min_torso_height`` (standing crouch: 0.285 m) or the torso
        tilted more than ``max_tilt_deg`` from vertical (constructor arguments)."""
        z = float(self.data.qpos[2])
        return z < self.min_torso_height or self.torso_upright() < math.cos(math.radians(self.max_tilt_deg))
