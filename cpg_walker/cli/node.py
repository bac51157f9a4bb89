"""`cpg-walker node list | info NODE`: `ros2 node` without ros2cli, on the domain in ROS_DOMAIN_ID, in
ros2cli's output formats (core: cpg_walker.graph.ros2cli_graph)."""

from __future__ import annotations

import argparse
import sys

from cpg_walker.cli.checks import non_negative


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("node", help="list the running nodes, or one node's endpoints (like `ros2 node`)",
                       description="Nodes of the running graph on the domain in ROS_DOMAIN_ID.")
    ps = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    q = ps.add_parser("list", help="fully qualified node names, sorted")
    q.add_argument("-a", "--all", action="store_true", help="hidden nodes (names starting with _) as well")
    q.add_argument("-c", "--count-nodes", action="store_true", help="only the number of nodes")
    q.add_argument("--wait", type=non_negative, default=5.0, metavar="S",
                   help="at most S seconds of discovery (default 5)")
    q.set_defaults(func=_list)
    q = ps.add_parser("info", help="a node's subscribers, publishers, services and actions")
    q.add_argument("node", metavar="NODE", help="node name, e.g. /cpg")
    q.add_argument("--include-hidden", action="store_true",
                   help="hidden topics, services and actions as well")
    q.add_argument("--timeout", type=non_negative, default=10.0, metavar="S",
                   help="seconds to wait for the node to be discovered (default 10)")
    q.set_defaults(func=_info)


def _list(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt
    from cpg_walker.graph import ros2cli_graph as rg

    with rt.Session("cpg_walker_node") as s:
        names = rg.list_nodes(s, args.all, timeout=args.wait)
        domain = s.domain
    if args.count_nodes:
        print(len(names))
    elif names:
        if len(set(names)) < len(names):
            print("WARNING: Be aware that there are nodes in the graph that share an exact name, which can "
                  "have unintended side effects.", file=sys.stderr)
        print(*names, sep="\n")
    if not names:
        print(f"cpg-walker node: no node found in domain {domain}; is the graph running?", file=sys.stderr)
        return 1
    return 0


def _info(args: argparse.Namespace) -> int:
    from cpg_walker.graph import ros2cli as rt
    from cpg_walker.graph import ros2cli_graph as rg

    node = rt.node_name(args.node)
    try:
        with rt.Session("cpg_walker_node") as s:
            endpoints, count = rg.node_info(s, node, args.include_hidden, timeout=args.timeout)
    except rt.ToolError as exc:
        print(f"cpg-walker node: error: {exc}", file=sys.stderr)
        return 1
    if count > 1:
        print(rg.nonunique_warning(node, count), file=sys.stderr)
    print(rg.format_node_info(node, endpoints))
    return 0
