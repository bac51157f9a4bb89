"""The URDF generated from the MJCF: parsed here on its own (xml.etree, numpy forward kinematics from the
joints' origins and axes, nothing of urdf.py's), its link poses equal MuJoCo's body and site poses over
random joint angles and base poses; it is one tree rooted at base_link with the MuJoCo joint names, every
message frame id is a link, and the shipped file is what the generator writes today."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from cpg_walker.robot import frames
from cpg_walker.robot.hoap2 import MODEL_PATH
from cpg_walker.robot.joints import JOINT_NAMES, MAX_TORQUE_NM, MAX_VELOCITY_RADS
from cpg_walker.robot.urdf import URDF_PATH, generate, urdf_from_model

#: The issue's bound: every link within 1 mm and 1 mrad of MuJoCo's pose.
POS_TOL_M, ROT_TOL_RAD = 1e-3, 1e-3
SAMPLES = 200


def _floats(text: str | None, n: int = 3) -> np.ndarray:
    v = np.array([float(x) for x in (text or " ".join(["0"] * n)).split()])
    assert v.shape == (n,), text
    return v


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: rotation by ``angle`` about the unit ``axis``."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _rpy(rpy: np.ndarray) -> np.ndarray:
    """URDF rpy: fixed-axis roll (x), then pitch (y), then yaw (z)."""
    r, p, y = rpy
    return _rot(np.array([0.0, 0, 1]), y) @ _rot(np.array([0.0, 1, 0]), p) @ _rot(np.array([1.0, 0, 0]), r)


class Urdf:
    """The parts of a URDF the tests need, read with xml.etree."""

    def __init__(self, text: str):
        self.root = ET.fromstring(text)
        self.links = [e.get("name") for e in self.root.findall("link")]
        self.joints = {}
        for j in self.root.findall("joint"):
            o = j.find("origin")
            axis = j.find("axis")
            self.joints[j.get("name")] = {
                "type": j.get("type"),
                "parent": j.find("parent").get("link"), "child": j.find("child").get("link"),
                "xyz": _floats(None if o is None else o.get("xyz")),
                "rpy": _floats(None if o is None else o.get("rpy")),
                "axis": _floats("1 0 0" if axis is None else axis.get("xyz")),
                "limit": None if j.find("limit") is None
                else {k: float(v) for k, v in j.find("limit").attrib.items()},
            }
        self.parent_joint = {j["child"]: name for name, j in self.joints.items()}

    def roots(self) -> list[str]:
        return [link for link in self.links if link not in self.parent_joint]

    def forward(self, base_pos: np.ndarray, base_R: np.ndarray, q: dict[str, float]) -> dict:
        """World (position, rotation) of every link, base_link at the given pose, joints at ``q``."""
        poses = {"base_link": (base_pos, base_R)}

        def pose(link: str):
            if link not in poses:
                j = self.joints[self.parent_joint[link]]
                p_pos, p_R = pose(j["parent"])
                R = p_R @ _rpy(j["rpy"])
                pos = p_pos + p_R @ j["xyz"]
                if j["type"] in ("revolute", "continuous"):
                    R = R @ _rot(j["axis"], q[self.parent_joint[link]])
                poses[link] = (pos, R)
            return poses[link]

        for link in self.links:
            pose(link)
        return poses


@pytest.fixture(scope="module")
def urdf() -> Urdf:
    return Urdf(URDF_PATH.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(MODEL_PATH))


def test_shipped_urdf_is_a_fresh_generation() -> None:
    assert URDF_PATH.read_text(encoding="utf-8") == generate(), \
        "cpg_walker/robot/hoap2.urdf is stale: `cpg-walker urdf --out cpg_walker/robot/hoap2.urdf`"


def test_cli_writes_the_same_urdf(tmp_path) -> None:
    from cpg_walker.cli.main import main

    out = tmp_path / "robot.urdf"
    assert main(["urdf", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == URDF_PATH.read_text(encoding="utf-8")


def test_one_tree_rooted_at_base_link_with_the_mujoco_joint_names(urdf: Urdf, model) -> None:
    assert len(set(urdf.links)) == len(urdf.links)
    assert urdf.roots() == [frames.BASE_LINK]
    children = [j["child"] for j in urdf.joints.values()]
    assert len(children) == len(set(children)) == len(urdf.links) - 1  # one parent each: a tree
    assert all(j["parent"] in urdf.links and j["child"] in urdf.links for j in urdf.joints.values())
    moving = {n for n, j in urdf.joints.items() if j["type"] != "fixed"}
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    hinges = {model.joint(i).name for i in range(model.njnt) if model.jnt_type[i] == hinge}
    assert moving == hinges == set(JOINT_NAMES)  # /joint_states names drive robot_state_publisher
    bodies = {frames.link_name(model.body(b).name) for b in range(1, model.nbody)}
    assert set(urdf.links) == bodies | set(frames.SITE_FRAMES)


def test_every_message_frame_id_is_a_urdf_link(urdf: Urdf) -> None:
    from nav_msgs.msg import Odometry
    from rclpy.serialization import deserialize_message

    from cpg_walker.nodes.messages import FOOT_LOAD_FRAMES, IMU_FRAME, OdometryBuilder

    odom = deserialize_message(OdometryBuilder().fill(0, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3),
                                                      np.zeros(3)), Odometry)
    assert odom.header.frame_id == frames.ODOM_FRAME
    ids = {IMU_FRAME, *(f for _, f in FOOT_LOAD_FRAMES), odom.child_frame_id}
    assert ids == {"imu", "l_sole", "r_sole", "base_link"}
    assert ids <= set(urdf.links)
    assert frames.ODOM_FRAME not in urdf.links  # odom -> base_link is /tf's, not the robot's


def test_limits_and_inertials_are_the_models(urdf: Urdf, model) -> None:
    for name, j in urdf.joints.items():
        if j["type"] == "fixed":
            continue
        lo, hi = model.joint(name).range
        assert j["type"] == "revolute"
        assert j["limit"]["lower"] == pytest.approx(lo) and j["limit"]["upper"] == pytest.approx(hi)
        assert j["limit"]["effort"] == MAX_TORQUE_NM and j["limit"]["velocity"] == MAX_VELOCITY_RADS
        assert np.allclose(j["axis"], model.jnt_axis[model.joint(name).id])
    masses = {e.get("name"): float(e.find("inertial/mass").get("value"))
              for e in urdf.root.findall("link") if e.find("inertial") is not None}
    total = float(model.body_subtreemass[model.body("torso").id])
    assert sum(masses.values()) == pytest.approx(total, rel=1e-9)
    # each link's inertia tensor and CoM: the MJCF's own numbers (parsed from the XML, not the compiled model)
    links = {e.get("name"): e for e in urdf.root.findall("link")}
    bodies = [b for b in ET.parse(MODEL_PATH).getroot().iter("body") if b.find("inertial") is not None]
    for b in bodies:
        inertial = b.find("inertial")
        xx, yy, zz, xy, xz, yz = (float(v) for v in inertial.get("fullinertia").split())
        want = {"ixx": xx, "iyy": yy, "izz": zz, "ixy": xy, "ixz": xz, "iyz": yz}
        link = links[frames.link_name(b.get("name"))]
        got = {k: float(v) for k, v in link.find("inertial/inertia").attrib.items()}
        assert all(got[k] == pytest.approx(want[k], rel=1e-6, abs=1e-12) for k in want), (b.get("name"), got)
        assert np.allclose(_floats(link.find("inertial/origin").get("xyz")), _floats(inertial.get("pos")))
        assert float(link.find("inertial/mass").get("value")) == float(inertial.get("mass"))
    assert len(bodies) == model.nbody - 3  # all but the world and the two sole plates (inertia from the box)


def test_forward_kinematics_matches_mujoco_over_random_poses(urdf: Urdf, model) -> None:
    """Base at identity first, then random base poses; joints uniform within their limits (seeded)."""
    data = mujoco.MjData(model)
    rng = np.random.default_rng(12)
    names = [n for n, j in urdf.joints.items() if j["type"] != "fixed"]
    worst_pos = worst_rot = 0.0
    for k in range(SAMPLES):
        q = {n: rng.uniform(urdf.joints[n]["limit"]["lower"], urdf.joints[n]["limit"]["upper"])
             for n in names}
        base_pos = np.zeros(3) if k == 0 else rng.uniform(-1, 1, 3)
        base_quat = np.array([1.0, 0, 0, 0]) if k == 0 else rng.normal(size=4)
        base_quat /= np.linalg.norm(base_quat)
        data.qpos[:3], data.qpos[3:7] = base_pos, base_quat
        for n, v in q.items():
            data.qpos[model.jnt_qposadr[model.joint(n).id]] = v
        mujoco.mj_kinematics(model, data)
        poses = urdf.forward(base_pos, _quat(base_quat), q)
        expected = {frames.link_name(model.body(b).name): (data.xpos[b], data.xmat[b].reshape(3, 3))
                    for b in range(1, model.nbody)}
        for frame, (_, site) in frames.SITE_FRAMES.items():
            s = model.site(site).id
            expected[frame] = (data.site_xpos[s], data.site_xmat[s].reshape(3, 3))
        assert set(expected) == set(poses)
        for link, (pos, R) in expected.items():
            got_pos, got_R = poses[link]
            dp = float(np.linalg.norm(got_pos - pos))
            # the angle of got_R^T R: |got_R - R|_F = 2 sqrt(2) sin(angle / 2) (precise near 0, unlike acos)
            dr = 2 * math.asin(min(1.0, float(np.linalg.norm(got_R - R)) / (2 * math.sqrt(2))))
            worst_pos, worst_rot = max(worst_pos, dp), max(worst_rot, dr)
            assert dp < POS_TOL_M and dr < ROT_TOL_RAD, (k, link, dp, dr)
    print(f"URDF vs MuJoCo over {SAMPLES} poses: max position error {worst_pos:.3g} m, "
          f"max rotation error {worst_rot:.3g} rad")


SHAPES = """<mujoco><compiler angle="radian"/><worldbody><body name="base"><freejoint/>
  <geom name="cap" type="capsule" size="0.02 0.05" pos="0.1 0 0" euler="0.3 0.2 0.1"/>
  <geom name="cyl" type="cylinder" size="0.03 0.04" rgba="1 0 0 0"/>
  <body name="arm" pos="0 0 0.1" euler="0 0.5 0"><joint name="j" axis="0 1 0" range="-1 1"/>
    <geom name="{last}" type="{kind}" size="0.01 0.02 0.03"/></body>
