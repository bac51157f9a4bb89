"""One home per value: each node's parameters come from its file config/<node>.yaml (``--params-file``),
which the graph harness and the launch files pass and the in-process loop reads too. Live nodes are read
back through their parameter services (real processes over DDS, each test on its own random domain;
fixtures ``graph``, ``probe``: conftest.py). Also: the defects fixed with the parameter files (sim_node in
real time without waiting for the controller; cpg_node's lifecycle ``stage``)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cpg_walker.graph.processes import NODES, stats_path
from cpg_walker.graph.ros2cli import from_parameter_value
from cpg_walker.nodes.interface import NODE_NAMES
from cpg_walker.nodes.params import params_file
from cpg_walker.paths import ros_parameters
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.urdf import read_urdf

pytestmark = [pytest.mark.ros, pytest.mark.slow]

REPO = Path(__file__).resolve().parent.parent
#: Nodes whose live parameters are compared with their file (cpg_node also loads its CPG file).
LIVE = ("sim_node", "pid_node", "target_player_node", "cpg_node")

#: wall s before a parameter request is sent again (its response can be lost at the service's start)
RETRY_S = 10.0


def _read_back(probe, node: str, names: list[str], timeout: float = 120.0) -> dict:
    """``names`` of ``/node`` through its get_parameters service, as Python values. The deadline is long:
    a node's parameter services exist from its start, but it answers only once it has finished starting
    (cpg_node loads and warms up its CPG first) on a machine that may be busy."""
    import time

    from rcl_interfaces.srv import GetParameters

    client = probe.node.create_client(GetParameters, f"/{node}/get_parameters")
    assert client.wait_for_service(timeout_sec=timeout), f"/{node}/get_parameters not available"
    # asked again every RETRY_S: a response sent before the server has matched this client's response
    # reader is lost ("failed to send response (timeout)" in the node's log, rmw_fastrtps; seen once in a
    # fresh-clone run, the relay's)
    end = time.monotonic() + timeout
    while True:
        future = client.call_async(GetParameters.Request(names=names))
        left = end - time.monotonic()
        if probe.spin_for(min(RETRY_S, max(left, 0.0)), until=future.done) or left <= RETRY_S:
            break
    assert future.done(), f"/{node} did not answer within {timeout} s"
    values = future.result().values
    return {n: from_parameter_value(v) for n, v in zip(names, values, strict=True)}


def test_live_nodes_use_every_value_of_their_file(graph, probe):
    """Every ``ros__parameters`` entry of each node's file, as the running node reports it, equals the
    file's value as the in-process code reads it (paths.ros_parameters: nested keys flattened like ROS)."""
    for exe in LIVE:
        # the sim waits for a controller (none here) and serves its parameters meanwhile
        graph.start(exe)
    for exe in LIVE:
        name = NODE_NAMES[exe]
        expected = ros_parameters(f"{name}.yaml", name)
        assert expected, name
        got = _read_back(probe, name, list(expected))
        for key, value in expected.items():
            if key == "stats_file":  # the graph gives every node a stats file in its log directory
                assert got[key] == str(stats_path(graph.log_dir, exe).resolve()), (name, got[key])
                continue
            same = got[key] == value if isinstance(value, str | bool) else got[key] == pytest.approx(value)
            assert same, (name, key, got[key], value)
        assert graph.procs[exe].popen.poll() is None, graph.procs[exe].log()[-2000:]


