"""`cpg-walker soak --out DIR`: the graph walks minutes of sim time (realtime pacing) with a zeta/alpha
or /cmd_vel change every 20 s; fell or not, each node's memory, late commands and overruns over time;
DIR/soak.json and DIR/soak.md (experiments/soak.py). The last result is committed as
docs/results/soak/soak.json."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import out_dir, positive
from cpg_walker.cli.outcome import OK, fall_line, report_fall


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("soak", help="walk the graph for minutes with changes every 20 s; memory, overruns")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--minutes", type=positive, default=10.0, help="sim minutes to walk (default 10)")
    p.add_argument("--period", type=positive, default=20.0, metavar="S",
                   help="sim s between changes (default 20)")
    p.add_argument("--pacing", choices=("realtime", "lockstep"), default="realtime",
                   help="the sim's pacing (default realtime; lockstep: the same run whatever the load)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    from cpg_walker.experiments.soak import markdown, run_soak

    report = run_soak(args.out, minutes=args.minutes, period=args.period, pacing=args.pacing,
                      say=lambda text: print(f"soak: {text}", file=sys.stderr, flush=True))
    table = markdown(report)
    (Path(args.out) / "soak.md").write_text(table)
    print(table, end="")
    if not report["fell"]:
        return OK
    last = report["windows"][-1] if report.get("windows") else None
    what = f"window {last['window'] + 1}: {last['change']}" if last else ""
    return report_fall("soak", [fall_line("soak", report["fell_at_s"], what=what)])
