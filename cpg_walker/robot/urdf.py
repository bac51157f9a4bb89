"""The HOAP-2's URDF, generated from the MuJoCo model (hoap2.xml is the one source of truth).

Regenerate the shipped file with ``cpg-walker urdf --out cpg_walker/robot/hoap2.urdf``; test/test_urdf.py
fails when it differs from a fresh generation, and checks its forward kinematics against MuJoCo's.

Mapping (from the *compiled* model, so MJCF defaults and classes are already applied):

* links: one per body but the world, named by ``frames.link_name`` (``torso`` -> ``base_link``, soles ->
  ``l_sole``/``r_sole``); one empty link per site frame (``frames.SITE_FRAMES``: ``imu``).
* joints: a MuJoCo hinge -> ``revolute`` (``continuous`` if unlimited) with the body's pose in its parent
  as origin, the hinge axis, limits = its ``range``, effort = its motor's torque limit (|gear x ctrlrange|,
  and forcerange if limited), velocity = ``joints.MAX_VELOCITY_RADS`` (the reference motors' maximum,
  enforced by the PID law, not by MuJoCo), dynamics = its damping and frictionloss (URDF has no armature).
  A body without a joint -> a ``fixed`` joint ``<link>_joint``; so is each site frame. The free root joint
  is not in the URDF: it is ``odom -> base_link`` on /tf (``frames.odom_transform``).
* inertials: mass, centre of mass and the full inertia tensor in the link frame (MuJoCo's principal
  inertia rotated back by the body's ``iquat``; origin rpy 0).
* geometry: every geom of a body as ``visual`` (unless fully transparent) and ``collision`` (if it has
  ``contype`` or ``conaffinity``): box, sphere, cylinder; a capsule (none today) as a cylinder plus a sphere
  at each end (URDF has no capsule). Other geom types are refused.
"""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.robot.frames import SITE_FRAMES, link_name
from cpg_walker.robot.hoap2 import MODEL_PATH
from cpg_walker.robot.joints import MAX_VELOCITY_RADS

#: The shipped URDF (installed beside the MJCF and under share/cpg_walker/urdf/).
URDF_PATH = Path(__file__).resolve().parent / "hoap2.urdf"
ROBOT_NAME = "hoap2"
#: How to regenerate it (in the file's header comment; XML comments cannot hold "--").
REGENERATE = "the cpg-walker urdf command (out: cpg_walker/robot/hoap2.urdf)"

_OBJ = mujoco.mjtObj
_GEOM = mujoco.mjtGeom


