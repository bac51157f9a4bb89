"""`cpg-walker demo --out DIR`: the project's main job, end to end (what `make demo` runs).

For now: the paper's Section II experiment (the generic CPG). Later issues replace it with the walking
robot.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job end to end (what `make demo` runs)")
    p.add_argument("--out", default="results", help="output directory (default: results)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from cpg_walker.cli.section2 import run_section2

    return run_section2(Path(args.out) / "section2")
