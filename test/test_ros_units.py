"""In-process tests of the ROS layer's pure helpers (no DDS): command validation, stamps, messages,
the graph harness's argument formatting, the sim node's sole wrenches, the launch file's syntax."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from cpg_walker.graph.processes import isolated_env, param_arg
from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.validation import (
    check_finite_scalar,
    from_ns,
    period_ns,
    to_ns,
    validate_joint_command,
)
from cpg_walker.robot.joints import JOINT_NAMES

REPO = Path(__file__).resolve().parent.parent


def test_valid_subset_command_maps_names_to_indices():
    cmd = validate_joint_command(["head_joint_1", "lleg_joint_4"], [0.1, 0.2], [0.0, 1.0])
    assert [JOINT_NAMES[i] for i in cmd.index] == ["head_joint_1", "lleg_joint_4"]
    assert cmd.position.tolist() == [0.1, 0.2] and cmd.velocity.tolist() == [0.0, 1.0]
    assert cmd.effort is None


@pytest.mark.parametrize("names, pos, vel, reason", [
    ([], [], [], "no joint names"),
    (["head_joint_1", "head_joint_1"], [0.0, 0.0], [], "duplicate"),
    (["head_joint_1", "tail_joint"], [0.0, 0.0], [], "unknown joint"),
    (["head_joint_1", "head_joint_2"], [0.0], [], "position has 1 values for 2"),
    (["head_joint_1"], [0.0], [0.0, 1.0], "velocity has 2 values"),
    (["head_joint_1", "head_joint_2"], [0.0, math.nan], [], "non-finite position"),
    (["head_joint_1"], [0.0], [math.inf], "non-finite velocity"),
    (["head_joint_1"], [], [0.0], "no position"),
])
def test_bad_commands_are_rejected_with_a_reason(names, pos, vel, reason):
    with pytest.raises(ValueError, match=reason):
        validate_joint_command(names, pos, vel)


def test_rejections_are_throttled_per_reason():
    from cpg_walker.nodes.runtime import Throttle
    from cpg_walker.nodes.validation import reason_key

    class Log:
        def __init__(self):
            self.lines = []

        def get_logger(self):
            return self

        def warn(self, text):
            self.lines.append(text)

    node, throttle = Log(), Throttle(period=60.0)
    for _ in range(3):
        for bad in (["head_joint_1", "x"], ["head_joint_1", "head_joint_1"]):
            try:
                validate_joint_command(bad, [0.0, 0.0])
            except ValueError as exc:
                throttle.warn(node, reason_key(exc), str(exc))
    assert len(node.lines) == 2 and "unknown" in node.lines[0] and "duplicate" in node.lines[1]
    assert throttle.suppressed == {"unknown joint": 2, "duplicate joint": 2}


def test_torque_commands_require_effort():
    with pytest.raises(ValueError, match="no effort"):
        validate_joint_command(["head_joint_1"], [0.0], require="effort")
    assert validate_joint_command(["head_joint_1"], effort=[1.5], require="effort").effort.tolist() == [1.5]


def test_stamps_are_exact_integers():
    p = period_ns(0.002)
    assert p == 2_000_000
    for k in (0, 1, 499, 500, 123457):
        assert to_ns(*from_ns(k * p)) == k * p
    with pytest.raises(ValueError):
        period_ns(0.0)


@pytest.mark.parametrize("value", [math.nan, -1.0, "1", True, math.inf])
def test_scalar_check_rejects(value):
    with pytest.raises(ValueError):
        check_finite_scalar("kp.leg", value, 0.0)


def test_param_args_keep_types():
    assert param_arg("duration", 5.0) == "duration:=5.0"
    assert param_arg("lockstep", True) == "lockstep:=true"
    assert param_arg("push.force", [0.0, 20.0, 0.0]) == "push.force:=[0.0,20.0,0.0]"
    assert param_arg("record_path", "") == "record_path:=''"
    env = isolated_env(7, {"ROS_LOCALHOST_ONLY": "1"})
    assert env["ROS_DOMAIN_ID"] == "7" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert "ROS_LOCALHOST_ONLY" not in env


def test_joint_state_round_trip_and_validation_of_messages():
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from cpg_walker.nodes.messages import JointStateBuilder, read_joint_command, stamp_ns

    q = np.linspace(-1, 1, len(JOINT_NAMES))
    raw = JointStateBuilder(JOINT_NAMES, fields=("position", "velocity")).fill(1_234_000_000, position=q,
                                                                              velocity=2 * q)
    msg = deserialize_message(raw, JointState)  # the builders return the message serialized
    assert stamp_ns(msg) == 1_234_000_000
    cmd = read_joint_command(msg)
    np.testing.assert_array_equal(cmd.position, q)
    np.testing.assert_array_equal(cmd.velocity, 2 * q)
    bad = JointState(name=["head_joint_1"], position=[float("nan")])
    with pytest.raises(ValueError, match="non-finite"):
        read_joint_command(bad)


def test_standing_sole_wrenches_carry_the_weight():
    from cpg_walker.robot.contact import sole_wrenches
    from cpg_walker.robot.hoap2 import Hoap2Sim, default_standing_posture
    from cpg_walker.robot.pid import PidLaw

    sim = Hoap2Sim()
    pid = PidLaw.from_config()
    target = default_standing_posture()
    for _ in range(500):  # 1 s standing under the PID
        tau = pid.step(target, np.zeros(len(JOINT_NAMES)), sim.joint_positions(), sim.joint_velocities(),
                       0.002)
        sim.step(tau, 2)
    (fl, _), (fr, _) = sole_wrenches(sim)
    weight = sim.total_mass * 9.81
    assert fl[2] + fr[2] == pytest.approx(weight, rel=0.05)  # normal forces along the sole z axes
    assert fl[2] > 0.2 * weight and fr[2] > 0.2 * weight
    loads = sim.sole_loads()  # the touch sensors agree with the contact wrenches
    assert loads[0] == pytest.approx(fl[2], rel=0.05) and loads[1] == pytest.approx(fr[2], rel=0.05)


def test_launch_file_compiles_and_names_the_nodes():
    path = REPO / "launch" / "sim_pid.launch.py"
    src = path.read_text()
    compile(src, str(path), "exec")
    tree = ast.parse(src)
    names = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)}
    assert {"cpg_walker", "use_sim_time"} <= names
    executables = {n.value.id for n in ast.walk(tree) if isinstance(n, ast.keyword) and n.arg == "executable"
                   and isinstance(n.value, ast.Name)}  # the executables, named by nodes/interface.py
    assert {getattr(ifc, name) for name in executables} == {ifc.SIM_NODE, ifc.PID_NODE, ifc.PLAYER_NODE}
    assert "generate_launch_description" in src


@pytest.mark.parametrize("exe", ["sim_node", "pid_node", "target_player_node"])
def test_node_help_lists_the_interface(exe, capsys):
    import importlib

    module = importlib.import_module(f"cpg_walker.nodes.{exe}")
    with pytest.raises(SystemExit) as exit_info:
        module.main([exe, "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "/joint_" in out or ifc.CLOCK in out
