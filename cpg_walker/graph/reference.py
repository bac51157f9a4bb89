"""Per-node reference pages from the one description of the interface: ``python -m
cpg_walker.graph.reference --out docs/reference`` writes docs/reference/<executable>.md for every node
(topics: nodes/interface.py; parameters: nodes/specs.py). test/test_reference.py checks the committed
pages against this output and the running nodes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cpg_walker.nodes.interface import INTERFACES
from cpg_walker.nodes.params import ParamSpec, render_reference, spec_of_descriptor
from cpg_walker.nodes.specs import SPECS

#: Parameters rclpy declares on every node (not ours to describe).
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
def declared_specs(node) -> tuple[ParamSpec, ...]:
    """The parameters ``node`` has declared (not rclpy's own), in declaration order, as ParamSpecs."""
    names = [n for n in node._parameters if n not in RCLPY_PARAMETERS]
    described = node.describe_parameters(names)
    return tuple(spec_of_descriptor(n, d) for n, d in zip(names, described, strict=True))


def pages() -> dict[str, str]:
    """File name -> Markdown of every node's page."""
    return {f"{exe}.md": render_reference(iface, SPECS[exe]) for exe, iface in INTERFACES.items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cpg_walker.graph.reference",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="docs/reference", help="directory of the pages (default docs/reference)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in pages().items():
        (out / name).write_text(text, encoding="utf-8")
        print(out / name, file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
