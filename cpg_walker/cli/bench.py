"""`cpg-walker bench --out DIR`: run the benchmarks; write DIR/bench.json, bench.md, bench_table.md and the
scaling plots (and, with --doc, the summary tables into their generated block: docs/benchmarks.md, where
readme_blocks.BLOCKS puts it, or the FILE given)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cpg_walker.cli.checks import in_text_file, out_dir
from cpg_walker.errors import InputError
from cpg_walker.experiments.bench_sections import SECTIONS
from cpg_walker.experiments.readme_blocks import BLOCKS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run the benchmarks; write bench.json, bench.md, tables, plots")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument(
        "--only", action="append", default=None, metavar="SECTION", choices=list(SECTIONS),
        help="run only this section (repeatable); default: all",
    )
    p.add_argument("--quick", action="store_true", help="fewer repetitions (for smoke tests)")
    p.add_argument("--doc", "--readme", dest="doc", nargs="?", const=BLOCKS["bench-table"], default=None,
                   type=in_text_file, metavar="FILE",
                   help="also write the summary tables into FILE's generated benchmark block (without FILE: "
                        f"{BLOCKS['bench-table']}; --readme is the former name)")
    p.add_argument("--from-json", default=None, type=in_text_file, metavar="BENCH_JSON",
                   help="run nothing: regenerate the tables and plots (and --doc) from this bench.json")
    p.set_defaults(func=_run)


def read_results(path: str) -> dict:
    """bench.json's results: a JSON object with a ``machine`` object and at least one section object;
    InputError naming the file (and the line of a JSON syntax error) otherwise."""
    import json
    from pathlib import Path

    try:
        results = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON: {exc.msg}") from None
    if not isinstance(results, dict):
        raise InputError(f"{path}: expected a JSON object (bench.json), got a {type(results).__name__}")
    if not isinstance(results.get("machine"), dict):
        raise InputError(f"{path}: no 'machine' object: not a bench.json")
    bad = [name for name in SECTIONS if name in results and not isinstance(results[name], dict)]
    if bad:
        raise InputError(f"{path}: section(s) {bad} must be JSON objects")
    if not any(name in results for name in SECTIONS):
        raise InputError(f"{path}: no benchmark section (expected one or more of {', '.join(SECTIONS)})")
    return results


def _check_doc(path: str) -> None:
    """--doc must be a text file holding the generated block's markers (replaced at the end of the run)."""
    import argparse

    from cpg_walker.cli.checks import in_text_file
    from cpg_walker.experiments.readme_blocks import read_block

    try:
        in_text_file(path)  # argparse does not check --doc's default FILE (nargs='?')
    except argparse.ArgumentTypeError as exc:
        raise InputError(f"--doc {exc}") from None
    if read_block(Path(path).read_text(encoding="utf-8"), "bench-table") is None:
        raise InputError(f"--doc {path}: no '<!-- bench-table:begin -->' ... '<!-- bench-table:end -->' "
                         "block to replace")


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.experiments.bench import headline_status

    if args.doc is not None:
        _check_doc(args.doc)
    if args.from_json:  # exit 1 if a headline run in it is invalid (the tables written first)
        from pathlib import Path

        from cpg_walker.experiments.bench_report import write

        results = read_results(args.from_json)  # write() checks the shape again (ValueError): a bug then
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        write(results, out, args.doc)
        return headline_status(results)
    from cpg_walker.experiments.bench import run_benchmarks

    return headline_status(run_benchmarks(args.out, only=args.only, quick=args.quick, readme=args.doc))
