"""`cpg-walker param list|get|set|describe|dump NODE [NAME...] [VALUE]`: `ros2 param` without ros2cli,
through the node's real parameter services on the domain in ROS_DOMAIN_ID, in ros2cli's output formats
(core: cpg_walker.graph.ros2cli)."""

from __future__ import annotations

import argparse
import sys

from cpg_walker.cli.checks import non_negative


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("param", help="list/get/set/describe/dump a running node's parameters (like `ros2 "
                                     "param`)",
                       description="Talk to a running node's parameter services on the domain in "
                                   "ROS_DOMAIN_ID, e.g. `ROS_DOMAIN_ID=42 cpg-walker param set /cpg zeta "
                                   "0.8`.")
    ps = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, helptext in (("list", "the node's parameter names"), ("get", "one parameter's value"),
                           ("set", "set one parameter (value parsed as YAML, like ros2 param set)"),
                           ("describe", "parameters' type, description and constraints"),
                           ("dump", "all parameters as a ros__parameters YAML file (to stdout)")):
        q = ps.add_parser(verb, help=helptext)
        q.add_argument("node", metavar="NODE", help="node name, e.g. /cpg")
        if verb in ("get", "set"):
            q.add_argument("name", metavar="NAME", help="parameter name, e.g. zeta")
        if verb == "describe":
            q.add_argument("names", metavar="NAME", nargs="+", help="parameter names, e.g. zeta alpha")
        if verb == "set":
            q.add_argument("value", metavar="VALUE", help="e.g. 0.8, 1, true, '[1.0, 2.0]', text")
        q.add_argument("--timeout", type=non_negative, default=10.0, metavar="S",
                       help="seconds to wait for the node (default 10)")
        q.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt

    try:
        with rt.Session("cpg_walker_param") as s:
            if args.verb == "list":
                for name in rt.list_parameters(s, args.node, args.timeout):
                    print(f"  {name}")
                return 0
            if args.verb == "describe":
                for descriptor in rt.describe_parameters(s, args.node, args.names, args.timeout):
                    print(rt.format_descriptor(descriptor))
                return 0
            if args.verb == "dump":
                print(rt.dump_parameters(s, args.node, args.timeout))
                return 0
            if args.verb == "get":
                value = rt.get_parameters(s, args.node, [args.name], args.timeout)[0]
                print(rt.describe_value(value))
                return 0 if value.type else 1
            ok, reason = rt.set_parameter(s, args.node, args.name, args.value, args.timeout)
    except rt.ToolError as exc:
        print(f"cpg-walker param: error: {exc}", file=sys.stderr)
        return 1
    if ok:
        print("Set parameter successful")
        return 0
    print(f"Setting parameter failed: {reason}", file=sys.stderr)
    return 1
