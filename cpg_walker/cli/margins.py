"""`cpg-walker margins --out DIR [--quick] [--duration S]`: how far the robot's settings can move before a
recorded gait stops walking (PID gains, floor friction, control delay, armature; both gaits)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import out_dir, positive


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("margins", help="sweep gains/friction/delay/armature; write margins.json and .png")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--quick", action="store_true", help="a few points only (kp and delay)")
    p.add_argument("--duration", type=positive, default=30.0, metavar="S", help="sim seconds per replay (30)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.experiments.replay_margins import QUICK, SWEEPS, run_margins
    from cpg_walker.progress import Progress

    sweeps = QUICK if args.quick else SWEEPS
    progress = Progress(2 * sum(len(v) for v in sweeps.values()), "margins", unit="replays")
    report = run_margins(args.out, quick=args.quick, duration=args.duration, progress=progress)
    progress.close()
    print(json.dumps({k: v["both_walk"] for k, v in report["ranges"].items()}))
    return 0
