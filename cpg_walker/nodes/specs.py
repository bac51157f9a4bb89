"""Every node's parameters (ParamSpec tuples, cpg_walker.nodes.params): the one home of each parameter's
name, type, range, read-only flag and description. The nodes declare from these; the reference pages
(docs/reference, cpg_walker.graph.reference) are rendered from them. Values: config/<node>.yaml."""

from __future__ import annotations

from cpg_walker.nodes.lossy_link import MAX_DELAY_S, MAX_JITTER_S
from cpg_walker.nodes.params import (
    SCHEDULING,
    STATS,
    ParamSpec,
    boolean,
    double,
    doubles,
    integer,
    string,
    strings,
)
from cpg_walker.robot.joints import GROUPS, MAX_TORQUE_NM
from cpg_walker.robot.pid import GAINS
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig
from cpg_walker.walker.governor import GovernorConfig, command_range

SIM = (
    string("pacing", "realtime | fast | lockstep", read_only=True),
    double("control_period", "s between state samples / torque updates (multiple of the physics timestep)",
           1e-4, 0.1, read_only=True),
    double("real_time_factor", "target sim/wall speed in realtime pacing", 0.01, 100.0),
    double("duration", "sim s to run, then exit (0 = until stopped)", 0.0, 1e6, read_only=True),
    boolean("publish_description",
            "publish the URDF on /robot_description (off when robot_state_publisher does)", read_only=True),
    boolean("stop_on_fall", "exit when the robot has fallen", read_only=True),
    boolean("wait_for_controller", "hold the first period until a torque arrives (every pacing)",
            read_only=True),
    string("wait_for_subscriber", "hold the first state until this node (e.g. recorder) subscribes to every "
           "state topic, and the second until it subscribes to the controllers' targets and torques ('' = do "
           "not wait)", read_only=True),
    double("lockstep_resend", "wall s without an answer before the state is re-sent", 0.001, 10.0),
    double("late_torque_wait", "realtime: wall s past a period's deadline to wait for a torque at most "
           "max_torque_age old before going on with the held one (0 = never wait)", 0.0, 10.0),
    double("max_torque_age", "realtime: sim s a torque may be old and still drive a period without waiting",
           0.0, 1.0, read_only=True),
    double("servo_hold_after", "sim s a torque may be old before the servos hold their posture by themselves "
           "(a lost controller); 0 = never", 0.0, 10.0, read_only=True),
    double("odom_period", "sim s between ground-truth odometry messages", 0.0, 10.0, read_only=True),
    boolean("publish_tf", "publish the ground truth's odom -> base_link on /tf (where tf2_msgs imports); off "
            "when odom_node's estimate does (REP-105)", read_only=True),
    double("diagnostics_period", "sim s between /diagnostics messages", 0.01, 100.0, read_only=True),
    double("imu_variance_floor", "diagonal IMU variance when the model's sensor noise is 0", 0.0, 1.0,
           read_only=True),
    doubles("push.force", "world-frame force (N) of ~/push"),
    string("push.body", "MJCF body name ~/push acts on (at its CoM)"),
    double("push.duration", "s of sim time ~/push lasts", 1e-4, 10.0),
    string("record_path", "write a JSON run record here on exit ('' = none)", read_only=True),
    double("record_period", "sim s between recorded samples", 1e-3, 1.0, read_only=True),
    *SCHEDULING,
    *STATS,
)

#: Upper ends of the gains' ranges (N*m/rad, N*m/(rad*s), N*m*s/rad): far above any stable HOAP-2 gain.
GAIN_RANGES = {"kp": 2000.0, "ki": 2000.0, "kd": 200.0}


def gain(name: str) -> ParamSpec:
    """The spec of a PID gain ``kp.leg`` / ``kd.lleg_joint_4`` (a group's, or a joint's override)."""
    g, owner = name.split(".", 1)
    return double(name, f"{g} of the {owner} joint(s)", 0.0, GAIN_RANGES[g])