def test_node_cli_and_inprocess_loop_share_one_value(graph, probe):
    """PID kp.leg, the control period and zeta: the live node's value (parameter service), what the CLI
    and the graph harness pass (the file, not a code default) and what the in-process loop uses."""
    from cpg_walker.experiments.cpg_walk import walk
    from cpg_walker.graph.runner import GraphSpec
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw, load_pid_config
    from cpg_walker.walker.learning import cpg_defaults, load_controller
    from cpg_walker.walker.loop import control_period, run_replay

    graph.start("pid_node")
    graph.start("sim_node")
    graph.start("cpg_node")
    node_kp = _read_back(probe, "pid", ["kp.leg"])["kp.leg"]
    node_period = _read_back(probe, "sim", ["control_period"])["control_period"]
    node_zeta = _read_back(probe, "cpg", ["zeta"])["zeta"]

    # the CLI (`cpg-walker graph`) passes none of them: each node reads its file, given first
    spec = GraphSpec(pacing="lockstep", duration=1.0).node_params()
    for exe, name in (("pid_node", "kp.leg"), ("sim_node", "control_period"), ("cpg_node", "zeta")):
        assert name.replace(".", "__") not in spec[exe] and name not in spec[exe]
        cmd = graph.command(exe, spec[exe])
        assert cmd[cmd.index("--params-file") + 1] == str(params_file(NODE_NAMES[exe]))
        assert cmd.index("--params-file") < cmd.index("-p")  # -p overrides come after the file

    # in-process: the PID law's leg gain, the loop's tick period, the walk's default zeta
    pid = PidLaw.from_config()
    assert pid.kp[JOINT_NAMES.index("lleg_joint_3")] == load_pid_config()["kp.leg"] == node_kp

    class Recorder:
        names = pid.names

        def __init__(self):
            self.t: list[float] = []
            self.q = Hoap2Sim().joint_positions()

        def targets(self, t):
            self.t.append(t)
            return self.q, np.zeros(len(self.q))

    rec = Recorder()
    run_replay(Hoap2Sim(), rec, PidLaw.from_config(), 0.02)
    ticks = np.diff(rec.t)
    assert ticks == pytest.approx(np.full(ticks.shape, node_period))
    assert control_period() == node_period

    ctrl, _, _ = load_controller(cpg_defaults()["cpg_file"])
    m = walk(ctrl, 0.05)
    assert m["zeta"] == cpg_defaults()["zeta"] == node_zeta


def test_a_p_override_wins_over_the_file(graph, probe):
    graph.start("pid_node", kp__leg=120.0)
    values = _read_back(probe, "pid", ["kp.leg", "kp.arm"])
    assert values == {"kp.leg": 120.0, "kp.arm": ros_parameters("pid.yaml", "pid")["kp.arm"]}


def test_per_joint_gain_from_the_start_up_parameters(graph, probe):
    graph.start("pid_node", kp__lleg_joint_4=123.0)
    assert _read_back(probe, "pid", ["kp.lleg_joint_4"]) == {"kp.lleg_joint_4": 123.0}
    assert probe.set_param("pid", "kp.lleg_joint_4", -1.0).successful is False


#: foxglove_node binds a TCP port (8765 in its file): two suites side by side would collide; its start
#: from the packaged file, on a free port, is in test_foxglove.py.
BARE = tuple(n for n in NODES if n != "foxglove_node")


@pytest.mark.parametrize("exe", BARE)
def test_a_bare_node_reads_its_packaged_file(exe, graph, probe):
    """``ros2 run cpg_walker <node>`` with no --params-file: the node takes every value from its packaged
    parameters file (the one home of the values; there is no code default) and says so in its log."""
    name = NODE_NAMES[exe]
    log = graph.log_dir / f"{exe}.bare.log"
    with open(log, "wb") as out:
        # cwd: the recorder's bag (out_dir '' = ./recording_<date>) goes to the test's directory
        proc = subprocess.Popen([sys.executable, "-m", f"cpg_walker.nodes.{exe}"], env=graph.env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
                                cwd=graph.log_dir)
    try:
        expected = ros_parameters(f"{name}.yaml", name)
        got = _read_back(probe, name, list(expected))
        for key, value in expected.items():  # a bare node: every value its file's, stats_file ('') too
            same = got[key] == value if isinstance(value, str | bool) else got[key] == pytest.approx(value)
            assert same, (name, key, got[key], value)
        assert proc.poll() is None
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    text = log.read_text()
    assert str(params_file(name)) in text and "Traceback" not in text


