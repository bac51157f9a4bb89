"""`cpg-walker replay --out DIR [--gait walk|slow] [--data FILE] [--duration S]`: replay a recorded gait
on the simulated HOAP-2 in-process (PID torque law, no ROS); write DIR/replay.json and a filmstrip."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import in_text_file, out_dir, positive
from cpg_walker.cli.outcome import walk_status


def _data(text: str) -> str:
    """``--data``: a packaged gait's name or a readable CSV."""
    from cpg_walker.robot.gait_data import PACKAGED

    return text if text in PACKAGED else in_text_file(text)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="replay a recorded gait on the simulated HOAP-2; write replay.json")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--gait", choices=("walk", "slow"), default="walk",
                   help="packaged recording (default walk)")
    p.add_argument("--data", default=None, type=_data, metavar="FILE",
                   help="a CSV in the packaged layout instead of --gait")
    p.add_argument("--duration", type=positive, default=None, metavar="S",
                   help="sim seconds (default: the recording, then its steady cycle repeated, to 30 s)")
    p.add_argument("--no-render", action="store_true", help="skip the filmstrip and GIF")
    p.add_argument("--graph", action="store_true",
                   help="run through the ROS graph instead (sim_node + pid_node + target_player_node "
                        "processes; no filmstrip); replay.json adds real_time_factor")
    p.add_argument("--pacing", choices=("lockstep", "realtime", "fast"), default="lockstep",
                   help="with --graph: the sim node's pacing (default lockstep)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    import os

    if args.graph:
        from cpg_walker.experiments.replay_graph import run_graph_replay

        report = run_graph_replay(args.out, gait=args.gait, data=args.data, duration=args.duration,
                                  pacing=args.pacing)
        keys = ("fell", "fall_time_s", "duration_s", "distance_m", "mean_speed_mps", "steps",
                "lateral_drift_m", "heading_change_deg", "real_time_factor")
        print(json.dumps({k: report[k] for k in keys}))
        return walk_status("replay", report, "through the graph")
    if not args.no_render:
        os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

    from cpg_walker.experiments.replay import replay_recording

    report = replay_recording(args.out, gait=args.gait, data=args.data, duration=args.duration,
                              render=not args.no_render)
    keys = ("fell", "fall_time_s", "duration_s", "distance_m", "mean_speed_mps", "steps", "lateral_drift_m",
            "heading_change_deg")
    print(json.dumps({k: report[k] for k in keys}))
    return walk_status("replay", report)
