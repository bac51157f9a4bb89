"""`cpg-walker random-walks --seeds A-B --out DIR [--duration S] [--feedback ours|paper|off] [--pathways P,P]
[--jobs N]`:
seeded random (ζ, α) command sequences inside the declared ranges, a new command every 8-16 sim s,
walked in-process through the governor (experiments/random_commands.py); DIR/random_walks.json. Exits 1
when a walk fell, with the seeds that fell on the last line."""

from __future__ import annotations

import argparse
import sys

from cpg_walker.cli.checks import out_dir, positive
from cpg_walker.cli.study_args import add_study_args, check_study_args


def seed_range(text: str) -> list[int]:
    """``A-B`` (inclusive) or ``A,B,C``: the seeds, each a non-negative integer."""
    try:
        if "-" in text:
            a, b = (int(x) for x in text.split("-", 1))
            seeds = list(range(a, b + 1))
        else:
            seeds = [int(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A-B or A,B,C (integers), got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"expected at least one seed >= 0, got {text!r}")
    return seeds


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("random-walks", help="seeded random zeta/alpha sequences walked in-process; exit 1 "
                                            "on a fall")
    p.add_argument("--seeds", type=seed_range, default=seed_range("0-9"), metavar="A-B",
                   help="the sequences' seeds: A-B (inclusive) or A,B,C (default 0-9)")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--duration", type=positive, default=120.0, metavar="S",
                   help="sim s per walk (default 120)")
    p.add_argument("--feedback", choices=("ours", "paper", "off"), default="ours",
                   help="feedback variant (default ours: cpg_node's)")
    p.add_argument("--pathways", default=None, metavar="P,P,...",
                   help="these feedback pathways instead of --feedback's (e.g. amplitude,reset_both,heading: "
                        "the default ones without the ankle strategy)")
    add_study_args(p, "random-walks")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.random_commands import run_random_walks

    check_study_args(args)
    pathways = None
    if args.pathways is not None:
        from cpg_walker.walker.feedback import check_pathways

        pathways = check_pathways(tuple(p.strip() for p in args.pathways.split(",") if p.strip()))
    r = run_random_walks(args.seeds, args.out, args.duration, args.feedback, args.jobs,
                         command=" ".join(["cpg-walker", *sys.argv[1:]]), pathways=pathways,
                         storage=args.storage, study=args.study, resume=args.resume)
    fell = [run for run in r["runs"] if run["fell"]]
    print(f"{len(r['runs'])} random walks of {args.duration:g} s: {len(fell)} fell", file=sys.stderr)
    if fell:
        where = ", ".join(f"{run['label']} at {run['fall_time_s']} s" for run in fell)
        print(f"cpg-walker random-walks: FELL: {where}", file=sys.stderr)
        return 1
    return 0
