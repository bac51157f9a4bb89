"""`cpg-walker urdf --out FILE`: write the HOAP-2's URDF, generated from the MJCF (cpg_walker.robot.urdf).
The package ships it as cpg_walker/robot/hoap2.urdf; test/test_urdf.py fails when that file is stale."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cpg_walker.cli.checks import in_text_file, out_file


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("urdf", help="write the HOAP-2 URDF generated from the MuJoCo model",
                       description="Generate the URDF from the MJCF (the one source of truth).")
    p.add_argument("--out", default="-", type=out_file, metavar="FILE",
                   help="where to write it ('-' = standard output, the default); the shipped file is "
                        "cpg_walker/robot/hoap2.urdf")
    p.add_argument("--model", default=None, type=in_text_file, metavar="MJCF",
                   help="another MJCF (default: the package's hoap2.xml)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.robot.urdf import generate

    text = generate(args.model) if args.model else generate()
    if args.out == "-":
        sys.stdout.write(text)
    else:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
        print(f"wrote {out} ({text.count('<link ')} links, {text.count('<joint ')} joints)", file=sys.stderr)
    return 0
