"""`cpg-walker walk --duration S --zeta Z --alpha A --feedback on|off [--schedule "T,Z,A;T,Z,A"] --out DIR`:
the learned CPG walking the simulated HOAP-2 through the ROS graph (sim_node + pid_node + cpg_node);
writes DIR/walk.json, and with --record DIR/recording.mcap (every topic; `cpg-walker plot` reads it).
The schedule's changes go through cpg_node's SetParameters service at those sim times
(experiments/walk_graph.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import config_or_file, out_dir, positive, within
from cpg_walker.cli.cpg_walk import governed
from cpg_walker.cli.graph import add_foxglove_option
from cpg_walker.cli.outcome import walk_status
from cpg_walker.nodes.interface import PACINGS
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE
from cpg_walker.walker.governor import GovernorConfig


def _cpg_file(text: str) -> str:
    """``--cpg-file``: a readable YAML file, or '' (cpg_node learns it)."""
    return text if text == "" else config_or_file(text)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("walk", help="CPG walk through the ROS graph (three node processes); write walk.json")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--duration", type=positive, default=60.0, metavar="S", help="sim seconds (default 60)")
    p.add_argument("--zeta", type=within(*ZETA_RANGE), default=None, metavar="Z",
                   help="frequency ratio of the oscillators, in [{:g}, {:g}] (default: cpg_node's, "
                        "config/cpg.yaml)".format(*ZETA_RANGE))
    p.add_argument("--alpha", type=within(*ALPHA_RANGE), default=None, metavar="A",
                   help="amplitude (step length) scale, in [0, {:g}] with the governor (the longest step "
                        "that walked), [{:g}, {:g}] without (default: cpg_node's, config/cpg.yaml)".format(
                            GovernorConfig.load().alpha_limit, *ALPHA_RANGE))
    p.add_argument("--governor", choices=("on", "off"), default=None,
                   help="cpg_node's governor (walker/governor.py): on (default, config/cpg.yaml) | off "
                        "(default with --feedback off; the raw controller: values the robot cannot walk "
                        "are commanded as they are)")
    p.add_argument("--feedback", choices=("on", "off"), default=None,
                   help="cpg_node's sensory feedback pathways (default: its 'feedback', config/cpg.yaml); "
                        "off: the paper's open-loop controller, without the governor unless --governor on")
    p.add_argument("--schedule", default=None, metavar="T,Z,A;...",
                   help="(sim s, zeta, alpha) changes, sent through cpg_node's SetParameters service when "
                        "the sim reaches each time (as 'cpg-walker param set /cpg zeta Z' would)")
    p.add_argument("--cpg-file", default=None, type=_cpg_file, metavar="FILE",
                   help="learned CPG YAML (default: cpg_node's cpg_file, config/cpg.yaml; '' = cpg_node "
                        "learns it)")
    p.add_argument("--pacing", choices=PACINGS, default="lockstep",
                   help="the sim node's pacing (default lockstep: deterministic)")
    p.add_argument("--record", action="store_true",
                   help="also record every topic (+ /tf, /tf_static) to DIR/recording.mcap, a rosbag2 MCAP "
                        "(Foxglove, PlotJuggler, ros2 bag play; cpg-walker plot)")
    add_foxglove_option(p)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.experiments.walk_graph import parse_schedule, run_graph_walk

    schedule = parse_schedule(args.schedule) if args.schedule else None  # ValueError: a user error
    feedback = None if args.feedback is None else args.feedback == "on"
    report = run_graph_walk(args.out, duration=args.duration, zeta=args.zeta, alpha=args.alpha,
                            cpg_file=args.cpg_file, feedback=feedback, schedule=schedule, pacing=args.pacing,
                            record=args.record, foxglove=args.foxglove,
                            node_params=None if args.governor is None and args.feedback != "off" else
                            {"cpg_node": {"governor": governed(args.governor, args.feedback)}})
    keys = ("fell", "fall_time_s", "duration_s", "distance_m", "mean_speed_mps", "steps",
            "lateral_drift_m", "heading_change_deg", "zeta", "alpha", "feedback", "real_time_factor")
    print(json.dumps({k: report[k] for k in keys}))
    fall = f"fell at {report['fall_time_s']} s" if report["fell"] else "no fall"
    print(f"walked {report['distance_m']:.3f} m in {report['duration_s']:.1f} s "
          f"({report['mean_speed_mps']:.3f} m/s), {fall}; walk.json in {args.out}"
          + (f"; recording: {report['bag']}" if args.record else ""))
    return walk_status("walk", report)
