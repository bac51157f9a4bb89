"""`cpg-walker topic list | echo TOPIC | hz TOPIC | info TOPIC | pub TOPIC TYPE [VALUES]`: `ros2 topic`
without ros2cli, on the domain in ROS_DOMAIN_ID, generic over the message types discovered from the graph
(core: cpg_walker.graph.ros2cli, ros2cli_graph (info), ros2cli_pub (pub))."""

from __future__ import annotations

import argparse
import math
import sys

from cpg_walker.cli.checks import at_least, count, non_negative, positive
from cpg_walker.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("topic", help="list/echo/measure the rate of/inspect/publish to topics (like `ros2 "
                                     "topic`)",
                       description="Topics of the running graph on the domain in ROS_DOMAIN_ID.")
    ps = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    q = ps.add_parser("list", help="topics with their types")
    q.add_argument("--wait", type=non_negative, default=3.0, metavar="S",
                   help="at most S seconds of discovery (default 3)")
    q.set_defaults(func=_list)
    q = ps.add_parser("echo", help="print the messages as YAML")
    q.add_argument("topic", metavar="TOPIC")
    q.add_argument("--once", action="store_true", help="one message, then exit")
    q.add_argument("--count", type=count, default=None, metavar="N", help="N messages, then exit")
    q.add_argument("--field", default=None, metavar="A.B", help="only this field, e.g. header.stamp")
    q.add_argument("--timeout", type=non_negative, default=None, metavar="S",
                   help="fail if the messages have not arrived after S wall seconds (default: wait)")
    q.set_defaults(func=_echo)
    q = ps.add_parser("hz", help="arrival rate in wall-clock time (not sim time), every second")
    q.add_argument("topic", metavar="TOPIC")
    q.add_argument("--window", type=at_least(2, int), default=10000, metavar="N",
                   help="statistics over the last N messages (default 10000)")
    q.add_argument("--duration", type=positive, default=None, metavar="S",
                   help="stop after S wall seconds (default: until Ctrl-C)")
    q.set_defaults(func=_hz)
    q = ps.add_parser("info", help="a topic's type and publisher/subscription counts (-v: each endpoint)")
    q.add_argument("topic", metavar="TOPIC")
    q.add_argument("-v", "--verbose", action="store_true",
                   help="each endpoint's node, type, GID and QoS profile")
    q.add_argument("--timeout", type=non_negative, default=10.0, metavar="S",
                   help="seconds to wait for the topic to be discovered (default 10)")
    q.set_defaults(func=_info)
    _register_pub(ps)


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a number, got {text!r}") from None
    if not 0.0 < value < math.inf:  # inf: a rate of "as fast as it goes" for ever, or a wait of for ever
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def _register_pub(ps: argparse._SubParsersAction) -> None:
    q = ps.add_parser("pub", help="publish a message (like `ros2 topic pub`), e.g. "
                                  "/cmd_vel geometry_msgs/msg/Twist '{linear: {x: 0.1}}' -r 10")
    q.add_argument("topic", metavar="TOPIC", help="e.g. /cmd_vel")
    q.add_argument("message_type", metavar="TYPE",
                   help="e.g. geometry_msgs/msg/Twist (or geometry_msgs/Twist)")
    g = q.add_mutually_exclusive_group()
    g.add_argument("values", metavar="VALUES", nargs="?", default="{}",
                   help="the fields in YAML, e.g. '{linear: {x: 0.1}, angular: {z: 0.2}}' (default: all "
                        "defaults; a Time field 'now' or a Header 'auto' is stamped at each publication)")
    g.add_argument("--stdin", action="store_true", help="read the values from standard input")
    q.add_argument("-r", "--rate", metavar="N", type=_positive_float, default=1.0,
                   help="publishing rate in Hz, wall clock (default: 1)")
    q.add_argument("-p", "--print", metavar="N", type=at_least(0, int), default=1,
                   help="only print every N-th published message (default: 1; 0: none)")
    g = q.add_mutually_exclusive_group()
    g.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    g.add_argument("-t", "--times", metavar="N", type=_nonnegative_int, default=0,
                   help="publish N times and exit (default 0: until Ctrl-C)")
    q.add_argument("-w", "--wait-matching-subscriptions", metavar="N", type=_nonnegative_int, default=None,
                   help="wait for N matching subscriptions first (default: 1 with -1/-t, else 0)")
    q.add_argument("--max-wait-time-secs", metavar="S", type=_positive_float, default=None,
                   help="give up waiting for the subscriptions after S wall seconds (default: wait)")
    q.add_argument("--keep-alive", metavar="S", type=_positive_float, default=0.1,
                   help="keep the publisher alive S wall seconds after the last message (default 0.1)")
    q.add_argument("-n", "--node-name", default=None, help="name of the publishing node (default: hidden)")
    # the QoS keys are rclpy's short keys (checked when used: rclpy is not imported for --help)
    q.add_argument("--qos-profile", default="default", metavar="PRESET",
                   help="QoS preset to publish with: default, sensor_data, system_default, services_default, "
                        "parameters, parameter_events, action_status_default, best_available (default: "
                        "default)")
    q.add_argument("--qos-depth", metavar="N", type=at_least(0, int), default=None,
                   help="queue depth (overrides the preset's)")
    q.add_argument("--qos-history", metavar="keep_last|keep_all", default=None,
                   help="history (overrides the preset's)")
    q.add_argument("--qos-reliability", metavar="reliable|best_effort", default=None,
                   help="reliability (overrides the preset's)")
    q.add_argument("--qos-durability", metavar="volatile|transient_local", default=None,
                   help="durability (overrides the preset's)")
    q.set_defaults(func=_pub)