def test_a_misspelt_gain_in_a_params_file_is_one_clear_line(tmp_path):
    """A params file naming a gain group that does not exist: exit status 2, one line naming it."""
    from cpg_walker.graph.processes import isolated_env, random_domain_id

    bad = tmp_path / "pid.yaml"
    bad.write_text("pid:\n  ros__parameters:\n    kp: {legg: 100.0}\n")
    done = subprocess.run([sys.executable, "-m", "cpg_walker.nodes.pid_node", "--ros-args", "--params-file",
                           str(bad)], capture_output=True, text=True, env=isolated_env(random_domain_id()),
                          timeout=120)
    assert done.returncode == 2, done.stderr
    assert "kp.legg" in done.stderr and "Traceback" not in done.stderr


def test_misspelt_gain_is_a_clear_error(graph):
    graph.start("pid_node", kp__legg=100.0)
    assert graph.wait("pid_node", 60) == 2
    log = graph.procs["pid_node"].log()
    assert "kp.legg" in log and "Traceback" not in log


def test_realtime_without_waiting_for_the_controller_runs(graph, tmp_path):
    """Defect: sim_node with pacing realtime and wait_for_controller false raised on its first period
    (the schedule's origin was set only after it)."""
    record = tmp_path / "record.json"
    graph.start("sim_node", pacing="realtime", wait_for_controller=False, duration=0.2,
                record_path=str(record))
    assert graph.wait("sim_node", 60) == 0, graph.procs["sim_node"].log()[-2000:]
    assert record.exists() and "Traceback" not in graph.procs["sim_node"].log()


