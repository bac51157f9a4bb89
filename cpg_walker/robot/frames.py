"""The HOAP-2's ROS frames over the MuJoCo model's bodies: the one home of frame names.

REP-105: the world frame of the simulation is ``odom`` (ground truth, never jumps). REP-120: the root link is
``base_link`` (the MuJoCo ``torso`` body), the soles are ``l_sole``/``r_sole``. Every other link keeps its
MuJoCo body name; ``imu`` is a fixed frame at the model's ``imu`` site. The URDF, ``/tf`` and the messages'
``frame_id`` all come from here.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

ODOM_FRAME = "odom"
BASE_LINK = "base_link"
LEFT_SOLE = "l_sole"
RIGHT_SOLE = "r_sole"
IMU_FRAME = "imu"

_LINK_OF_BODY = {"torso": BASE_LINK, "lleg_sole": LEFT_SOLE, "rleg_sole": RIGHT_SOLE}
# frames fixed to a body at one of its sites: frame -> (body, site)
SITE_FRAMES = {IMU_FRAME: ("torso", "imu")}
FOOT_LOAD_FRAMES = (("left", LEFT_SOLE), ("right", RIGHT_SOLE))


def link_name(body: str) -> str:
    """The ROS link (frame) name of a MuJoCo body."""
    return _LINK_OF_BODY.get(body, body)


@dataclass(frozen=True)
class Transform:
    """``child``'s pose in ``parent``: translation (m) and rotation quaternion (w, x, y, z)."""

    parent: str
    child: str
    translation: np.ndarray
    quat_wxyz: np.ndarray


def _relative(p_pos: np.ndarray, p_mat: np.ndarray, c_pos: np.ndarray, c_mat: np.ndarray) -> tuple:
    rot = p_mat.T @ c_mat
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, rot.reshape(9))
    return p_mat.T @ (c_pos - p_pos), q


def fixed_links(model: mujoco.MjModel) -> frozenset[str]:
    """Links welded to their parent link (a body without a joint, other than the floating base): their
    transform in the parent never changes (``/tf_static``; the others are ``/tf``)."""
    return frozenset(link_name(model.body(b).name) for b in range(1, model.nbody)
                     if int(model.body_parentid[b]) != 0 and int(model.body_jntnum[b]) == 0)


def body_transforms(model: mujoco.MjModel, data: mujoco.MjData) -> list[Transform]:
    """Every link's pose in its parent link, from the posed ``data`` (after ``mj_kinematics``)."""
    out = []
    for b in range(1, model.nbody):
        parent = int(model.body_parentid[b])
        if parent == 0:
            continue  # the floating base: see odom_transform
        t, q = _relative(data.xpos[parent], data.xmat[parent].reshape(3, 3),
                         data.xpos[b], data.xmat[b].reshape(3, 3))
        out.append(Transform(link_name(model.body(parent).name), link_name(model.body(b).name), t, q))
    return out


def site_transforms(model: mujoco.MjModel, data: mujoco.MjData) -> list[Transform]:
    """The fixed frames at sites (``imu``), in their body's link."""
    out = []
    for frame, (body, site) in SITE_FRAMES.items():
        b, s = model.body(body).id, model.site(site).id
        t, q = _relative(data.xpos[b], data.xmat[b].reshape(3, 3),
                         data.site_xpos[s], data.site_xmat[s].reshape(3, 3))
        out.append(Transform(link_name(body), frame, t, q))
    return out


def odom_transform(model: mujoco.MjModel, data: mujoco.MjData) -> Transform:
    """``odom -> base_link``: the root body's world pose, read from its free joint's ``qpos`` - the pose
    the joint angles in ``qpos`` (/joint_states) go with, also right after ``mj_step`` (whose ``xpos`` is
    still the pre-step pose); equal to ``xpos``/``xquat`` after ``mj_kinematics``."""
    b = next(i for i in range(1, model.nbody) if int(model.body_parentid[i]) == 0)
    j = int(model.body_jntadr[b])
    if model.body_jntnum[b] != 1 or model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"odom_transform: root body {model.body(b).name!r} needs one free joint")
    a = int(model.jnt_qposadr[j])
    return Transform(ODOM_FRAME, link_name(model.body(b).name), data.qpos[a:a + 3].copy(),
                     data.qpos[a + 3:a + 7].copy())


def set_pose(model: mujoco.MjModel, data: mujoco.MjData, position: Sequence[float],
             quat_wxyz: Sequence[float], joints: Iterable[tuple[str, float]]) -> None:
    """Pose ``data.qpos`` as the sim was: the floating base (``odom -> base_link``, e.g. from
    /odom/ground_truth) at ``position``/``quat_wxyz``, each named hinge joint (e.g. /joint_states' names and
    positions) at its angle; names the model does not have are skipped. Run ``mj_kinematics`` (transforms)
    or ``mj_forward`` (also cameras) after."""
    b = next(i for i in range(1, model.nbody) if int(model.body_parentid[i]) == 0)
    a = int(model.jnt_qposadr[int(model.body_jntadr[b])])
    data.qpos[a:a + 3] = position
    data.qpos[a + 3:a + 7] = quat_wxyz
    for name, q in joints:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j >= 0 and model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            data.qpos[int(model.jnt_qposadr[j])] = q
