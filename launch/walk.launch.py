"""Launch the CPG walk on a ROS 2 install: sim_node + pid_node + cpg_node + odom_node + robot_state_publisher
(+ ``ros2 bag record`` with ``record:=true``, + RViz with ``rviz:=true``). Example:
``ros2 launch cpg_walker walk.launch.py pacing:=lockstep zeta:=1.2 alpha:=1.1 feedback:=false record:=true``.

Each of our nodes gets its parameters file from the package's share/config (config/<node name>.yaml:
every value's one home, e.g. zeta, alpha and feedback in cpg.yaml); a launch argument given on the
command line overrides the file's value (left empty, the file's stands). robot_state_publisher gets the
URDF generated from the MJCF (share/cpg_walker/urdf/hoap2.urdf), publishes it on /robot_description and
turns /joint_states into /tf and /tf_static (so sim_node does not publish /robot_description itself here);
odom_node estimates odom -> base_link (leg odometry, /odom) and puts it on /tf, so sim_node's ground truth
stays on /odom/ground_truth only (its publish_tf false: REP-105, one parent per frame). Without ROS's
launch tools (a pip install), use ``cpg-walker graph`` / ``cpg-walker walk``.
"""

import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch_ros.actions import Node

from cpg_walker.nodes.interface import (
    CPG_NODE,
    NODE_NAMES,
    ODOM_NODE,
    PID_NODE,
    SIM_NODE,
    controllers_lockstep,
)
from launch import LaunchDescription

PACKAGE = "cpg_walker"
#: The launch arguments (name -> description); all default to "" = the parameters file's value, but
#: record and rviz ("false").
ARGUMENTS = {
    "pacing": "realtime | fast | lockstep (empty: config/sim.yaml's)",
    "zeta": "cpg_node's frequency ratio in [-2, 2] (empty: config/cpg.yaml's)",
    "alpha": "cpg_node's amplitude scale in [0, 2] (empty: config/cpg.yaml's)",
    "feedback": "true | false: cpg_node's sensory feedback pathways (empty: config/cpg.yaml's)",
    "record": "true: also record every topic with `ros2 bag record -s mcap -a` (sim time)",
    "record_dir": "the recording's directory (empty: rosbag2's timestamped one in the current directory)",
    "rviz": "true: also start RViz with share/cpg_walker/rviz/hoap2.rviz",
}
OFF_BY_DEFAULT = ("record", "rviz")


def share(*parts: str) -> str:
    """A file of the installed package: share/cpg_walker/<parts>."""
    return os.path.join(get_package_share_directory(PACKAGE), *parts)


def params(node_name: str) -> str:
    """The node's parameters file: share/cpg_walker/config/<node_name>.yaml."""
    return share("config", f"{node_name}.yaml")


def file_value(node_name: str, key: str):
    """One value of a node's parameters file (to configure another node consistently)."""
    with open(params(node_name), encoding="utf-8") as fh:
        return yaml.safe_load(fh)[node_name]["ros__parameters"][key]


def flag(name: str, text: str) -> bool | None:
    """A true/false launch argument (None when left empty); anything else is an error naming it."""
    if text == "":
        return None
    if text.lower() not in ("true", "false"):
        raise ValueError(f"launch argument {name}:={text!r}: expected true or false")
    return text.lower() == "true"


def nodes(context) -> list:
    """The nodes (each of ours with its file, then the given launch arguments as overrides) and the
    recorder."""
    arg = {name: context.launch_configurations.get(name, "") for name in ARGUMENTS}
    pacing = arg["pacing"] or file_value(NODE_NAMES[SIM_NODE], "pacing")
    feedback = flag("feedback", arg["feedback"])
    cpg = {"use_sim_time": True, "lockstep": controllers_lockstep(pacing),
           **{k: float(arg[k]) for k in ("zeta", "alpha") if arg[k]},
           **({} if feedback is None else {"feedback": feedback})}
    record = flag("record", arg["record"])
    # recorded: the sim holds its first state until `ros2 bag record` (node rosbag2_recorder) subscribes
    waits = {"wait_for_subscriber": "rosbag2_recorder"} if record else {}
    with open(share("urdf", "hoap2.urdf"), encoding="utf-8") as fh:
        description = fh.read()
    out = [
        Node(package=PACKAGE, executable=SIM_NODE, name=NODE_NAMES[SIM_NODE], output="screen",
             parameters=[params(NODE_NAMES[SIM_NODE]), {"use_sim_time": True, "pacing": pacing,
                                                        "publish_description": False, "publish_tf": False,
                                                        **waits}]),
        Node(package=PACKAGE, executable=PID_NODE, name=NODE_NAMES[PID_NODE], output="screen",
             parameters=[params(NODE_NAMES[PID_NODE]), {"use_sim_time": True,
                                                        "lockstep": controllers_lockstep(pacing),
                                                        "wait_for_targets": True}]),
        Node(package=PACKAGE, executable=CPG_NODE, name=NODE_NAMES[CPG_NODE], output="screen",
             parameters=[params(NODE_NAMES[CPG_NODE]), cpg]),
        Node(package=PACKAGE, executable=ODOM_NODE, name=NODE_NAMES[ODOM_NODE], output="screen",
             parameters=[params(NODE_NAMES[ODOM_NODE]), {"use_sim_time": True}]),
        Node(package="robot_state_publisher", executable="robot_state_publisher",
             name="robot_state_publisher", output="screen",
             parameters=[{"robot_description": description, "use_sim_time": True}]),
    ]
    if record:
        out.append(ExecuteProcess(
            cmd=["ros2", "bag", "record", "-s", "mcap", "-a", "--use-sim-time",
                 *(["-o", arg["record_dir"]] if arg["record_dir"] else [])],
            name="record", output="screen"))
    if flag("rviz", arg["rviz"]):
        out.append(Node(package="rviz2", executable="rviz2", name="rviz2", output="screen",
                        arguments=["-d", share("rviz", "hoap2.rviz")],
                        parameters=[{"use_sim_time": True}]))
    return out


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value="false" if name in OFF_BY_DEFAULT else "",
                                description=text) for name, text in ARGUMENTS.items()),
        OpaqueFunction(function=nodes),
    ])
