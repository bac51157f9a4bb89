"""`cpg-walker bench --out DIR`: run the benchmarks; write DIR/bench.json, bench.md, bench_table.md and the
scaling plots (and, with --readme, the summary tables into the README)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run the benchmarks; write bench.json, bench.md, tables, plots")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--only", action="append", default=None, metavar="SECTION",
        help="run only this section (repeatable); default: all",
    )
    p.add_argument("--quick", action="store_true", help="fewer repetitions (for smoke tests)")
    p.add_argument("--readme", default=None, metavar="FILE",
                   help="also write the summary tables into FILE's generated benchmark block (README.md)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.bench import run_benchmarks

    run_benchmarks(args.out, only=args.only, quick=args.quick, readme=args.readme)
    return 0
