"""`cpg-walker cmd-vel-map --out DIR` (measure config/speed_map.yaml's data) and `cpg-walker drive-check
--out DIR [--quick]` (commanded vs actual speed and turn rate of /cmd_vel driving, in-process;
experiments/cmd_vel.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import config_or_file, count, domain_id, out_dir, positive
from cpg_walker.cli.outcome import fall_line, report_fall


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cmd-vel-map", help="measure /cmd_vel's speed vs zeta/alpha map (in-process)")
    p.add_argument("--out", required=True, type=out_dir,
                   help="output directory (speed_map.yaml, speed_map.json)")
    p.add_argument("--jobs", type=count, default=2, metavar="N", help="parallel walks (default 2)")
    p.add_argument("--window", type=positive, default=30.0, metavar="S",
                   help="sim s walked after the command")
    p.set_defaults(func=_map)
    d = sub.add_parser("drive-check", help="/cmd_vel commanded vs actual speed and turn rate: table + plot")
    d.add_argument("--out", required=True, type=out_dir,
                   help="output directory (drive_check.json, .md, .png)")
    d.add_argument("--jobs", type=count, default=2, metavar="N", help="parallel walks (default 2)")
    d.add_argument("--quick", action="store_true", help="forward, backward, left, right only")
    d.add_argument("--speed-map", default=None, type=config_or_file, metavar="FILE",
                   help="speed map (default: config/cpg.yaml's)")
    d.add_argument("--graph", action="store_true",
                   help="drive a graph started like `cpg-walker graph` (lockstep) by /cmd_vel instead, "
                        "measured from /odom/ground_truth: DIR/drive_graph.json, .md")
    d.add_argument("--attach", action="store_true",
                   help="with --graph: drive the graph already running on --domain-id (or ROS_DOMAIN_ID)")
    d.add_argument("--domain-id", type=domain_id, default=None, metavar="N",
                   help="with --graph: the DDS domain")
    d.add_argument("--plan", choices=("drive", "steer"), default="drive",
                   help="with --graph: drive (forward, left, right) or steer (turn in place 0.5 rad/s 10 s, "
                        "side-step 0.05 m/s 20 s, forward 0.15 m/s 20 s)")
    d.add_argument("--pacing", choices=("lockstep", "realtime"), default="lockstep",
                   help="with --graph (not --attach): the started graph's pacing")
    d.add_argument("-p", dest="params", action="append", default=[], metavar="NODE:NAME=VALUE",
                   help="with --graph (not --attach): a start-up parameter of the started graph, as "
                        "`cpg-walker graph -p`; repeatable")
    d.set_defaults(func=_drive)


def _map(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.cmd_vel import map_specs, measure_speed_map
    from cpg_walker.progress import Progress

    prog = Progress(len(map_specs(args.window)), "cmd-vel-map", "walks")
    doc = measure_speed_map(args.out, args.jobs, args.window, prog)
    prog.close()
    print(f"wrote {args.out}/speed_map.yaml ({len(doc['fell'])} walks fell)")
    return 0


def _drive(args: argparse.Namespace) -> int:
    if args.graph and args.attach and args.domain_id is None:
        from cpg_walker.graph.processes import env_domain_id

        env_domain_id()  # InputError when ROS_DOMAIN_ID is not a domain
    if args.graph:
        from cpg_walker.cli.graph import parse_param
        from cpg_walker.experiments.cmd_vel_graph import drive_graph

        for text in args.params:
            parse_param(text)  # InputError naming the bad one, before anything starts
        res = drive_graph(args.out, args.domain_id, args.attach, plan=args.plan, pacing=args.pacing,
                          params=args.params)
        print(open(f"{args.out}/drive_graph.md", encoding="utf-8").read())
        return report_fall("drive-check", [fall_line("drive-check", res.get("fell_at_s"),
                                                     what="driven through the graph")] if res["fell"] else [])
    from cpg_walker.experiments.cmd_vel import drive_set
    from cpg_walker.experiments.drive_protocol import drive_check
    from cpg_walker.walker.cmd_vel import SpeedMap

    if args.speed_map is not None:
        SpeedMap.load(args.speed_map)  # InputError naming the file, before the drives
    from cpg_walker.experiments.drive_protocol import protocol_drives
    from cpg_walker.progress import Progress

    prog = Progress(len(drive_set(args.quick)) + (0 if args.quick else len(protocol_drives())), "drive-check",
                    "drives")
    res = drive_check(args.out, args.jobs, args.quick, args.speed_map, prog)
    prog.close()
    print(open(f"{args.out}/drive_check.md", encoding="utf-8").read())
    return report_fall("drive-check", [
        fall_line("drive-check", r["fall_time_s"], what=f"drive '{r['label']}'")
        for r in res["runs"] if r.get("fell")])
