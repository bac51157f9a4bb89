"""`cpg-walker fit --csv FILE [--column NAME] [--time-column NAME] [--oscillators N] --out DIR`: learn a
recorded signal."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, in_text_file, out_dir


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="learn a periodic signal from a CSV into a CPG; write fit.json and a PNG")
    p.add_argument("--csv", required=True, type=in_text_file,
                   help="CSV with a header: a time column (s) and signal columns, any sampling rate")
    p.add_argument("--time-column", default=None, metavar="NAME",
                   help="time column (default: one named time, t, time_s, timestamp, ...; else the first)")
    p.add_argument("--column", default=None, help="signal column to learn (default: every column)")
    p.add_argument("--oscillators", type=count, default=None,
                   help="oscillators per CPG (default: number of significant spectral components)")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from cpg_walker.experiments.fit import run_fit

    return run_fit(Path(args.csv), args.column, args.oscillators, Path(args.out), args.time_column)
