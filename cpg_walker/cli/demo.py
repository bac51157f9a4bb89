"""`cpg-walker demo --duration S --out DIR`: the project's main job through the ROS graph (what `make demo`
runs). The learned CPG walks the simulated HOAP-2 through sim_node + pid_node + cpg_node (three
processes), zeta and alpha change mid-run through cpg_node's parameter service (faster, shorter steps,
stopped, forward again, backwards), a one-line status follows the run, and every topic is recorded;
then DIR holds the recording (recording.mcap), its plots (*.png), a video (walk.mp4), walk.json and
summary.json (experiments/demo.py). Ctrl-C stops every node and still writes what was recorded (exit
status 130). --paper adds the in-process Section II experiment and the CPG learning (Fig. 6) first."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import domain_id, out_dir, positive
from cpg_walker.cli.graph import add_foxglove_option
from cpg_walker.cli.outcome import OK, walk_status
from cpg_walker.nodes.interface import PACINGS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job: a walk through the ROS graph with zeta/alpha changes, "
                                    "recorded, plotted and filmed (what `make demo` runs)")
    p.add_argument("--out", default="results", type=out_dir, help="output directory (default: results)")
    p.add_argument("--duration", type=positive, default=60.0, metavar="S",
                   help="sim seconds of the walk (default 60); the zeta/alpha changes are spread over it")
    p.add_argument("--pacing", choices=PACINGS, default="lockstep",
                   help="the sim node's pacing (default lockstep: deterministic, safe on a loaded machine; "
                        "realtime: at wall-clock speed, to watch)")
    p.add_argument("--domain-id", type=domain_id, default=None, metavar="N",
                   help="DDS domain (default: ROS_DOMAIN_ID if set, else a free one in 1..101)")
    p.add_argument("--paper", action="store_true",
                   help="also run the paper's Section II experiment and the CPG learning (Fig. 6) first, "
                        "in-process, into DIR/section2 and DIR/learn")
    add_foxglove_option(p)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import os
    import sys

    os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

    from cpg_walker.experiments.demo import run_demo
    from cpg_walker.graph.runner import resolve_domain

    domain, how = resolve_domain(args.domain_id)
    if args.paper:
        from pathlib import Path

        from cpg_walker.cli.section2 import run_section2
        from cpg_walker.experiments.learn import run_learn

        print("== Section II: the generic CPG learns and replays a periodic signal (in-process)",
              file=sys.stderr)
        run_section2(Path(args.out) / "section2")
        print("== learning the 10-DOF humanoid CPG from the recorded walk (Fig. 6, in-process)",
              file=sys.stderr)
        run_learn(str(Path(args.out) / "learn"))
    print(f"ROS_DOMAIN_ID={domain} ({how})", file=sys.stderr)
    summary = run_demo(args.out, args.duration, pacing=args.pacing, domain_id=domain, foxglove=args.foxglove)
    fall = f"fell at {summary['fall_time_s']} s" if summary["fell"] else "no fall"
    print("segment (from sim s: zeta, alpha -> forward speed over its second half):", file=sys.stderr)
    for seg in summary["segments"]:
        speed = "-" if seg["speed_mps"] is None else f"{seg['speed_mps']:+.3f} m/s"
        print(f"  {seg['from_s']:6.1f} s: zeta {seg['zeta']:+g}, alpha {seg['alpha']:g} -> {speed}  "
              f"{seg['label']}", file=sys.stderr)
    print(f"{summary['duration_s']:.1f} sim s, {summary['distance_m']:+.2f} m along the starting heading, "
          f"heading change {summary['heading_change_deg']:+.0f} deg, {fall}; in {args.out}/: "
          + ", ".join(summary["files"]), file=sys.stderr)
    fell = {**(summary.get("walk") or {}), "fell": summary["fell"], "fall_time_s": summary["fall_time_s"]}
    during = [s for s in summary["segments"] if summary["fell"] and s["from_s"] <= summary["fall_time_s"]]
    status = walk_status("demo", fell, f"during '{during[-1]['label']}'" if during else "")
    return status or (130 if summary["interrupted"] else OK)
