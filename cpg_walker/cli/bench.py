"""`cpg-walker bench --out DIR`: run the benchmarks and write DIR/bench.json and DIR/bench.md."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run the benchmarks; write bench.json and bench.md")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--only", action="append", default=None, metavar="SECTION",
        help="run only this section (repeatable); default: all",
    )
    p.add_argument("--quick", action="store_true", help="fewer repetitions (for smoke tests)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.bench import run_benchmarks

    run_benchmarks(args.out, only=args.only, quick=args.quick)
    return 0