#: pid_node's gains of each joint group (per-joint overrides given at start-up get ``gain(name)`` too).
PID_GAINS = tuple(gain(f"{g}.{group}") for g in GAINS for group in GROUPS)
PID = (
    *PID_GAINS,
    double("max_torque", "N*m torque clamp", 0.0, MAX_TORQUE_NM),
    double("integral_limit", "N*m anti-windup clamp", 0.0, 100.0),
    double("max_velocity", "rad/s beyond which no torque speeds a joint up further", 0.0, 100.0),
    double("target_timeout", "sim s without a target before holding the last posture", 1e-3, 1e3),
    boolean("lockstep", "answer state t_k only with the target stamped t_k", read_only=True),
    boolean("wait_for_targets", "do not answer before the first target has arrived; in lockstep, wait for "
            "the target of every period", read_only=True),
    double("target_wait", "lockstep: wall s to wait for a target before the watchdog trips", 1e-3, 1e3),
    double("startup_wait", "lockstep: wall s to wait for the first target", 1e-3, 1e4),
    *SCHEDULING,
    double("safe_blend", "sim s of the C1 blend from the horizon's end to the standing crouch", 0.0, 10.0),
    double("resume_blend", "sim s of the C1 blend back to the live targets (or to a newer horizon)",
           0.0, 10.0),
    *STATS,
)

TARGET_PLAYER = (
    string("gait", "packaged recording: walk or slow", read_only=True),
    string("data", "a CSV in the packaged layout (overrides gait)", read_only=True),
    double("start_time", "sim s at which the recording starts", 0.0, 1e6, read_only=True),
    boolean("lookahead", "also send the next period's target on each tick (period from the last two ticks)",
            read_only=True),
    *STATS,
)

RECORDER = (
    string("out_dir",
           "directory of the bag (recording.mcap + metadata.yaml); '' = ./recording_<UTC date-time>",
           read_only=True),
    double("scan_period", "wall s between scans of the graph for new topics", 0.01, 60.0, read_only=True),
    integer("queue_depth", "messages held per subscription until the recorder takes them", 1, 1_000_000,
            read_only=True),
    double("duration", "s of bag time to record, then stop (0 = until stopped)", 0.0, 1e9, read_only=True),
    *SCHEDULING,
    *STATS,
)

FOXGLOVE = (
    string("host", "address the WebSocket server binds to (127.0.0.1: this machine only; 0.0.0.0: every "
           "interface)", read_only=True),
    integer("port", "TCP port of the WebSocket server (0 = any free port)", 0, 65535, read_only=True),
    double("display_rate", "most messages per wall second on each high-rate channel", 1.0, 500.0,
           read_only=True),
    double("service_timeout", "wall s to wait for a node's parameter service before answering Foxglove "
           "without it", 0.1, 60.0, read_only=True),
    strings("parameters", "parameters of other nodes shown in Foxglove's parameter panel, NODE.NAME (e.g. "
            "cpg.zeta)", read_only=True),
    *SCHEDULING,
    *STATS,
)

ODOM = (
    double("publish_period", "sim s between /odom messages (every sensor sample is processed)", 1e-4, 10.0,
           read_only=True),
    boolean("publish_tf", "also publish odom -> base_link on /tf (where tf2_msgs imports)", read_only=True),
    boolean("flat_floor", "anchor a touching-down foot at the floor's height (a flat-floor prior)",
            read_only=True),
    double("velocity_filter", "s: time constant of the low-pass on the position's rate (the twist)",
           0.0, 10.0, read_only=True),
    *(double(f"covariance.{name}", text, 0.0, 100.0, read_only=True) for name, text in (
        ("position_sigma0", "m: x, y standard deviation at the start"),
        ("position_per_m", "m per m walked: growth of the x, y standard deviation"),
        ("position_per_rad", "m per rad turned: growth of the x, y standard deviation"),
        ("z_sigma0", "m: z standard deviation at the start"),
        ("z_per_m", "m per m walked: growth of the z standard deviation"),
        ("tilt_sigma", "rad: roll and pitch standard deviation"),
        ("yaw_sigma0", "rad: yaw standard deviation at the start"),
        ("yaw_per_rad", "rad per rad turned: growth of the yaw standard deviation"),
        ("yaw_per_m", "rad per m walked: growth of the yaw standard deviation"),
        ("linear_velocity_sigma", "m/s: twist linear standard deviation"),
        ("angular_velocity_sigma", "rad/s: twist angular standard deviation"))),
    *SCHEDULING,
    *STATS,
)

RELAY = (
    strings("topics", "topics to relay", read_only=True),
    strings("types", "their message types (pkg/msg/Type), one per topic", read_only=True),
    string("prefix", "output topic = prefix + input topic (e.g. /net)", read_only=True),
    double("loss", "fraction of messages dropped", 0.0, 1.0),
    double("delay", "wall s each message is held", 0.0, MAX_DELAY_S),
    double("jitter", "wall s: plus U(0, jitter)", 0.0, MAX_JITTER_S),
    integer("seed", "seed of the drops' and jitter's RNG", 0, 2**31 - 1, read_only=True),
    integer("queue_depth", "history of each subscription and publisher", 1, 100_000, read_only=True),
    double("diagnostics_period", "wall s between /diagnostics messages (while messages flow)", 0.05, 100.0,
           read_only=True),
    *SCHEDULING,
    *STATS,
)

