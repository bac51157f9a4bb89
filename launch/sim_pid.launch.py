"""Launch the HOAP-2 graph on a ROS 2 install: sim_node + pid_node (+ target_player_node with
``player:=true``). Example: ``ros2 launch cpg_walker sim_pid.launch.py pacing:=lockstep player:=true``.

Each node gets its parameters file from the package's share/config (config/<node name>.yaml: every
value's one home); a launch argument given on the command line overrides the file's value (left empty,
the file's stands). The CPG walk: walk.launch.py. Without ROS's launch tools (a pip install), use
``cpg-walker graph`` (cpg_walker.graph.processes.Graph).
"""

import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

from cpg_walker.nodes.interface import NODE_NAMES, PID_NODE, PLAYER_NODE, SIM_NODE, controllers_lockstep
from launch import LaunchDescription


def params(node_name: str) -> str:
    """The node's parameters file: share/cpg_walker/config/<node_name>.yaml."""
    return os.path.join(get_package_share_directory("cpg_walker"), "config", f"{node_name}.yaml")


def file_value(node_name: str, key: str):
    """One value of a node's parameters file (to configure another node consistently)."""
    with open(params(node_name), encoding="utf-8") as fh:
        return yaml.safe_load(fh)[node_name]["ros__parameters"][key]


def nodes(context) -> list:
    """sim + pid (+ the player), each with its file, then the given launch arguments as overrides."""
    names = ("pacing", "control_period", "player", "gait")
    arg = {k: context.launch_configurations.get(k, "") for k in names}
    pacing = arg["pacing"] or file_value(NODE_NAMES[SIM_NODE], "pacing")
    player = arg["player"].lower() == "true"
    sim = {"use_sim_time": True, "pacing": pacing,
           **({"control_period": float(arg["control_period"])} if arg["control_period"] else {})}
    out = [
        Node(package="cpg_walker", executable=SIM_NODE, name=NODE_NAMES[SIM_NODE], output="screen",
             parameters=[params(NODE_NAMES[SIM_NODE]), sim]),
        Node(package="cpg_walker", executable=PID_NODE, name=NODE_NAMES[PID_NODE], output="screen",
             parameters=[params(NODE_NAMES[PID_NODE]), {"use_sim_time": True,
                                                        "lockstep": controllers_lockstep(pacing),
                                                        "wait_for_targets": player}]),
    ]
    if player:
        out.append(Node(package="cpg_walker", executable=PLAYER_NODE, name=NODE_NAMES[PLAYER_NODE],
                        output="screen", parameters=[params(NODE_NAMES[PLAYER_NODE]), {
                            "use_sim_time": True, **({"gait": arg["gait"]} if arg["gait"] else {})}]))
    return out


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("pacing", default_value="",
                              description="realtime | fast | lockstep (empty: config/sim.yaml's)"),
        DeclareLaunchArgument("control_period", default_value="",
                              description="s (empty: config/sim.yaml's)"),
        DeclareLaunchArgument("player", default_value="false",
                              description="also stream the recorded walk as /joint_targets"),
        DeclareLaunchArgument("gait", default_value="",
                              description="walk | slow (empty: config/target_player.yaml's)"),
        OpaqueFunction(function=nodes),
    ])
