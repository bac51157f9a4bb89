"""`cpg-walker walk --duration S --zeta Z --alpha A [--feedback off] --out DIR`: the learned CPG walking
the simulated HOAP-2 through the ROS graph (sim_node + pid_node + cpg_node); writes DIR/walk.json."""

from __future__ import annotations

import argparse

from cpg_walker.nodes.runtime import PACINGS
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("walk", help="CPG walk through the ROS graph (three node processes); write walk.json")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--duration", type=float, default=60.0, metavar="S", help="sim seconds (default 60)")
    p.add_argument("--zeta", type=float, default=None, metavar="Z",
                   help="frequency ratio of the oscillators, in [{:g}, {:g}] (default: cpg_node's, "
                        "config/cpg.yaml)".format(*ZETA_RANGE))
    p.add_argument("--alpha", type=float, default=None, metavar="A",
                   help="amplitude (step length) scale, in [{:g}, {:g}] (default: cpg_node's, "
                        "config/cpg.yaml)".format(*ALPHA_RANGE))
    p.add_argument("--feedback", choices=("on", "off"), default="off",
                   help="sensory feedback (eqs 14-20): not in cpg_node yet (in-process: cpg-walk --feedback)")
    p.add_argument("--cpg-file", default=None, metavar="FILE",
                   help="learned CPG YAML (default: cpg_node's cpg_file, config/cpg.yaml; '' = cpg_node "
                        "learns it)")
    p.add_argument("--pacing", choices=PACINGS, default="lockstep",
                   help="the sim node's pacing (default lockstep: deterministic)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.cli.main import UserError

    if args.feedback == "on":
        raise UserError("--feedback on: cpg_node does not close the feedback pathways yet; the in-process "
                        "walk does (cpg-walker cpg-walk --feedback on)")
    from cpg_walker.experiments.walk_graph import run_graph_walk

    report = run_graph_walk(args.out, duration=args.duration, zeta=args.zeta, alpha=args.alpha,
                            cpg_file=args.cpg_file, pacing=args.pacing)
    keys = ("fell", "fall_time_s", "duration_s", "distance_m", "mean_speed_mps", "steps",
            "lateral_drift_m", "heading_change_deg", "zeta", "alpha", "feedback", "real_time_factor")
    print(json.dumps({k: report[k] for k in keys}))
    fall = f"fell at {report['fall_time_s']} s" if report["fell"] else "no fall"
    print(f"walked {report['distance_m']:.3f} m in {report['duration_s']:.1f} s "
          f"({report['mean_speed_mps']:.3f} m/s), {fall}; walk.json in {args.out}")
    return 0