#: cpg_node's /cmd_vel limits (walker/cmd_vel.py CmdVelLimits; values: config/cpg.yaml).
CPG_CMD_VEL_LIMITS = (
    double("cmd_vel.timeout", "sim s without a /cmd_vel message before stepping stops (alpha -> 0)",
           0.01, 60.0),
    double("cmd_vel.max_linear_x", "largest forward linear.x followed (m/s; larger is clamped)", 0.0, 1.0),
    double("cmd_vel.min_linear_x", "most negative (backward) linear.x followed (m/s; smaller is clamped)",
           -1.0, 0.0),
    double("cmd_vel.max_angular_z", "largest |angular.z| followed (rad/s; larger is clamped; the range: "
           "what walked, docs/steering.md)", 0.0, 0.5),
    double("cmd_vel.stand_below", "|linear.x| below this (m/s): stand (alpha 0)", 0.0, 0.1),
    double("cmd_vel.alpha_fall_rate", "the alpha command falls at most this much per sim s (a stop takes "
           "1/rate s)", 0.01, 100.0),
    double("cmd_vel.max_linear_y", "largest |linear.y| followed (m/s, sideways; larger is clamped; the "
           "range: what walked, docs/steering.md)", 0.0, 0.05),
    double("cmd_vel.steer_zeta", "|zeta| at least, while turning or side-stepping", 0.3, 2.0),
    double("cmd_vel.steer_alpha", "alpha at least, while turning or side-stepping (side-stepping in "
           "place: exactly)", 0.01, 1.0),
    double("cmd_vel.turn_alpha", "alpha of a turn in place (no linear.x, no linear.y)", 0.01, 1.0),
    double("cmd_vel.angular_z_rate", "the turn rate moves at most this much per sim s walking (rad/s^2)",
           0.01, 100.0),
    double("cmd_vel.angular_z_rate_in_place", "the same stepping in place (rad/s^2)", 0.01, 100.0),
    double("cmd_vel.side_step_max_alpha", "alpha at most while side-stepping (at |zeta| = steer_zeta): "
           "linear.x beside linear.y is followed up to the speed of those steps (the range: what walked, "
           "docs/steering.md)", 0.01, 1.0),
)

