"""Launch the CPG walk on a ROS 2 install: sim_node + pid_node + cpg_node. Example:
``ros2 launch cpg_walker walk.launch.py pacing:=lockstep zeta:=0.9 alpha:=1.1``.

Each node gets its parameters file from the package's share/config (config/<node name>.yaml: every
value's one home, e.g. zeta and alpha in cpg.yaml); a launch argument given on the command line overrides
the file's value (left empty, the file's stands). Without ROS's launch tools (a pip install), use
``cpg-walker graph`` / ``cpg-walker walk``.
"""

import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

from launch import LaunchDescription


def params(node_name: str) -> str:
    """The node's parameters file: share/cpg_walker/config/<node_name>.yaml."""
    return os.path.join(get_package_share_directory("cpg_walker"), "config", f"{node_name}.yaml")


def file_value(node_name: str, key: str):
    """One value of a node's parameters file (to configure another node consistently)."""
    with open(params(node_name), encoding="utf-8") as fh:
        return yaml.safe_load(fh)[node_name]["ros__parameters"][key]


def nodes(context) -> list:
    """The three nodes, each with its file, then the given launch arguments as overrides."""
    arg = {name: context.launch_configurations.get(name, "") for name in ("pacing", "zeta", "alpha")}
    pacing = arg["pacing"] or file_value("sim", "pacing")
    cpg = {"use_sim_time": True, "lockstep": pacing == "lockstep",
           **{k: float(arg[k]) for k in ("zeta", "alpha") if arg[k]}}
    return [
        Node(package="cpg_walker", executable="sim_node", name="sim", output="screen",
             parameters=[params("sim"), {"use_sim_time": True, "pacing": pacing}]),
        Node(package="cpg_walker", executable="pid_node", name="pid", output="screen",
             parameters=[params("pid"), {"use_sim_time": True, "lockstep": pacing == "lockstep",
                                         "wait_for_targets": True}]),
        Node(package="cpg_walker", executable="cpg_node", name="cpg", output="screen",
             parameters=[params("cpg"), cpg]),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("pacing", default_value="",
                              description="realtime | fast | lockstep (empty: config/sim.yaml's)"),
        DeclareLaunchArgument("zeta", default_value="",
                              description="cpg_node's frequency ratio in [-2, 2] (empty: config/cpg.yaml's)"),
        DeclareLaunchArgument("alpha", default_value="",
                              description="cpg_node's amplitude scale in [0, 2] (empty: config/cpg.yaml's)"),
        OpaqueFunction(function=nodes),
    ])
