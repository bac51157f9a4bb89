"""`cpg-walker results [--out docs/results] [--only NAME ...] [--docs [ROOT]]`: regenerate every result the
docs quote (experiments/artifacts.py), each into DIR/<name>/ (the benchmarks into docs/bench), with
progress. ``headline`` - every headline walk of the README (experiments/headline.py, in-process) - runs
here: headline.json and headline.md with the command, commit, date and load; the others run their own
`cpg-walker` command. With --docs the generated tables are rewritten too, each in the doc under ROOT (the
checkout, default .) that readme_blocks.BLOCKS names: the results table in README.md, the benchmark's in
docs/benchmarks.md. Exit status: the worst of them (1: a walk fell, cli/outcome.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import at_least, out_dir
from cpg_walker.cli.outcome import OK, fall_line, report_fall
from cpg_walker.experiments.artifacts import ARTIFACTS
from cpg_walker.experiments.readme_blocks import BLOCKS, block_file


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
    p.add_argument("--docs", nargs="?", const=".", default=None, metavar="ROOT",
                   help="also rewrite the generated tables, each in its doc under ROOT (default: the current "
                        "directory, a checkout): " + ", ".join(f"{k} in {v}" for k, v in BLOCKS.items()))
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import subprocess
    import sys
    import time
    from pathlib import Path

    from cpg_walker.experiments.artifacts import PLACES

    chosen = [a for a in ARTIFACTS if args.only is None or a.name in args.only]
    if args.docs is not None:
        _check_docs(args.docs, chosen)
    root, statuses = Path(args.out), []
    for k, art in enumerate(chosen):
        dest = root / PLACES.get(art.name, art.name)
        print(f"[{k + 1}/{len(chosen)}] {art.name}: {art.what} (about {art.wall_min:g} min) -> {dest}",
              file=sys.stderr, flush=True)
        t0 = time.monotonic()
        if not art.argv:
            status = _headline(dest, args)
        else:
            extra = ["--doc", str(block_file(_BLOCK_OF[art.name], args.docs))] \
                if args.docs is not None and art.name in _BLOCK_OF else []
            argv = [*art.argv, "--out", str(dest), *extra]
            status = subprocess.run([sys.executable, "-m", "cpg_walker.cli.main", *argv]).returncode
        print(f"[{k + 1}/{len(chosen)}] {art.name}: exit status {status} after {time.monotonic() - t0:.0f} s",
              file=sys.stderr, flush=True)
        statuses.append(status)
    return max(statuses, default=OK)


#: The generated block each artifact writes with --docs (where it lives: readme_blocks.BLOCKS).
_BLOCK_OF = {"headline": "results-table", "bench": "bench-table"}


def _check_docs(root: str, chosen) -> None:
    """Before any run: every block the chosen artifacts will write is in its file under ``root``."""
    from cpg_walker.errors import InputError
    from cpg_walker.experiments.readme_blocks import read_block

    for art in chosen:
        if art.name not in _BLOCK_OF:
            continue
        name = _BLOCK_OF[art.name]
        path = block_file(name, root)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"--docs {root}: cannot read {path} ({exc.__class__.__name__}), which holds the "
                             f"'{name}' block") from None
        if read_block(text, name) is None:
            raise InputError(f"--docs {root}: {path} has no '<!-- {name}:begin -->' block to replace")


def _headline(dest, args: argparse.Namespace) -> int:
    """The headline walks into ``dest``; the README's results block from them with --docs."""
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
    if args.docs is not None:
        from cpg_walker.experiments.readme_blocks import replace_block

        replace_block(block_file(_BLOCK_OF["headline"], args.docs), _BLOCK_OF["headline"], markdown(doc))
    print(md.read_text(), end="")
    print(f"wrote {js} and {md}")
    return report_fall("results", [fall_line("results", r["fall_time_s"], what=r["title"])
                                   for r in doc["runs"] if r.get("fell")])
