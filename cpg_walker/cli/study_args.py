"""The options every many-walk experiment shares (sweep, feedback-search, transitions, random-walks): where
its Optuna study lives and how many local workers run it (experiments/study.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import at_least
from cpg_walker.errors import InputError

STORAGE_HELP = ("the study's Optuna storage: a database URL such as postgresql://user@host:5432/db, shared "
                "with `cpg-walker worker`s on other hosts (default: DIR/study.db, a SQLite file)")


def add_study_args(p: argparse.ArgumentParser, default_study: str, resume: bool = True) -> None:
    """--storage, --study, --jobs (0 allowed with --storage: only remote workers) and, if ``resume``,
    --resume."""
    p.add_argument("--storage", default=None, metavar="URL", help=STORAGE_HELP)
    p.add_argument("--study", default=None, metavar="NAME",
                   help=f"the study's name in the storage (default {default_study})")
    p.add_argument("--jobs", type=at_least(0, int), default=None, metavar="N",
                   help="local worker processes (default: every core; 0, with --storage: only "
                        "`cpg-walker worker`s elsewhere)")
    if resume:
        p.add_argument("--resume", action="store_true",
                       help="continue the study: tasks already done are read back, not walked again")


def check_study_args(args: argparse.Namespace) -> None:
    """InputError for --jobs 0 without --storage (nobody could run the default file's study) and for a
    study name that is empty."""
    if args.jobs == 0 and args.storage is None:
        raise InputError("--jobs 0 needs --storage: with the default study file no other worker can join")
    if args.study is not None and not args.study.strip():
        raise InputError("--study: expected a name, got an empty one")
