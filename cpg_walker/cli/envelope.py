"""`cpg-walker envelope --out DIR [--quick] [--duration S] [--jobs N] [--config FILE]`: which (ζ, α) walk,
from standing and changed at run time (issue 24; grid: config/envelope.yaml); DIR/envelope.json,
envelope.md, envelope.png. Falls are data: exit status 0."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import config_or_file, count, out_dir, positive


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("envelope", help="which (zeta, alpha) walk, from standing and changed at 10 s; "
                                        "JSON + MD + PNG map")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--quick", action="store_true", help="a few short cells (config/envelope.yaml's quick:)")
    p.add_argument("--jobs", type=count, default=None, metavar="N",
                   help="parallel walks (default: every core)")
    p.add_argument("--duration", type=positive, default=None, metavar="S",
                   help="sim s walked after each command (default: config/envelope.yaml's duration_after_s)")
    p.add_argument("--config", default=None, type=config_or_file, metavar="FILE",
                   help="an envelope YAML (default config/envelope.yaml)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import shlex
    import sys

    from cpg_walker.experiments.envelope import run_envelope

    argv = sys.argv[1:] if sys.argv[1:2] == ["envelope"] else ["envelope", "--out", str(args.out)]
    command = "cpg-walker " + " ".join(shlex.quote(a) for a in argv)
    r = run_envelope(args.out, args.quick, args.jobs, args.config, args.duration, command=command)
    n = len(r["cells"])
    falls = sum(c["status"] == "falls" for c in r["cells"])
    errors = sum(c["status"] == "error" for c in r["cells"])
    print(f"envelope: {n} cells, {n - falls - errors} walk, {falls} fall, {errors} errors -> {args.out}")
    return 0
