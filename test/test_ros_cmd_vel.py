"""cpg_node's /cmd_vel through DDS: one cpg_node fed by a stand-in sim (the test publishes /clock, /imu and
/foot_load, test_ros_feedback.StandIn, so sim time advances only when the test ticks: deterministic) and
/cmd_vel from the test. Checked from /diagnostics: nothing followed before the first Twist; a bad Twist is
dropped and counted; a Twist is followed with the speed map's ζ/α and the turn rate; without messages the
timeout stops stepping (α command 0, the applied α falling smoothly); the next Twist resumes; the
``cmd_vel.*`` parameters are validated and ``cmd_vel.follow`` false hands back to the zeta/alpha
parameters; an angular.z with feedback off is reported as unable to turn. Waits are for conditions, with
hang-guard deadlines (ros_helpers.py)."""

from __future__ import annotations

import itertools
import math

import pytest
from ros_helpers import START_S
from test_ros_feedback import StandIn, _diag_values

from cpg_walker.nodes import interface as ifc
from cpg_walker.walker.cmd_vel import CmdVelLimits, SpeedMap


@pytest.mark.ros
def test_cmd_vel_follow_timeout_resume_and_bad_input(graph, probe):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import Twist
    from rcl_interfaces.msg import ParameterType, ParameterValue

    smap, limits = SpeedMap.load(), CmdVelLimits.load()
    cpg = graph.start("cpg_node")
    probe.listen(ifc.DIAGNOSTICS, DiagnosticArray, 500)
    pub = probe.node.create_publisher(Twist, ifc.CMD_VEL, 10)
    stand_in = StandIn(probe, dt=0.05)
    for topic in (ifc.CLOCK, ifc.IMU, ifc.CMD_VEL):
        probe.wait_endpoints(topic, 1, 1)
    sending: dict[str, tuple[float, float] | None] = {"twist": None}
    last_sent = {"t": -1.0}

    def twist(vx: float, wz: float, vy: float = 0.0) -> Twist:
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, wz
        return msg

    def step() -> None:
        stand_in.tick()
        if sending["twist"] is not None:
            pub.publish(twist(*sending["twist"]))
            last_sent["t"] = stand_in.now()

    diags = lambda: [(t, v, lvl) for _, m in probe.received[ifc.DIAGNOSTICS]  # noqa: E731
                     if (d := _diag_values(m)) for t, v in [d] for lvl in [m.status[0].level]]

    def holds(pred, v: dict) -> bool:
        try:
            return bool(pred(v))
        except KeyError:  # the first message (before the node's set-up) has no cmd_vel values
            return False

    def until(pred, what: str, since: float = -1.0) -> tuple[float, dict]:
        probe.wait(lambda: any(t > since and holds(pred, v) for t, v, _ in diags()),
                   lambda: f"{what}: {[(t, {k: x for k, x in v.items() if k.startswith(('cmd', 'alpha', 'zeta'))}) for t, v, _ in diags()[-3:]]}\n"  # noqa: E501
                           f"{cpg.log()[-2000:]}", START_S, each=step)
        return next((t, v) for t, v, _ in diags() if t > since and holds(pred, v))

    t_walk, v = until(lambda v: v["state"] == "walking", "the CPG walking")
    assert v["cmd_vel"] == "waiting" and v["alpha_command"] == "1"  # not following before a Twist
    pub.publish(twist(math.nan, 0.0))
    until(lambda v: v["cmd_vel_dropped"] == "1", "a NaN Twist dropped")
    assert "dropped /cmd_vel: non-finite linear.x" in cpg.log()

    sending["twist"] = (0.1, 0.05)
    zeta, alpha = smap.inverse(0.1)
    t_f, v = until(lambda v: v["cmd_vel"] == "following", "following /cmd_vel", t_walk)
    # the follower's output (cmd_vel_*), which the governor then reaches at its rates (zeta_command)
    assert float(v["cmd_vel_zeta"]) == pytest.approx(zeta, rel=1e-5) and float(v["cmd_vel_alpha"]) == alpha
    assert float(v["zeta_requested"]) == 1.0 and v["governor"] in ("accelerating", "following")
    assert float(v["cmd_vel_turn_rate"]) == 0.05 and v["cmd_vel_turn"] == "ok"
    assert v["cmd_vel_linear_x"] == "0.1" and v["cmd_vel_angular_z"] == "0.05"

    sending["twist"] = None  # the sender stops: the timeout stops stepping
    t_stop, v = until(lambda v: v["cmd_vel"] == "timed_out", "timed out", t_f)
    t_last = last_sent["t"]
    # falling; the turn slews down to 0 at cmd_vel.angular_z_rate
    assert float(v["alpha_command"]) < 1.0 and 0.0 <= float(v["cmd_vel_turn_rate"]) < 0.05
    until(lambda v: float(v["cmd_vel_turn_rate"]) == 0.0, "the turn at 0", t_stop)
    # a Twist is timed by the tick the node has when it arrives (t_last: the tick after the last send, or
    # one before it); the diagnostics come every 0.1 sim s
    assert limits.timeout - 2 * stand_in.dt <= t_stop - t_last <= limits.timeout + 0.1 + 2 * stand_in.dt, \
        (t_stop, t_last)
    # the α command falls at cmd_vel.alpha_fall_rate: 0 after 1 / rate (+ a diagnostics period)
    t_zero, _ = until(lambda v: v["alpha_command"] == "0", "the alpha command 0", t_stop)
    assert t_zero - (t_last + limits.timeout) <= 1.0 / limits.alpha_fall_rate + 0.1 + 2 * stand_in.dt, \
        (t_zero, t_last)
    t_low, _ = until(lambda v: float(v["alpha"]) < 0.05, "the applied alpha near 0", t_stop)
    alphas = [float(v["alpha"]) for t, v, _ in diags() if t_stop <= t <= t_low]
    assert all(b <= a for a, b in itertools.pairwise(alphas)) and alphas[0] > 0.5, alphas  # smooth
    assert float(v["cmd_vel_zeta"]) == pytest.approx(zeta, rel=1e-5)  # the direction kept

    sending["twist"] = (0.03, 0.0)  # resumes (slow: shorter steps at zeta 1)
    z2, a2 = smap.inverse(0.03)
    _, v = until(lambda v: v["cmd_vel"] == "following" and v["cmd_vel_linear_x"] == "0.03", "resumed", t_low)
    assert float(v["cmd_vel_alpha"]) == pytest.approx(a2, rel=1e-5) and float(v["cmd_vel_zeta"]) == z2

    # linear.y: this node paces in realtime, where the ankle pathway stays out but for a side step
    sending["twist"] = (0.0, 0.0, 0.02)
    _, v = until(lambda v: v["cmd_vel_linear_y"] == "0.02" and float(v["cmd_vel_side_step_mps"]) == 0.02,
                 "side-stepping", t_low)
    assert v["cmd_vel_side_step"] == "ok" and v["ankle_allowed"] == "false" and v["ankle_closed"] == "true"
    assert "cannot side-step the robot" not in cpg.log()

    bad = probe.set_param("cpg", "cmd_vel.timeout", -1.0)
    assert not bad.successful and "cmd_vel.timeout" in bad.reason, bad.reason
    bad = probe.set_param("cpg", "cmd_vel.speed_map", ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                                      string_value="no_such_map.yaml"))
    assert not bad.successful and "no_such_map.yaml" in bad.reason, bad.reason

    assert probe.set_param("cpg", "feedback", ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                             bool_value=False)).successful
    sending["twist"] = (0.085, 0.1)
    t_nt, v = until(lambda v: "feedback is off" in v["cmd_vel_turn"], "turning unavailable reported")
    assert float(v["cmd_vel_turn_rate"]) == 0.0
    assert any(lvl == DiagnosticStatus.WARN for t, _, lvl in diags() if t >= t_nt)
    assert "cannot turn the robot: feedback is off" in cpg.log()

    assert probe.set_param("cpg", "cmd_vel.follow", ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                                   bool_value=False)).successful
    _, v = until(lambda v: v["cmd_vel"] == "off", "not following", t_nt)
    until(lambda v: v["alpha_command"] == "1" and v["zeta_command"] == "1", "the zeta/alpha parameters again")
    sending["twist"] = None
