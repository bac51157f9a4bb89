"""The graph's interface in one place: topic names, QoS profiles, node names, what each node subscribes
and publishes, and the graph's specification (which nodes make a graph; which pacing makes pid_node and
cpg_node lockstep). Everything else imports these instead of repeating the literals.

Frames are robot facts and live in cpg_walker/robot/frames.py (``ODOM_FRAME``, ``BASE_LINK``, the sole and
IMU frames, ``FOOT_LOAD_FRAMES``: the sides below with their sole frames).

Nothing heavy at import time (the CLI and the launch files import this module; robot/frames.py imports
MuJoCo): no rclpy, the QoS profiles are made by functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

# ----------------------------------------------------------------------------------------- topics
CLOCK = "/clock"
JOINT_STATES = "/joint_states"
JOINT_TARGETS = "/joint_targets"
JOINT_TORQUES = "/joint_torques"
JOINT_TRAJECTORY = "/joint_trajectory"
IMU = "/imu"
FOOT_LOAD = "/foot_load"  # namespace: /foot_load/left, /foot_load/right (foot_load_topic)
ODOM = "/odom"
ODOM_GROUND_TRUTH = "/odom/ground_truth"
SIM_FALLEN = "/sim/fallen"
SIM_SERVO_HOLD = "/sim/servo_hold"
DIAGNOSTICS = "/diagnostics"
ROBOT_DESCRIPTION = "/robot_description"
TF = "/tf"
TF_STATIC = "/tf_static"
CMD_VEL = "/cmd_vel"
CPG_STATE = "/cpg/state"
CPG_TEACH = "/cpg/teach"
CPG_TEACH_STATE = "/cpg/teach/state"
PARAMETER_EVENTS = "/parameter_events"
ROSOUT = "/rosout"
#: foxglove_node's own channels (Foxglove WebSocket, not ROS topics)
CONTACT = "/contact"
CONTACT_TOUCHDOWN = "/contact/touchdown"


def foot_load_topic(side: str) -> str:
    """``left`` -> ``/foot_load/left``."""
    return f"{FOOT_LOAD}/{side}"


#: The feet whose sole loads are published (frames.FOOT_LOAD_FRAMES pairs each with its sole frame).
FOOT_LOAD_SIDES = ("left", "right")
#: /foot_load/left, /foot_load/right
FOOT_LOADS = FOOT_LOAD_LEFT, FOOT_LOAD_RIGHT = tuple(foot_load_topic(side) for side in FOOT_LOAD_SIDES)

# ----------------------------------------------------------------------------------------- QoS
#: History depth of the state, command and clock topics' publishers and subscriptions (reliable, volatile).
DEPTH = 10


def latched_qos() -> QoSProfile:
    """Depth 1, reliable, transient local: a late subscriber still gets the last message (/sim/fallen,
    /sim/servo_hold, /robot_description)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def matching_qos(infos: list, depth: int) -> QoSProfile:
    """A subscription QoS that receives from every publisher in ``infos`` (their TopicEndpointInfo):
    reliable and transient local only when all of them are (like ``ros2 topic echo``)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


# ----------------------------------------------------------------------------------------- nodes
#: Each node executable's ROS node name; its parameters are config/<node name>.yaml.
NODE_NAMES = {"sim_node": "sim", "pid_node": "pid", "target_player_node": "target_player", "cpg_node": "cpg",
              "recorder_node": "recorder", "foxglove_node": "foxglove", "relay_node": "relay",
              "odom_node": "odom"}
#: Node name -> executable.
EXECUTABLES = {name: exe for exe, name in NODE_NAMES.items()}

SIM_NODE, PID_NODE, CPG_NODE, PLAYER_NODE = "sim_node", "pid_node", "cpg_node", "target_player_node"
RECORDER_NODE, FOXGLOVE_NODE, RELAY_NODE = "recorder_node", "foxglove_node", "relay_node"
ODOM_NODE = "odom_node"

# ----------------------------------------------------------------------------------------- the graph
#: sim_node's pacings: wall-clock schedule, as fast as possible, or one period per controller answer.
PACINGS = ("realtime", "fast", "lockstep")
LOCKSTEP = "lockstep"
#: The sources of /joint_targets a graph runs with: the learned CPG, or a recorded gait.
TARGET_SOURCES = (CPG_NODE, PLAYER_NODE)
#: The controllers that have a ``lockstep`` parameter (set by controllers_lockstep from the sim's pacing).
LOCKSTEP_NODES = (PID_NODE, CPG_NODE)


def graph_nodes(source: str = CPG_NODE) -> tuple[str, ...]:
    """The node executables that close the control loop: the sim, the servos and a target source."""
    if source not in TARGET_SOURCES:
        raise ValueError(f"target source must be one of {TARGET_SOURCES}, got {source!r}")
    return (SIM_NODE, PID_NODE, source)


def controllers_lockstep(pacing: str) -> bool:
    """The graph's rule: pid_node and cpg_node answer in lockstep iff the sim's pacing is lockstep."""
    return pacing == LOCKSTEP


# ----------------------------------------------------------------------------------------- per node
@dataclass(frozen=True)
class Topic:
    """A topic of the graph: its name, message type and what it carries (QoS: ``latched`` or DEPTH)."""

    name: str
    type: str
    description: str
    latched: bool = False


TOPICS = {t.name: t for t in (
    Topic(CLOCK, "rosgraph_msgs/msg/Clock", "sim time, one message per control period"),
    Topic(JOINT_STATES, "sensor_msgs/msg/JointState",
          "position, velocity, effort of all 25 joints, stamped t_k = k * control_period"),
    Topic(JOINT_TARGETS, "sensor_msgs/msg/JointState",
          "target position (optional velocity) by joint name, stamped with the state it is for"),
    Topic(JOINT_TORQUES, "sensor_msgs/msg/JointState",
          "name + effort (N*m), stamped like the state it answers"),
    Topic(JOINT_TRAJECTORY, "trajectory_msgs/msg/JointTrajectory",
          "the target source's horizon of future targets (followed by pid_node when targets are late)"),
    Topic(IMU, "sensor_msgs/msg/Imu", "torso IMU, frame 'imu'"),
    *(Topic(topic, "geometry_msgs/msg/WrenchStamped", f"{side} sole load, in the sole's frame")
      for side, topic in zip(FOOT_LOAD_SIDES, FOOT_LOADS, strict=True)),
    Topic(ODOM, "nav_msgs/msg/Odometry",
          "the leg odometry's estimate odom -> base_link, with a covariance (joints, IMU, sole loads)"),
    Topic(ODOM_GROUND_TRUTH, "nav_msgs/msg/Odometry",
          "ground-truth odometry odom -> base_link (evaluation only)"),
    Topic(SIM_FALLEN, "std_msgs/msg/Bool", "the robot has fallen", latched=True),
    Topic(SIM_SERVO_HOLD, "std_msgs/msg/Bool", "the servos hold their posture by themselves (no controller)",
          latched=True),
    Topic(DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray", "the node's status and counters"),
    Topic(ROBOT_DESCRIPTION, "std_msgs/msg/String", "the URDF", latched=True),
    Topic(TF, "tf2_msgs/msg/TFMessage", "odom -> base_link (only where tf2_msgs is installed)"),
    Topic(CMD_VEL, "geometry_msgs/msg/Twist", "velocity command: forward speed and turn rate"),
    Topic(CPG_STATE, "std_msgs/msg/Float64MultiArray", "the oscillators' phases, frequencies, amplitudes"),
    Topic(CPG_TEACH, "sensor_msgs/msg/JointState",
          "a gait to learn live: the CPG's ten joints, stamped in the teacher's time"),
    Topic(CPG_TEACH_STATE, "std_msgs/msg/Float64MultiArray",
          "the live learning's per-joint frequency, amplitude and error"),
    Topic(PARAMETER_EVENTS, "rcl_interfaces/msg/ParameterEvent", "parameter changes of every node"),
)}


@dataclass(frozen=True)
class NodeInterface:
    """A node executable's ROS interface: node name, topics subscribed and published (names of TOPICS),
    services, and a note on what the lists cannot say (topics chosen at run time)."""

    executable: str
    summary: str
    subscribes: tuple[str, ...] = ()
    publishes: tuple[str, ...] = ()
    services: tuple[str, ...] = ()
    note: str = ""
    #: Topics chosen at run time (by parameters, or found in the graph) besides the listed ones.
    runtime_topics: bool = False

    @property
    def name(self) -> str:
        return NODE_NAMES[self.executable]


INTERFACES = {i.executable: i for i in (
    NodeInterface(SIM_NODE, "the MuJoCo HOAP-2 simulation, paced realtime, fast or lockstep",
                  subscribes=(JOINT_TORQUES,),
                  publishes=(CLOCK, JOINT_STATES, IMU, *FOOT_LOADS, ODOM_GROUND_TRUTH, SIM_FALLEN,
                             SIM_SERVO_HOLD, DIAGNOSTICS, ROBOT_DESCRIPTION, TF),
                  services=("~/reset", "~/push"),
                  note="/robot_description only with publish_description; /tf only with publish_tf, where "
                       "tf2_msgs imports."),
    NodeInterface(PID_NODE, "the HOAP-2 joint servos: answers each state with torques",
                  subscribes=(JOINT_TARGETS, JOINT_STATES, JOINT_TRAJECTORY), publishes=(JOINT_TORQUES,),
                  note="/joint_trajectory is not subscribed in lockstep. Per-joint gains (`kp.<joint>` ...) "
                       "given at start-up are declared beside the group gains, with the same ranges."),
    NodeInterface(CPG_NODE, "the learned CPG: joint targets from the oscillators, on /clock",
                  subscribes=(CLOCK, IMU, *FOOT_LOADS, CMD_VEL, SIM_SERVO_HOLD, CPG_TEACH),
                  publishes=(DIAGNOSTICS, CPG_STATE, JOINT_TARGETS, JOINT_TRAJECTORY, CPG_TEACH_STATE),
                  services=("~/take_over", "~/save_taught"),
                  note="/cpg/teach, /cpg/teach/state and the services only with teach."),
    NodeInterface(ODOM_NODE, "leg odometry from the joints, the IMU and the sole loads (no ground truth)",
                  subscribes=(JOINT_STATES, IMU, *FOOT_LOADS), publishes=(ODOM, TF),
                  note="/tf only with publish_tf, where tf2_msgs imports."),
    NodeInterface(PLAYER_NODE, "streams a recorded gait as joint targets, on /clock",
                  subscribes=(CLOCK,), publishes=(JOINT_TARGETS,)),
    NodeInterface(RECORDER_NODE, "records every topic of the graph to one rosbag2 MCAP",
                  note="Subscribes to every topic that has a publisher (found by scanning the graph, the "
                       "publishers' QoS); writes /tf and /tf_static into the bag on stop.",
                  runtime_topics=True),
    NodeInterface(FOXGLOVE_NODE, "a live view of the walking robot in Foxglove (WebSocket server)",
                  subscribes=(JOINT_STATES, JOINT_TARGETS, ODOM_GROUND_TRUTH, *FOOT_LOADS, CPG_STATE,
                              CPG_TEACH_STATE, DIAGNOSTICS, PARAMETER_EVENTS),
                  note="Serves Foxglove channels /tf, /joint_states, /joint_targets, /cpg/state, "
                       "/cpg/teach/state, /contact, /contact/touchdown, /diagnostics, /robot_description; "
                       "calls the parameter services of the forwarded parameters' nodes."),
    NodeInterface(RELAY_NODE, "a degraded link between remapped topics, for fault injection",
                  publishes=(DIAGNOSTICS,),
                  note="Subscribes to each of `topics` (raw) and publishes it again on `prefix` + topic.",
                  runtime_topics=True),
)}


def help_text(executable: str) -> str:
    """A node executable's interface for its ``--help``: topics subscribed and published (with types),
    services, and where its parameters are described."""
    i = INTERFACES[executable]
    lines = [f"{i.summary} (node /{i.name})"]
    for verb, names in (("subscribes", i.subscribes), ("publishes", i.publishes)):
        if names:
            typed = (f"{n} ({TOPICS[n].type.replace('/msg/', '/')})" for n in names)
            lines.append(f"{verb}: " + ", ".join(typed))
    if i.services:
        lines.append("services: " + ", ".join(i.services))
    if i.note:
        lines.append(i.note)
    lines.append(f"parameters: docs/reference/{executable}.md")
    return "\n".join(lines)
