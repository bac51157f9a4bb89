"""Launch the HOAP-2 graph on a ROS 2 install: sim_node + pid_node (+ target_player_node with
``player:=true``). Example: ``ros2 launch cpg_walker sim_pid.launch.py pacing:=lockstep player:=true``.

Without ROS's launch tools (a pip install), use cpg_walker.nodes.graph.Graph instead.
"""

from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    pacing = LaunchConfiguration("pacing")
    player = LaunchConfiguration("player")
    lockstep = PythonExpression(["'", pacing, "' == 'lockstep'"])
    return LaunchDescription([
        DeclareLaunchArgument("pacing", default_value="realtime",
                              description="realtime | fast | lockstep"),
        DeclareLaunchArgument("control_period", default_value="0.002", description="s"),
        DeclareLaunchArgument("player", default_value="false",
                              description="also stream the recorded walk as /joint_targets"),
        DeclareLaunchArgument("gait", default_value="walk", description="walk | slow"),
        Node(package="cpg_walker", executable="sim_node", name="sim", output="screen",
             parameters=[{"use_sim_time": True, "pacing": pacing,
                          "control_period": LaunchConfiguration("control_period")}]),
        Node(package="cpg_walker", executable="pid_node", name="pid", output="screen",
             parameters=[{"use_sim_time": True, "lockstep": lockstep, "wait_for_targets": player}]),
        Node(package="cpg_walker", executable="target_player_node", name="target_player", output="screen",
             condition=IfCondition(player),
             parameters=[{"use_sim_time": True, "gait": LaunchConfiguration("gait")}]),
    ])