def _list(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt

    with rt.Session("cpg_walker_topic") as s:
        topics = rt.topic_types(s, timeout=args.wait)
        for name in sorted(topics):
            print(f"{name} [{', '.join(topics[name])}]")
        if not rt._others_seen(s):
            print(f"cpg-walker topic: no node found in domain {s.domain}; is the graph running?",
                  file=sys.stderr)
            return 1
    return 0


def _echo(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt

    count = 1 if args.once else args.count
    if count is not None and count < 1:
        raise InputError(f"--count must be at least 1, got {count}")
    try:
        with rt.Session("cpg_walker_topic") as s:
            for text in rt.echo(s, args.topic, count, args.field, timeout=args.timeout):
                print(text, end="" if text.endswith("\n") else "\n")
                print("---", flush=True)
    except rt.ToolError as exc:
        print(f"cpg-walker topic: error: {exc}", file=sys.stderr)
        return 1
    return 0


def _hz(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt

    rt.RateMeter(args.window)  # validates --window before joining the graph
    try:
        with rt.Session("cpg_walker_topic") as s:
            print(f"measuring {rt.node_name(args.topic)}: arrival rate in wall-clock time", flush=True)
            last = None
            for summary in rt.hz(s, args.topic, args.window, duration=args.duration):
                last = summary
                print(rt.format_rate(summary) if summary else "no new messages", flush=True)
    except rt.ToolError as exc:
        print(f"cpg-walker topic: error: {exc}", file=sys.stderr)
        return 1
    return 0 if last else 1


def _info(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt
    from cpg_walker.graph import ros2cli_graph as rg

    try:
        with rt.Session("cpg_walker_topic") as s:
            types, pubs, subs = rg.topic_info(s, args.topic, timeout=args.timeout)
    except rt.ToolError as exc:
        print(f"cpg-walker topic: error: {exc}", file=sys.stderr)
        return 1
    print(rg.format_topic_info(types, pubs, subs, args.verbose), end="")
    return 0


def _pub(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt
    from cpg_walker.graph import ros2cli_pub as rp

    times = 1 if args.once else args.times
    wait = args.wait_matching_subscriptions
    wait = int(times != 0) if wait is None else wait
    if wait == 0 and args.max_wait_time_secs is not None:
        raise InputError("--max-wait-time-secs needs --wait-matching-subscriptions, --once or --times")
    qos = rp.qos_profile(args.qos_profile, args.qos_reliability, args.qos_durability, args.qos_depth,
                         args.qos_history)
    cls, msg, stamps = rp.build_message(args.message_type, sys.stdin.read() if args.stdin else args.values)
    if args.node_name is None:
        session = rt.Session("cpg_walker_pub")
    else:
        from rclpy.exceptions import InvalidNodeNameException

        try:
            session = rt.Session(args.node_name, hidden=False, pid_suffix=False)
        except InvalidNodeNameException as exc:
            raise InputError(f"--node-name {args.node_name!r} is not a valid node name "
                             f"({str(exc).splitlines()[0]})") from None
    try:
        with session as s:
            rp.publish(s, args.topic, cls, msg, stamps, period=1.0 / args.rate, print_nth=args.print,
                       times=times, wait_matching=wait, max_wait=args.max_wait_time_secs, qos=qos,
                       keep_alive=args.keep_alive)
    except rt.ToolError as exc:
        print(f"cpg-walker topic: error: {exc}", file=sys.stderr)
        return 1
    return 0
