"""`cpg-walker results --out DIR`: regenerate the README's locomotion results - every headline walk
(experiments/headline.py: zeta 1 for 60 s, zeta 1.5 and -1.2 from standing and at run time, a reversal,
alpha 0 -> 1, the demo's schedule; in-process, feedback on) into DIR/headline.json and headline.md with
the command, commit, date and load; with --readme FILE also the README's generated results table. Exit 1
when a headline walk fell (cli/outcome.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import at_least, in_text_file, out_dir
from cpg_walker.cli.outcome import fall_line, report_fall


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("results", help="regenerate the README's locomotion results (headline.json/.md)")
    p.add_argument("--out", default="docs/results", type=out_dir,
                   help="output directory (default docs/results)")
    p.add_argument("--jobs", type=at_least(1, int), default=None, metavar="N",
                   help="parallel walks (default: every core)")
    p.add_argument("--readme", default=None, type=in_text_file, metavar="FILE",
                   help="also write the table into FILE's generated results block (README.md)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import shlex
    import sys
    import time

    from cpg_walker.experiments.headline import SCENARIOS, run_all, write
    from cpg_walker.experiments.provenance import provenance
    from cpg_walker.progress import Progress

    if args.readme is not None:
        from cpg_walker.errors import InputError
        from cpg_walker.experiments.readme_blocks import read_block

        if read_block(open(args.readme, encoding="utf-8").read(), "results-table") is None:
            raise InputError(f"--readme {args.readme}: no '<!-- results-table:begin -->' block to replace")
    command = "cpg-walker " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else \
        "cpg-walker results"
    doc = {"provenance": provenance(command)}
    t0 = time.monotonic()
    prog = Progress(len(SCENARIOS), "results", "walks")
    doc["runs"] = run_all(progress=prog.update, jobs=args.jobs)
    prog.close()
    doc["wall_s"] = round(time.monotonic() - t0, 1)
    js, md = write(args.out, doc)
    if args.readme:
        from cpg_walker.experiments.headline import markdown
        from cpg_walker.experiments.readme_blocks import replace_block

        replace_block(args.readme, "results-table", markdown(doc))
    print(md.read_text(), end="")
    print(f"wrote {js} and {md}")
    return report_fall("results", [fall_line("results", r["fall_time_s"], what=r["title"])
                                   for r in doc["runs"] if r.get("fell")])
