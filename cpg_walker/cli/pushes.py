"""`cpg-walker pushes --out DIR [--feedback ours|paper|off] [--jobs N]`: the largest lateral pushes
recovered standing and walking, both ways (experiments/pushes.py); DIR/pushes.json, pushes.md. Falls are
data: exit status 0."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, out_dir


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("pushes", help="largest lateral pushes recovered standing and walking; JSON + MD")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--feedback", choices=("ours", "paper", "off"), default="ours",
                   help="feedback variant (default ours: cpg_node's)")
    p.add_argument("--jobs", type=count, default=None, metavar="N",
                   help="parallel walks (default: every core)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import sys

    from cpg_walker.experiments.pushes import run_pushes

    r = run_pushes(args.out, args.feedback, args.jobs, command=" ".join(["cpg-walker", *sys.argv[1:]]))
    for run in r["runs"]:
        side = "left" if run["direction"] > 0 else "right"
        print(f"{run['case']} pushed {side}: recovers {run['max_recovered_impulse_Ns']:.2f} N s, falls at "
              f"{run['first_fall_impulse_Ns']:.2f}")
    return 0
