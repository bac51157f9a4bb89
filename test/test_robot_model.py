"""The MJCF HOAP-2 loads with the expected joints, limits and mass, and stands on its soles."""

import math

import mujoco
import numpy as np
import pytest

from cpg_walker.robot import joints
from cpg_walker.robot.hoap2 import MODEL_PATH, Hoap2Sim
from cpg_walker.robot.pid import PidLaw

PROTO_TOTAL_MASS = 7.1598898  # kg, sum of the reference model's masses
G = 9.81


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(MODEL_PATH))


def test_joint_table():
    assert len(joints.JOINT_NAMES) == 25 == len(set(joints.JOINT_NAMES))
    assert len(joints.CONTROLLED_JOINTS) == 10
    assert joints.paper_name("lleg_joint_2") == "left Hip1"
    assert joints.paper_name("rleg_joint_3") == "right Hip2"
    assert joints.paper_name("rleg_joint_6") == "right Ankle2"
    assert joints.joint_function("lleg_joint_1") == "hip_yaw"
    with pytest.raises(KeyError):
        joints.joint_function("tail_joint_1")


def test_model_joints_axes_limits(model):
    names = {model.joint(i).name for i in range(model.njnt)}
    assert names == set(joints.JOINT_NAMES) | {"root"}
    assert model.nu == 25 and model.nq == 7 + 25
    expected = {  # axis and range of the reference model (radians)
        "body_joint_1": ((0, -1, 0), (-0.017453, 1.5708)),
        "lleg_joint_2": ((1, 0, 0), (-0.36652, 0.541052)),
        "rleg_joint_2": ((1, 0, 0), (-0.541052, 0.36652)),
        "lleg_joint_3": ((0, 1, 0), (-1.43117, 1.23918)),
        "rleg_joint_4": ((0, 1, 0), (-0.017453, 2.26893)),
        "lleg_joint_6": ((1, 0, 0), (-0.43633, 0.43633)),
        "rleg_joint_1": ((0, 0, 1), (-1.58825, 0.541052)),
        "larm_joint_1": ((0, 1, 0), (-1.5882, 2.6354)),
        "head_joint_2": ((0, 1, 0), (-0.2618, 1.0472)),
    }
    for name, (axis, rng) in expected.items():
        j = model.joint(name)
        np.testing.assert_allclose(j.axis, axis, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(j.range, rng, atol=1e-9, err_msg=name)
        assert j.limited[0] if np.ndim(j.limited) else j.limited
    # hip nesting yaw -> pitch (joint_3) -> roll (joint_2), as in the reference and the recordings
    thigh = model.body("lleg_thigh")
    assert model.body(thigh.parentid[0]).name == "lleg_hip_pitch_link"
    for a in range(model.nu):
        np.testing.assert_allclose(model.actuator_ctrlrange[a], (-9, 9))


def test_total_mass_and_geometry(model):
    assert math.isclose(float(model.body_subtreemass[model.body("torso").id]), PROTO_TOTAL_MASS, rel_tol=1e-6)
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)  # zero posture, torso origin at z = 0.3: soles 4.5 mm above the floor
    for s in ("lleg_sole", "rleg_sole"):
        assert d.geom(s).xpos[2] - model.geom(s).size[2] == pytest.approx(0.0045, abs=1e-6)
    assert model.opt.timestep <= 0.001


def test_standing_imu_reads_gravity_and_soles_carry_the_weight():
    sim = Hoap2Sim()
    pid = PidLaw.from_config()
    q0 = sim.joint_positions()
    for _ in range(750):  # 1.5 s holding the standing posture at 500 Hz
        tau = pid.step(q0, np.zeros(25), sim.joint_positions(), sim.joint_velocities(), 0.002)
        sim.step(tau, 2)
    assert not sim.has_fallen()
    imu = sim.imu()
    assert np.linalg.norm(imu.accel) == pytest.approx(G, rel=0.01)
    assert imu.accel[2] > 0.99 * G  # torso nearly upright: gravity reaction along the torso z-axis
    assert np.abs(imu.gyro).max() < 0.01
    left, right = sim.sole_loads()
    weight = sim.total_mass * G
    assert left + right == pytest.approx(weight, rel=0.05)
    assert min(left, right) > 0.3 * weight  # both feet carry load
    assert np.abs(sim.joint_positions() - q0).max() < 0.03


def test_push_topples_and_reset_is_complete():
    sim = Hoap2Sim()
    pid = PidLaw.from_config()
    start = sim.data.qpos.copy()
    q0 = sim.joint_positions()
    sim.apply_push([40.0, 0.0, 0.0], duration=0.3)  # 12 N*s forward on the servoed, standing robot
    for _ in range(1000):
        sim.step(pid.step(q0, np.zeros(25), sim.joint_positions(), sim.joint_velocities(), 0.002), 2)
    assert sim.has_fallen()
    sim.reset()
    np.testing.assert_array_equal(sim.data.qpos, start)
    assert not sim.data.qvel.any() and not sim.data.xfrc_applied.any()
    assert not sim.has_fallen()
    with pytest.raises(ValueError):
        sim.step(np.full(25, np.nan))
    with pytest.raises(ValueError):
        sim.step({"nose_joint": 1.0})
