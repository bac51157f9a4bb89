"""target_player_node: streams a recorded gait as ``/joint_targets`` (``ros2 run cpg_walker
target_player_node``), one message per ``/clock`` tick, stamped with that tick, so it stays in step with
the simulation in every pacing mode (event-driven on /clock, no wall timer). The recording plays from sim
time ``start_time``, then its steady cycle repeats (cpg_walker.robot.gait_data.GaitPlayback). Parameter
values: config/target_player.yaml (``--params-file``).
"""

from __future__ import annotations

from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes import specs
from cpg_walker.nodes.messages import JointStateBuilder
from cpg_walker.nodes.params import declare_params
from cpg_walker.nodes.runtime import (
    HotPath,
    exit_stats,
    parse_cli,
    run_main,
)
from cpg_walker.nodes.validation import to_ns
from cpg_walker.robot.gait_data import Cycle, GaitPlayback, find_steady_cycle, load_gait
from cpg_walker.timing import ActivityStats


class TargetPlayerNode(Node):
    """Plays a recording (GaitPlayback) on /clock. ``node_options`` go to rclpy's Node."""

    def __init__(self, **node_options) -> None:
        super().__init__(ifc.NODE_NAMES[ifc.PLAYER_NODE], **node_options)
        v = declare_params(self, specs.TARGET_PLAYER)
        gait, data, start = v["gait"], v["data"], v["start_time"]
        self.lookahead = bool(v["lookahead"])
        gait = load_gait(data or gait)
        try:
            cycle = find_steady_cycle(gait)
        except ValueError:
            cycle = Cycle(start=0.0, period=gait.duration + 1.0, mismatch_rad=float("nan"))
        self.playback = GaitPlayback(gait, cycle=cycle)
        self.start_ns = round(start * 1e9)
        self.last_tick_ns: int | None = None
        self.sent_ns: int | None = None
        self.builder = JointStateBuilder(self.playback.names, fields=("position", "velocity"))
        self.pub = self.create_publisher(JointState, ifc.JOINT_TARGETS, ifc.DEPTH)
        self.activity = ActivityStats()
        self.hot = HotPath(self, [self.create_subscription(Clock, ifc.CLOCK, self._on_clock, 100)])
        self.get_logger().info(f"playing {gait.name} ({gait.duration:.2f} s, then its "
                               f"{cycle.period:.3f} s cycle) from sim time {self.start_ns / 1e9} s")

    def _on_clock(self, msg: Clock) -> None:
        self.activity.tick()
        t_ns = to_ns(msg.clock.sec, msg.clock.nanosec)
        # not sent ahead (first tick, a gap), or a re-sent tick (the first one included: its target may
        # have gone out before the controller's subscription was matched): send it
        if t_ns != self.sent_ns or t_ns == self.last_tick_ns:
            self._publish(t_ns)
        if self.lookahead and self.last_tick_ns is not None and t_ns > self.last_tick_ns:
            # the target is a function of its stamp alone, so sending the next period's now is
            # deterministic and takes this node off the controller's critical path
            self._publish(t_ns + (t_ns - self.last_tick_ns))
        self.last_tick_ns = t_ns

    def _publish(self, t_ns: int) -> None:
        q, qd = self.playback.targets(max(0, t_ns - self.start_ns) / 1e9)
        self.pub.publish(self.builder.fill(t_ns, position=q, velocity=qd))
        self.sent_ns = t_ns

    def on_exit(self) -> None:
        exit_stats(self, self.activity.summary())



def main(argv: list[str] | None = None) -> int:
    argv = parse_cli("target_player_node", "Streams a recorded HOAP-2 gait as /joint_targets on /clock.",
                     specs.node_help(ifc.PLAYER_NODE), argv)
    return run_main(argv, TargetPlayerNode)


if __name__ == "__main__":
    raise SystemExit(main())