def _num(x: float) -> str:
    """A number as URDF text: 10 significant digits, no negative zero."""
    s = f"{float(x):.10g}"
    return "0" if s in ("-0", "0") else s


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def _mat(quat_wxyz) -> np.ndarray:
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(quat_wxyz, dtype=float))
    return m.reshape(3, 3)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw (fixed axes x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation matrix."""
    sp = -float(R[2, 0])
    if abs(sp) > 1.0 - 1e-12:  # gimbal lock: yaw folded into roll
        return math.atan2(-R[1, 2], R[1, 1]), math.copysign(math.pi / 2, sp), 0.0
    return math.atan2(R[2, 1], R[2, 2]), math.asin(sp), math.atan2(R[1, 0], R[0, 0])


def _origin(parent: ET.Element, pos, quat_wxyz) -> None:
    ET.SubElement(parent, "origin", xyz=_vec(pos), rpy=_vec(rpy_from_matrix(_mat(quat_wxyz))))


def _name(model: mujoco.MjModel, obj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"{obj.name.removeprefix('mjOBJ_').lower()}{i}"


def _shapes(model: mujoco.MjModel, g: int) -> list[tuple[ET.Element, np.ndarray, np.ndarray]]:
    """The URDF geometries of geom ``g``: (geometry element, position, quaternion) in the body frame."""
    kind, size = int(model.geom_type[g]), model.geom_size[g]
    pos, quat = model.geom_pos[g], model.geom_quat[g]
    geometry = ET.Element("geometry")
    if kind == _GEOM.mjGEOM_BOX:
        ET.SubElement(geometry, "box", size=_vec(2 * size))
    elif kind == _GEOM.mjGEOM_SPHERE:
        ET.SubElement(geometry, "sphere", radius=_num(size[0]))
    elif kind in (_GEOM.mjGEOM_CYLINDER, _GEOM.mjGEOM_CAPSULE):
        ET.SubElement(geometry, "cylinder", radius=_num(size[0]), length=_num(2 * size[1]))
    else:
        raise InputError(f"urdf: geom {_name(model, _OBJ.mjOBJ_GEOM, g)!r} of body "
                         f"{_name(model, _OBJ.mjOBJ_BODY, int(model.geom_bodyid[g]))!r} has type "
                         f"{_GEOM(kind).name}; only box, sphere, cylinder and capsule have a URDF shape")
    out = [(geometry, pos, quat)]
    if kind == _GEOM.mjGEOM_CAPSULE:  # the two hemispherical ends, as spheres at the cylinder's ends
        axis = _mat(quat)[:, 2] * size[1]
        for sign in (1.0, -1.0):
            cap = ET.Element("geometry")
            ET.SubElement(cap, "sphere", radius=_num(size[0]))
            out.append((cap, pos + sign * axis, quat))
    return out


def _joint_limit(model: mujoco.MjModel, j: int) -> dict[str, str]:
    """effort (N*m) from the joint's motor(s), velocity (rad/s), and the range if the joint is limited."""
    acts = [a for a in range(model.nu)
            if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and model.actuator_trnid[a, 0] == j]
    if not acts:
        raise InputError(f"urdf: joint {_name(model, _OBJ.mjOBJ_JOINT, j)!r} has no motor: no effort limit")
    effort = 0.0
    for a in acts:
        torque = abs(model.actuator_gear[a, 0]) * np.abs(model.actuator_ctrlrange[a]).max()
        if model.actuator_forcelimited[a]:
            torque = min(torque, np.abs(model.actuator_forcerange[a]).max())
        effort += torque
    limit = {"effort": _num(effort), "velocity": _num(MAX_VELOCITY_RADS)}
    if model.jnt_limited[j]:
        limit = {"lower": _num(model.jnt_range[j, 0]), "upper": _num(model.jnt_range[j, 1]), **limit}
    return limit


def _link(model: mujoco.MjModel, b: int, materials: dict[tuple, str]) -> ET.Element:
    link = ET.Element("link", name=link_name(_name(model, _OBJ.mjOBJ_BODY, b)))
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=_vec(model.body_ipos[b]), rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=_num(model.body_mass[b]))
    R = _mat(model.body_iquat[b])
    inertia = R @ np.diag(model.body_inertia[b]) @ R.T
    upper = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    ET.SubElement(inertial, "inertia", **{f"i{'xyz'[r]}{'xyz'[c]}": _num(inertia[r, c]) for r, c in upper})
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != b:
            continue
        rgba = tuple(float(x) for x in model.geom_rgba[g])
        collides = bool(model.geom_contype[g] or model.geom_conaffinity[g])
        for geometry, pos, quat in _shapes(model, g):
            if rgba[3] > 0:
                visual = ET.SubElement(link, "visual")
                _origin(visual, pos, quat)
                visual.append(geometry)
                ET.SubElement(visual, "material", name=materials.setdefault(rgba, f"color{len(materials)}"))
            if collides:
                collision = ET.SubElement(link, "collision")
                _origin(collision, pos, quat)
                collision.append(copy.deepcopy(geometry))
    return link


