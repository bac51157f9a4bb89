"""`cpg-walker feedback-search --out DIR [--generations G] [--popsize P] [--seed S] [--jobs N] [--resume]
[--quick] [--holdout]`: CMA-ES over the feedback gains named in config/feedback_search.yaml.

Objective (minimised, summed over the searched scenarios — several ζ, change times, from standing — so
robustness is part of it): survive first (a fall costs a large penalty minus the seconds survived after
the command), then speed close to ζ·α × the open-loop ζ = 1 speed, straight (heading change and lateral
drift per minute), low torque (mean |τ| of the CPG joints). Weights: the YAML's ``objective``; the formula:
experiments/feedback_search.py. Writes DIR/trials.jsonl (every candidate: parameters, per-scenario
metrics, objective), DIR/best.yaml (a config/feedback.yaml fragment), DIR/state.pkl (the CMA-ES state).
Every candidate is a trial of an Optuna study (default DIR/study.db; --storage URL --study NAME for a
shared one that `cpg-walker worker`s on other hosts join; --resume continues it).
``--holdout`` judges DIR/best.yaml (against the defaults and the open loop) on the searched and the
held-out scenarios (other ζ and change times, friction ±30 %, a push): DIR/holdout.json, holdout.md."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import at_least, count, in_text_file, out_dir, within
from cpg_walker.cli.study_args import add_study_args, check_study_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("feedback-search", help="CMA-ES search of the feedback gains; trials.jsonl, best.yaml",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=out_dir, help="output directory (holds the resumable state)")
    p.add_argument("--generations", type=count, default=None, metavar="G", help="total generations (YAML's)")
    p.add_argument("--popsize", type=at_least(2, int), default=None, metavar="P",
                   help="candidates per generation")
    p.add_argument("--seed", type=within(0, 2**32 - 1, int), default=1, metavar="S",
                   help="CMA-ES seed (default 1)")
    p.add_argument("--resume", action="store_true", help="continue the search saved in its study")
    p.add_argument("--quick", action="store_true", help="short scenarios (the YAML's quick: section)")
    p.add_argument("--config", default=None, type=in_text_file, metavar="FILE",
                   help="default config/feedback_search.yaml")
    p.add_argument("--holdout", action="store_true",
                   help="after the search (or alone, with DIR/best.yaml from an earlier one) judge the best "
                        "on held-out conditions")
    p.add_argument("--no-search", action="store_true", help="with --holdout: skip the search")
    add_study_args(p, "feedback-search", resume=False)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    import sys

    from cpg_walker.experiments.feedback_search import holdout, search

    check_study_args(args)
    if not args.no_search:
        best = search(args.out, args.generations, args.popsize, args.seed, args.jobs, args.resume, args.quick,
                      args.config, log=lambda s: print(s, file=sys.stderr), storage=args.storage,
                      study=args.study)
        print(json.dumps({"objective": best["objective"], "params": best["params"]}))
    if args.holdout:
        r = holdout(args.out, args.jobs, args.quick, args.config, storage=args.storage, study=args.study)
        print(json.dumps({f"objective_{n}": r[f"objective_{n}"] for n in ("off", "default", "best")}))
    return 0
