"""`cpg-walker graph`: the node graph in the foreground (sim_node + pid_node + cpg_node, or the recorded
gait's player with --player), without `ros2 launch`: prints the DDS domain and how to talk to it from
another shell, streams the nodes' log lines, stops everything on Ctrl-C / SIGTERM or when the sim ends."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import domain_id, non_negative, out_dir, within
from cpg_walker.cli.outcome import fall_line, report_fall
from cpg_walker.errors import InputError
from cpg_walker.nodes.interface import PACINGS
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE
from cpg_walker.walker.governor import GovernorConfig

ALIASES = {"sim": "sim_node", "pid": "pid_node", "cpg": "cpg_node", "player": "target_player_node",
           "target_player": "target_player_node", "foxglove": "foxglove_node", "odom": "odom_node"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("graph", help="run the ROS node graph in the foreground (like `ros2 launch`)")
    p.add_argument("--pacing", choices=PACINGS, default=None,
                   help="the sim node's pacing (default: config/sim.yaml's)")
    p.add_argument("--duration", type=non_negative, default=None, metavar="S",
                   help="sim seconds, then everything stops; 0: until Ctrl-C (default: config/sim.yaml's)")
    p.add_argument("--zeta", type=within(*ZETA_RANGE), default=None, metavar="Z",
                   help=f"cpg_node's zeta, in [{ZETA_RANGE[0]:g}, {ZETA_RANGE[1]:g}]")
    p.add_argument("--alpha", type=within(*ALPHA_RANGE), default=None, metavar="A",
                   help=f"cpg_node's alpha, in [0, {GovernorConfig.load().alpha_limit:g}] with its governor, "
                        f"[{ALPHA_RANGE[0]:g}, {ALPHA_RANGE[1]:g}] without")
    p.add_argument("--player", action="store_true",
                   help="target_player_node (the recorded gait) instead of cpg_node")
    p.add_argument("--domain-id", type=domain_id, default=None, metavar="N",
                   help="DDS domain (default: ROS_DOMAIN_ID if set, else a free one in 1..101)")
    p.add_argument("-p", dest="params", action="append", default=[], metavar="NODE:NAME=VALUE",
                   help="a start-up parameter, e.g. -p sim:real_time_factor=0.5 -p cpg:cpg_file=x.yaml "
                        "(NODE: sim, pid, cpg, player, foxglove; VALUE parsed as YAML); repeatable")
    p.add_argument("--log-dir", default=None, type=out_dir, metavar="DIR",
                   help="where the node logs are written (default: a new temporary directory)")
    p.add_argument("--record", default=None, type=out_dir, metavar="DIR",
                   help="record every topic (+ /tf, /tf_static) to DIR/recording.mcap, a rosbag2 MCAP, "
                        "complete once the graph has stopped (cpg-walker plot reads it)")
    add_foxglove_option(p)
    p.set_defaults(func=_run)


def add_foxglove_option(p: argparse.ArgumentParser) -> None:
    """``--foxglove [HOST:]PORT`` (graph, walk, demo): the live view (foxglove_node)."""
    p.add_argument("--foxglove", nargs="?", const="", default=None, type=_address, metavar="[HOST:]PORT",
                   help="also serve a live view to Foxglove (foxglove_node, a WebSocket server; default "
                        "127.0.0.1:8765, this machine only unless HOST is given; port 0: any free one): the "
                        "robot in 3D, joints, CPG phases and amplitudes, sole loads, zeta/alpha settable")


def _address(text: str) -> str:
    """``--foxglove``'s value, checked ([HOST:]PORT)."""
    from cpg_walker.nodes.foxglove_view import parse_address

    try:
        parse_address(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--foxglove").lstrip(": ")) from None
    return text


def parse_param(text: str) -> tuple[str, str, object]:
    """``cpg:zeta=0.8`` -> ("cpg_node", "zeta", 0.8)."""
    import yaml

    node, sep, rest = text.partition(":")
    name, eq, value = rest.partition("=")
    node = ALIASES.get(node, node)
    if not sep or not eq or not name or node not in ALIASES.values():
        raise InputError(f"-p expects NODE:NAME=VALUE with NODE one of sim, pid, cpg, player, foxglove; got "
                         f"{text!r}")
    try:
        parsed = yaml.safe_load(value)
    except yaml.YAMLError:
        parsed = value
    return node, name.replace(".", "__"), value if parsed is None else parsed


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.graph.runner import GraphSpec, run_foreground

    spec = GraphSpec(pacing=args.pacing, duration=args.duration, zeta=args.zeta, alpha=args.alpha,
                     player=args.player, domain_id=args.domain_id,
                     params=[parse_param(t) for t in args.params], log_dir=args.log_dir,
                     record=args.record, foxglove=args.foxglove)
    status, fall = run_foreground(spec)
    if fall is None:
        return status
    t, xy = fall
    place = "" if xy is None else f", base at x {xy[0]:+.2f} m, y {xy[1]:+.2f} m (world frame)"
    return report_fall("graph", [fall_line("graph", t, place)]) or status
