"""`cpg-walker topic list | echo TOPIC | hz TOPIC`: `ros2 topic` without ros2cli, on the domain in
ROS_DOMAIN_ID, generic over the message types discovered from the graph (core: cpg_walker.nodes.rostools)."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("topic", help="list/echo/measure the rate of topics (like `ros2 topic`)",
                       description="Topics of the running graph on the domain in ROS_DOMAIN_ID.")
    ps = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    q = ps.add_parser("list", help="topics with their types")
    q.add_argument("--wait", type=float, default=3.0, metavar="S",
                   help="at most S seconds of discovery (default 3)")
    q.set_defaults(func=_list)
    q = ps.add_parser("echo", help="print the messages as YAML")
    q.add_argument("topic", metavar="TOPIC")
    q.add_argument("--once", action="store_true", help="one message, then exit")
    q.add_argument("--count", type=int, default=None, metavar="N", help="N messages, then exit")
    q.add_argument("--field", default=None, metavar="A.B", help="only this field, e.g. header.stamp")
    q.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="fail if the messages have not arrived after S wall seconds (default: wait)")
    q.set_defaults(func=_echo)
    q = ps.add_parser("hz", help="arrival rate in wall-clock time (not sim time), every second")
    q.add_argument("topic", metavar="TOPIC")
    q.add_argument("--window", type=int, default=10000, metavar="N",
                   help="statistics over the last N messages (default 10000)")
    q.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S wall seconds (default: until Ctrl-C)")
    q.set_defaults(func=_hz)


def _list(args: argparse.Namespace) -> int:
    from cpg_walker.nodes import rostools as rt

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
    from cpg_walker.nodes import rostools as rt

    count = 1 if args.once else args.count
    if count is not None and count < 1:
        raise ValueError(f"--count must be at least 1, got {count}")
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
    from cpg_walker.nodes import rostools as rt

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
