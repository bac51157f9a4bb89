"""`cpg-walker worker --storage URL --study NAME [--jobs N] [--name NAME] [--wait S]`: join a many-walk
experiment's Optuna study (a sweep, a feedback search, transitions, random walks started elsewhere with
the same --storage and --study) and run its waiting trials on N local processes (default: every core).

It exits 0 when the study's coordinator has finished and nothing waits. Ctrl-C or SIGTERM stops it: each
trial it was running is enqueued again for another worker; a worker killed outright (SIGKILL, a lost
host) stops beating, and the next worker or coordinator that looks after the grace period
(config/study.yaml) enqueues its trials again. Progress: a line per finished trial on stderr."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, non_negative


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("worker", help="join an experiment's Optuna study (any host) and run its trials",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--storage", required=True, metavar="URL",
                   help="the study's storage, e.g. postgresql://user@host:5432/db")
    p.add_argument("--study", required=True, metavar="NAME", help="the study's name")
    p.add_argument("--jobs", type=count, default=None, metavar="N",
                   help="local worker processes (default: every core)")
    p.add_argument("--name", default=None, metavar="NAME",
                   help="this worker's name in the trials' 'worker' attribute (default HOST:PID)")
    p.add_argument("--wait", type=non_negative, default=0.0, metavar="S",
                   help="wait up to S wall s for the study to be created (default 0: it must exist)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import os
    import sys

    from cpg_walker.experiments.study import run_workers, storage_url

    jobs = args.jobs or os.cpu_count() or 1
    try:
        ran = run_workers(storage_url(args.storage), args.study, jobs, args.name, args.wait)
    except KeyboardInterrupt:
        print("cpg-walker worker: interrupted; its running trials were enqueued again", file=sys.stderr)
        return 130
    print(f"cpg-walker worker: the study {args.study!r} is finished; {ran} trial(s) ran here",
          file=sys.stderr)
    return 0
