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
    p.add_argument("--from-json", default=None, metavar="BENCH_JSON",
                   help="run nothing: regenerate the tables and plots (and --readme) from this bench.json")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.bench import headline_status

    if args.from_json:  # exit 1 if a headline run in it is invalid (the tables written first)
        import json
        from pathlib import Path

        from cpg_walker.cli.main import UserError
        from cpg_walker.experiments.bench_report import check_shape, write

        try:
            results = json.loads(Path(args.from_json).read_text())
            check_shape(results)
        except json.JSONDecodeError as exc:
            raise UserError(f"--from-json {args.from_json}: not JSON ({exc})") from None
        except (OSError, ValueError) as exc:  # missing or unreadable file, not bench.json's shape
            raise UserError(f"--from-json {args.from_json}: {exc}") from None
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        write(results, out, args.readme)
        return headline_status(results)
    from cpg_walker.experiments.bench import run_benchmarks

    return headline_status(run_benchmarks(args.out, only=args.only, quick=args.quick, readme=args.readme))