CPG = (
    string("cpg_file", "learned CPG YAML (a path, or a name in the package's config/); '' = learn at "
           "start-up", read_only=True),
    integer("n_oscillators", "oscillators per DOF when learning at start-up (0 = the learning settings' N)",
            0, 20, read_only=True),
    boolean("governor", "reach every zeta/alpha along a path that walks (walker/governor.py, "
            f"config/governor.yaml); false: the raw controller (alpha up to {ALPHA_RANGE[1]:g})",
            read_only=True),
    double("zeta", "frequency ratio ζ of the oscillators (negative: backwards)", *ZETA_RANGE),
    double("alpha", "amplitude (step length) scale α of the oscillators: up to the longest step that walked "
           f"(config/governor.yaml's envelope; governor false: up to {ALPHA_RANGE[1]:g})",
           *command_range("alpha", GovernorConfig.load())),
    boolean("lookahead", "also send the next period's target on each tick", read_only=True),
    double("monitor_period", "sim s between /cpg/state and /diagnostics messages", 0.002, 60.0,
           read_only=True),
    *SCHEDULING,
    double("horizon", "sim s of future targets in each /joint_trajectory (0 = none published)", 0.0, 5.0,
           read_only=True),
    double("horizon_step", "sim s between /joint_trajectory points", 0.002, 1.0, read_only=True),
    double("horizon_period", "sim s between /joint_trajectory messages (0 = horizon_step; at most half "
           "the horizon)", 0.0, 2.5, read_only=True),
    double("horizon_stop", "sim s after the horizon over which its stepping dies out (alpha -> 0): where "
           "pid_node goes when this node is gone", 0.0, 10.0, read_only=True),
    double("rejoin_settle", "sim s a node that joined a running sim (realtime pacing) stands by before it "
           "re-enters the gait (pid_node holds the crouch meanwhile); lockstep re-enters at once", 0.0, 10.0,
           read_only=True),
    boolean("lockstep", "wait for the sensor samples stamped like each /clock tick (deterministic; with the "
            "sim's lockstep pacing)", read_only=True),
    boolean("ankle_in_realtime", "the ankle feedback pathway acts outside lockstep too (its rate gains need "
            "a loop that waits for its samples: on an overloaded realtime machine it fell, docs/governor.md)",
            read_only=True),
    boolean("ankle_for_side_step", "without ankle_in_realtime, a /cmd_vel side step closes the ankle "
            "pathway while it lasts (side steps need it; false: linear.y is refused outside lockstep)",
            read_only=True),
    boolean("ankle_for_speed", "without ankle_in_realtime, a command of steps longer than the plain envelope "
            "allows (the speed map's fast nodes, config/governor.yaml ankle:) closes the ankle pathway while "
            "it lasts (false: /cmd_vel linear.x stops short of them outside lockstep)", read_only=True),
    boolean("feedback", "close the sensory feedback pathways (false: the open-loop CPG)"),
    double("sensor_timeout", "sim s without a newer /imu or /foot_load sample before feedback fades out",
           1e-3, 10.0),
    double("feedback_fade", "sim s over which feedback fades out (stale sensors, switched off) or back in",
           0.0, 60.0),
    double("sensor_wait", "lockstep: wall s to wait for a tick's sensor samples before going on with the "
           "newest", 1e-3, 60.0),
    boolean("cmd_vel.follow", "follow /cmd_vel from its first message on (false: ignore it; zeta/alpha "
            "parameters only)"),
    *CPG_CMD_VEL_LIMITS,
    string("cmd_vel.speed_map", "measured speed vs zeta/alpha for linear.x (a path, or a name in the "
           "package's config/)"),
    boolean("teach", "learn from /cpg/teach (sensor_msgs/JointState) while walking; ~/take_over, "
            "~/save_taught (walker/live_teaching.py)", read_only=True),
    integer("teach_steps", "learning steps (RK4, ~0.08 ms each) after each tick's targets: the teacher's "
            "rate they keep up with, about 6 per step at 500 Hz", 1, 1000),
    double("teach_blend", "sim s over which a taught network's targets cross-fade in at ~/take_over", 0.0,
           10.0),
    string("teach_file", "where ~/save_taught writes the taught network (a CPG YAML cpg_file loads)"),
    *STATS,
)


def cpg_specs(governed: bool) -> tuple[ParamSpec, ...]:
    """cpg_node's specs: alpha's range is what walks with the governor (CPG), the raw CPG's without."""
    if governed:
        return CPG
    return tuple(double(s.name, s.description, *ALPHA_RANGE) if s.name == "alpha" else s for s in CPG)


#: FeedbackConfig field types that are ROS parameters, as ParamSpec types.
FEEDBACK_FIELD_TYPES = {float: "double", str: "string", bool: "bool"}


def feedback_field_specs() -> tuple[ParamSpec, ...]:
    """``feedback.<field>`` for every FeedbackConfig field of a plain type (walker/feedback.py)."""
    from dataclasses import fields
    from typing import get_type_hints

    hints = get_type_hints(FeedbackConfig)
    return tuple(ParamSpec(f"feedback.{f.name}", FEEDBACK_FIELD_TYPES[hints[f.name]],
                           f"FeedbackConfig.{f.name} (walker/feedback.py; default in config/feedback.yaml)")
                 for f in fields(FeedbackConfig) if hints.get(f.name) in FEEDBACK_FIELD_TYPES)


#: cpg_node's parameters whose default is config/feedback.yaml's value (config/cpg.yaml may override it).
CPG_FEEDBACK = (strings("feedback_pathways", f"feedback pathways in use, any of {', '.join(PATHWAYS)}"),
                *feedback_field_specs())

#: Every node's specs, by executable.
SPECS = {"sim_node": SIM, "pid_node": PID, "target_player_node": TARGET_PLAYER,
         "cpg_node": CPG + CPG_FEEDBACK, "recorder_node": RECORDER, "foxglove_node": FOXGLOVE,
         "relay_node": RELAY, "odom_node": ODOM}


def node_help(executable: str) -> str:
    """A node's ``--help`` epilog: its topics (interface.help_text) and every parameter with its range."""
    from cpg_walker.nodes.interface import help_text
    from cpg_walker.nodes.params import range_text

    lines = [help_text(executable), "parameters (type range: description; * = settable at run time):"]
    for spec in SPECS[executable]:
        rng = range_text(spec)
        settable = "" if spec.read_only else " *"
        lines.append(f"  {spec.name} ({spec.type}{' ' + rng if rng else ''}){settable}: {spec.description}")
    return "\n".join(lines)