</body></worldbody><actuator><motor joint="j" gear="2" ctrlrange="-3 3"/></actuator></mujoco>"""


def test_geom_shapes_capsules_and_refused_types() -> None:
    model = mujoco.MjModel.from_xml_string(SHAPES.format(last="b", kind="box"))
    u = Urdf(urdf_from_model(model, name="t", site_frames={}))
    base = u.root.find("link[@name='base']")
    # the capsule: a cylinder (full length 0.1) and a sphere at each end; the invisible cylinder only collides
    assert [g.tag for g in base.findall("visual/geometry/*")] == ["cylinder", "sphere", "sphere"]
    collisions = [g.tag for g in base.findall("collision/geometry/*")]
    assert collisions == ["cylinder", "sphere", "sphere", "cylinder"]
    assert base.find("visual/geometry/cylinder").get("length") == "0.1"
    ends = [_floats(v.find("origin").get("xyz")) for v in base.findall("visual")[1:]]
    assert np.linalg.norm(ends[0] - ends[1]) == pytest.approx(0.1)
    R = _rpy(_floats(base.find("visual/origin").get("rpy")))
    assert np.allclose(R @ [0, 0, 1], (ends[0] - ends[1]) / 0.1)
    assert u.joints["j"]["limit"]["effort"] == 6.0  # gear x ctrlrange
    assert u.joints["j"]["rpy"] == pytest.approx([0, 0.5, 0])
    with pytest.raises(ValueError, match="geom 'bad' of body 'arm' has type mjGEOM_ELLIPSOID"):
        bad = mujoco.MjModel.from_xml_string(SHAPES.format(last="bad", kind="ellipsoid"))
        urdf_from_model(bad, site_frames={})


def test_tf_entry_is_the_free_joint_pose_after_a_step(model) -> None:
    """odom -> base_link (sim_node's /tf, the recorder's) is the pose in qpos, which /joint_states' angles go
    with, also right after mj_step; and equals MuJoCo's xpos/xquat once the kinematics are computed."""
    from cpg_walker.nodes.messages import transform_stamped

    data = mujoco.MjData(model)
    data.qvel[:6] = [0.3, -0.2, 0.1, 0.5, -0.4, 0.2]
    mujoco.mj_step(model, data)
    t = frames.odom_transform(model, data)
    assert (t.parent, t.child) == ("odom", "base_link")
    assert np.array_equal(t.translation, data.qpos[:3]) and np.array_equal(t.quat_wxyz, data.qpos[3:7])
    mujoco.mj_kinematics(model, data)
    b = model.body("torso").id
    assert np.allclose(t.translation, data.xpos[b]) and np.allclose(t.quat_wxyz, data.xquat[b])
    msg = transform_stamped(1_234_000_000, t)
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 234_000_000)
    tr, q = msg.transform.translation, msg.transform.rotation
    assert [tr.x, tr.y, tr.z, q.w, q.x, q.y, q.z] == [*t.translation, *t.quat_wxyz]
