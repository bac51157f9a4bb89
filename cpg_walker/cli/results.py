"""`cpg-walker results [--out docs/results] [--only NAME ...] [--readme README.md]`: regenerate every result
the docs quote (experiments/artifacts.py), each into DIR/<name>/ (the benchmarks into docs/bench), with
progress. ``headline`` - every headline walk of the README (experiments/headline.py, in-process) - runs
here: headline.json and headline.md with the command, commit, date and load, and with --readme the
README's generated results table; the others run their own `cpg-walker` command. Exit status: the worst
of them (1: a walk fell, cli/outcome.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import at_least, in_text_file, out_dir
from cpg_walker.cli.outcome import OK, fall_line, report_fall
from cpg_walker.experiments.artifacts import ARTIFACTS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("results", help="regenerate every result the docs quote (docs/results/)")
    p.add_argument("--out", default="docs/results", type=out_dir,
                   help="the results root (default docs/results): each artifact in its own folder")
    p.add_argument("--only", action="append", default=None, metavar="NAME",
                   choices=[a.name for a in ARTIFACTS],
                   help="regenerate only this artifact (repeatable): " + ", ".join(a.name for a in ARTIFACTS)
                        + "; default: all (about "
                        + f"{sum(a.wall_min for a in ARTIFACTS):.0f} min on 2 cores)")
    p.add_argument("--jobs", type=at_least(1, int), default=None, metavar="N",
                   help="parallel walks of the headline walks (default: every core)")
    p.add_argument("--readme", default=None, type=in_text_file, metavar="FILE",
                   help="also write the generated tables into FILE's blocks (README.md)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import subprocess
    import sys
    import time
    from pathlib import Path

    from cpg_walker.experiments.artifacts import PLACES

    if args.readme is not None:
        _check_readme(args.readme)
    chosen = [a for a in ARTIFACTS if args.only is None or a.name in args.only]
    root, statuses = Path(args.out), []
    for k, art in enumerate(chosen):
        dest = root / PLACES.get(art.name, art.name)
        print(f"[{k + 1}/{len(chosen)}] {art.name}: {art.what} (about {art.wall_min:g} min) -> {dest}",
              file=sys.stderr, flush=True)
        t0 = time.monotonic()
        if not art.argv:
            status = _headline(dest, args)
        else:
            extra = ["--readme", args.readme] if args.readme and art.name == "bench" else []
            argv = [*art.argv, "--out", str(dest), *extra]
            status = subprocess.run([sys.executable, "-m", "cpg_walker.cli.main", *argv]).returncode
        print(f"[{k + 1}/{len(chosen)}] {art.name}: exit status {status} after {time.monotonic() - t0:.0f} s",
              file=sys.stderr, flush=True)
        statuses.append(status)
    return max(statuses, default=OK)


def _check_readme(path: str) -> None:
    from cpg_walker.errors import InputError
    from cpg_walker.experiments.readme_blocks import read_block

    if read_block(open(path, encoding="utf-8").read(), "results-table") is None:
        raise InputError(f"--readme {path}: no '<!-- results-table:begin -->' block to replace")


def _headline(dest, args: argparse.Namespace) -> int:
    """The headline walks into ``dest``; the README's results block from them with --readme."""
    import shlex
    import sys
    import time

    from cpg_walker.experiments.headline import SCENARIOS, markdown, run_all, write
    from cpg_walker.experiments.provenance import provenance
    from cpg_walker.progress import Progress

    command = "cpg-walker " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else \
        "cpg-walker results --only headline"
    doc = {"provenance": provenance(command)}
    t0 = time.monotonic()
    prog = Progress(len(SCENARIOS), "headline", "walks")
    doc["runs"] = run_all(progress=prog.update, jobs=args.jobs)
    prog.close()
    doc["wall_s"] = round(time.monotonic() - t0, 1)
    js, md = write(dest, doc)
    if args.readme:
        from cpg_walker.experiments.readme_blocks import replace_block

        replace_block(args.readme, "results-table", markdown(doc))
    print(md.read_text(), end="")
    print(f"wrote {js} and {md}")
    return report_fall("results", [fall_line("results", r["fall_time_s"], what=r["title"])
                                   for r in doc["runs"] if r.get("fell")])
