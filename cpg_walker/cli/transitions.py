"""`cpg-walker transitions --out DIR [--phases N] [--jobs N]`: the transition map alone (what `cpg-walker
sweep` also writes): every ordered pair of config/sweep.yaml's ``transitions.states`` changed at N stride
phases through the governor, in-process (experiments/transitions.py); DIR/transitions.json and
transitions.png. Falls are data: exit status 0."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, out_dir
from cpg_walker.cli.study_args import add_study_args, check_study_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("transitions", help="which changes between walking states survive at every stride "
                                           "phase; JSON + PNG")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--phases", type=count, default=None, metavar="N",
                   help="stride phases per change (default: config/sweep.yaml's transitions.phases)")
    add_study_args(p, "transitions")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import sys

    from cpg_walker.experiments.sweep import load_config
    from cpg_walker.experiments.transitions import from_config, run_transitions

    check_study_args(args)
    states, phases, times = from_config(load_config()["transitions"])
    r = run_transitions(args.out, states, args.phases or phases, args.jobs, times,
                        command=" ".join(["cpg-walker", *sys.argv[1:]]), storage=args.storage,
                        study=args.study, resume=args.resume)
    for run in r["runs"]:
        if run["fell"]:
            print(f"fell: {run['from']} -> {run['to']} at phase {run['phase']} ({run['at_s']} s): "
                  f"at {run['fall_time_s']} s", file=sys.stderr)
    print(f"{len(r['runs'])} transitions: {r['falls']} fell; {args.out}/transitions.png", file=sys.stderr)
    return 0