def _joint(model: mujoco.MjModel, b: int) -> ET.Element:
    parent = link_name(_name(model, _OBJ.mjOBJ_BODY, int(model.body_parentid[b])))
    child = link_name(_name(model, _OBJ.mjOBJ_BODY, b))
    n = int(model.body_jntnum[b])
    if n > 1:
        raise InputError(f"urdf: body {child!r} has {n} joints; a URDF link has one joint to its parent")
    if n == 0:
        joint = ET.Element("joint", name=f"{child}_joint", type="fixed")
    else:
        j = int(model.body_jntadr[b])
        name = _name(model, _OBJ.mjOBJ_JOINT, j)
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise InputError(f"urdf: joint {name!r} is a {mujoco.mjtJoint(model.jnt_type[j]).name}; only "
                             "hinges (and the free root joint) are supported")
        if np.any(model.jnt_pos[j] != 0):
            raise InputError(f"urdf: joint {name!r} is not at its body's origin (pos {model.jnt_pos[j]}); "
                             "a URDF joint sits at its child link's frame")
        joint = ET.Element("joint", name=name, type="revolute" if model.jnt_limited[j] else "continuous")
    _origin(joint, model.body_pos[b], model.body_quat[b])
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    if n:
        dof = int(model.jnt_dofadr[j])
        ET.SubElement(joint, "axis", xyz=_vec(model.jnt_axis[j]))
        ET.SubElement(joint, "limit", **_joint_limit(model, j))
        ET.SubElement(joint, "dynamics", damping=_num(model.dof_damping[dof]),
                      friction=_num(model.dof_frictionloss[dof]))
    return joint


def urdf_from_model(model: mujoco.MjModel, name: str = ROBOT_NAME, source: str = "hoap2.xml",
                    site_frames: dict[str, tuple[str, str]] = SITE_FRAMES) -> str:
    """The URDF text of a compiled MuJoCo model with one free-floating root body (see the module doc);
    ``site_frames``: frame -> (body, site) of the fixed frames at sites."""
    roots = [b for b in range(1, model.nbody) if model.body_parentid[b] == 0]
    if len(roots) != 1:
        names = [_name(model, _OBJ.mjOBJ_BODY, b) for b in roots]
        raise InputError(f"urdf: the model needs exactly one body under the world (the floating base), "
                         f"has {names}")
    root = roots[0]
    robot = ET.Element("robot", name=name)
    robot.append(ET.Comment(f" Generated from {source} by cpg_walker/robot/urdf.py; do not edit. "
                            f"Regenerate with {REGENERATE}. "))
    materials: dict[tuple, str] = {}
    links, joints = [], []
    for b in range(1, model.nbody):
        links.append(_link(model, b, materials))
        if b != root:
            joints.append(_joint(model, b))
    for frame, (body, site) in site_frames.items():
        s = mujoco.mj_name2id(model, _OBJ.mjOBJ_SITE, site)
        if s < 0 or _name(model, _OBJ.mjOBJ_BODY, int(model.site_bodyid[s])) != body:
            raise InputError(f"urdf: frame {frame!r} needs site {site!r} on body {body!r}")
        links.append(ET.Element("link", name=frame))
        joint = ET.Element("joint", name=f"{frame}_joint", type="fixed")
        _origin(joint, model.site_pos[s], model.site_quat[s])
        ET.SubElement(joint, "parent", link=link_name(body))
        ET.SubElement(joint, "child", link=frame)
        joints.append(joint)
    for rgba, mat in materials.items():
        material = ET.SubElement(robot, "material", name=mat)
        ET.SubElement(material, "color", rgba=" ".join(f"{x:.6g}" for x in rgba))  # float32 in MuJoCo
    robot.extend(links)
    robot.extend(joints)
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def generate(model_path: str | Path = MODEL_PATH) -> str:
    """The URDF of the MJCF at ``model_path`` (default: the package's hoap2.xml). A file MuJoCo cannot load,
    or a model a URDF cannot describe: InputError naming the file (and MuJoCo's line)."""
    try:
        model = mujoco.MjModel.from_xml_path(str(model_path))
    except ValueError as exc:  # MuJoCo's XML parse / compile error
        raise InputError(f"{model_path}: not a loadable MJCF model: {' '.join(str(exc).split())}") from None
    try:
        return urdf_from_model(model, source=Path(model_path).name)
    except InputError as exc:
        raise InputError(f"{model_path}: {exc}") from None


def read_urdf() -> str:
    """The shipped URDF's text (what sim_node publishes on /robot_description)."""
    return URDF_PATH.read_text(encoding="utf-8")