def test_cpg_node_reports_its_stage_not_a_phase():
    """cpg_node's lifecycle (learning, converged, starting, walking) is ``stage``; ``phase`` means an
    oscillator phase θ in this codebase (and /cpg/state carries those). Built in-process from its file."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from cpg_walker.graph.processes import random_domain_id
    from cpg_walker.nodes.cpg_node import CPGNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=random_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = CPGNode(context=ctx, cli_args=["--ros-args", "--params-file", str(params_file("cpg"))])
        assert node.driver.stage == "converged" and not hasattr(node.driver, "phase")
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def _launch_nodes(monkeypatch, tmp_path, name: str, args: dict[str, str]) -> dict[str, dict]:
    """Run a launch file's node list with stand-ins for launch/launch_ros (not installed here): each
    Node's (or ExecuteProcess's) name -> its keyword arguments. The share directory is the source tree,
    with the URDF where setup.py installs it from."""
    import types

    class Stub:
        def __init__(self, *a, **kw):
            self.args, self.kw = a, kw

    modules = {"launch": types.ModuleType("launch"), "launch.actions": types.ModuleType("launch.actions"),
               "launch_ros": types.ModuleType("launch_ros"),
               "launch_ros.actions": types.ModuleType("launch_ros.actions"),
               "ament_index_python": types.ModuleType("ament_index_python"),
               "ament_index_python.packages": types.ModuleType("ament_index_python.packages")}
    modules["launch"].LaunchDescription = lambda entities: entities
    modules["launch.actions"].DeclareLaunchArgument = Stub
    modules["launch.actions"].OpaqueFunction = Stub
    modules["launch.actions"].ExecuteProcess = Stub
    modules["launch_ros.actions"].Node = Stub
    modules["ament_index_python.packages"].get_package_share_directory = lambda pkg: str(share)
    for mod_name, mod in modules.items():
        monkeypatch.setitem(sys.modules, mod_name, mod)
    share = tmp_path / "share"
    (share / "urdf").mkdir(parents=True, exist_ok=True)
    for sub in ("config", "rviz"):
        if not (share / sub).exists():
            (share / sub).symlink_to(REPO / sub)
    (share / "urdf" / "hoap2.urdf").write_text(read_urdf(), encoding="utf-8")
    path = REPO / "launch" / name
    namespace: dict = {"__name__": "launch_file"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    entities = namespace["generate_launch_description"]()
    declared = {e.args[0]: e.kw.get("default_value") for e in entities if "default_value" in e.kw}
    context = types.SimpleNamespace(launch_configurations={**declared, **args})
    (opaque,) = [e for e in entities if "function" in e.kw]
    return {n.kw["name"]: n.kw for n in opaque.kw["function"](context)}


def test_launch_files_pass_each_node_its_file_then_the_arguments(monkeypatch, tmp_path):
    """Both launch files give every node config/<node name>.yaml first; a launch argument overrides one
    value, and without it the file's value stands (no second default in the launch file). The walk also
    starts robot_state_publisher with the shipped URDF (sim_node then leaves /robot_description to it),
    and the recorder / RViz when asked."""
    walk = _launch_nodes(monkeypatch, tmp_path, "walk.launch.py", {})
    assert set(walk) == {"sim", "pid", "cpg", "odom", "robot_state_publisher"}
    rsp = walk.pop("robot_state_publisher")
    assert rsp["package"] == rsp["executable"] == "robot_state_publisher"
    assert rsp["parameters"] == [{"robot_description": read_urdf(), "use_sim_time": True}]
    for name, kw in walk.items():
        assert kw["parameters"][0] == str(tmp_path / "share" / "config" / f"{name}.yaml")
        assert kw["executable"] == {v: k for k, v in NODE_NAMES.items()}[name]
    assert walk["sim"]["parameters"][1]["publish_description"] is False
    assert walk["sim"]["parameters"][1]["publish_tf"] is False  # odom_node's estimate is odom -> base_link
    assert not {"zeta", "alpha", "feedback"} & set(walk["cpg"]["parameters"][1])
    file_pacing = ros_parameters("sim.yaml", "sim")["pacing"]
    assert walk["pid"]["parameters"][1]["lockstep"] == (file_pacing == "lockstep")
    walk = _launch_nodes(monkeypatch, tmp_path, "walk.launch.py", {
        "zeta": "0.8", "alpha": "1.2", "pacing": "lockstep", "feedback": "false", "record": "true",
        "record_dir": "bags/walk", "rviz": "true"})
    cpg = walk["cpg"]["parameters"][1]
    assert cpg["zeta"] == 0.8 and cpg["alpha"] == 1.2 and cpg["feedback"] is False
    assert walk["sim"]["parameters"][1]["pacing"] == "lockstep" and walk["pid"]["parameters"][1]["lockstep"]
    assert walk["record"]["cmd"] == ["ros2", "bag", "record", "-s", "mcap", "-a", "--use-sim-time",
                                     "-o", "bags/walk"]
    assert walk["rviz2"]["arguments"] == ["-d", str(tmp_path / "share" / "rviz" / "hoap2.rviz")]
    assert (tmp_path / "share" / "rviz" / "hoap2.rviz").is_file()
    with pytest.raises(ValueError, match="feedback:='yes'"):
        _launch_nodes(monkeypatch, tmp_path, "walk.launch.py", {"feedback": "yes"})

    graph = _launch_nodes(monkeypatch, tmp_path, "sim_pid.launch.py", {"player": "true", "gait": "slow"})
    assert set(graph) == {"sim", "pid", "target_player"}
    for name, kw in graph.items():
        assert kw["parameters"][0] == str(tmp_path / "share" / "config" / f"{name}.yaml")
    assert graph["target_player"]["parameters"][1]["gait"] == "slow"
    assert "control_period" not in graph["sim"]["parameters"][1]
    assert set(_launch_nodes(monkeypatch, tmp_path, "sim_pid.launch.py", {})) == {"sim", "pid"}


def test_physics_lives_in_the_model_only():
    """config/sim.yaml is the sim node's parameters only: no MuJoCo setting, no fall threshold."""
    from cpg_walker.robot.hoap2 import PHYSICS_KEYS, Hoap2Sim

    sim_params = ros_parameters("sim.yaml", "sim")
    assert not set(sim_params) & {*PHYSICS_KEYS, "fall.min_torso_height", "fall.max_tilt_deg"}
    assert Hoap2Sim({"friction": 0.5}).physics()["friction"] == 0.5  # a sweep's override
    with pytest.raises(ValueError, match="frction"):
        Hoap2Sim({"frction": 0.5})
    assert math.isclose(Hoap2Sim(min_torso_height=0.25).min_torso_height, 0.25)
