"""`cpg-walker scaleout --out DIR [--full] [--jobs N] [--generations G] [--seed S] [--no-screenshot]`: the
experiments' engine across "hosts" on this machine (root; network namespaces and PostgreSQL 15 needed):
a throwaway PostgreSQL server, two namespaces joined to it by veth pairs with one `cpg-walker worker` in
each, the sweep with one worker and with two (trials per hour), the feedback search with two, one of them
killed mid-trial (its trial retried), every result table compared with a one-machine run of the same
seeds, and optuna-dashboard's page of the search screenshot by headless Chromium
(experiments/scaleout.py). DIR/scaleout.json, scaleout.md, dashboard.png, the runs' directories and the
workers' logs. Exit 1 when a table differs from the one-machine run's or a killed trial was not retried."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, out_dir, within


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scaleout", help="sweep and feedback search through PostgreSQL with workers in two "
                                        "network namespaces; trials/hour, a killed worker, the dashboard",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--full", action="store_true",
                   help="the whole sweep and search (default: their --quick versions)")
    p.add_argument("--jobs", type=count, default=2, metavar="N",
                   help="local processes of the one-machine reference runs (default 2)")
    p.add_argument("--generations", type=count, default=None, metavar="G",
                   help="the search's generations (default: config/feedback_search.yaml's)")
    p.add_argument("--seed", type=within(0, 2**32 - 1, int), default=1, metavar="S", help="the search's seed")
    p.add_argument("--no-screenshot", action="store_true", help="skip the dashboard screenshot")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    import sys

    from cpg_walker.experiments.scaleout import run_scaleout

    r = run_scaleout(args.out, quick=not args.full, jobs=args.jobs, generations=args.generations,
                     seed=args.seed, screenshot=not args.no_screenshot,
                     log=lambda s: print(s, file=sys.stderr))
    print(json.dumps(r["throughput"]))
    bad = [f"{name}: {k}" for name, run in r["runs"].items() for k, same in run["same_as_one_machine"].items()
           if not same]
    killed = r["runs"]["search-2-workers"]
    lost = [f for f in killed["failed"] if not any(a["state"] == "COMPLETE" for a in f["retried_as"])]
    if killed.get("killed") is None:
        bad.append("worker B was not killed mid-trial (it never ran a second trial)")
    for f in lost:
        bad.append(f"trial {f['trial']} failed and was not completed by a retry")
    for line in bad:
        print(f"cpg-walker scaleout: {line}", file=sys.stderr)
    return 1 if bad else 0
