"""`cpg-walker plot BAG --out DIR`: PNGs of a recording (`walk --record`, `graph --record`, `record`):
targets vs joint states, torso tilt, sole loads with touchdowns, speed/zeta/alpha/heading, CPG phases
(experiments/plot_bag.py); DIR/plot.json lists them."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import in_path, out_dir


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="plot a recording (DIR/recording.mcap) to PNGs")
    p.add_argument("bag", metavar="BAG", type=in_path, help="the recording: its directory or its .mcap file")
    p.add_argument("--out", required=True, type=out_dir, metavar="DIR", help="where the PNGs go")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.plot_bag import plot_bag

    summary = plot_bag(args.bag, args.out)
    print(f"{len(summary['files'])} plots in {args.out}: {', '.join(summary['files'])}")
    for name, why in summary["not_plotted"].items():
        print(f"not plotted: {name}: {why}")
    return 0
