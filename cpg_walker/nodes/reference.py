"""Per-node reference pages from the one description of the interface: ``python -m
cpg_walker.nodes.reference --out docs/reference`` writes docs/reference/<executable>.md for every node
(topics: nodes/interface.py; parameters: nodes/specs.py). cpg_node does not declare from specs yet: its
parameters are read from the node itself, built in-process from its packaged parameters file (its learned
CPG is loaded: a few seconds). test/test_reference.py checks the committed pages against this output and
the running nodes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cpg_walker.nodes.interface import CPG_NODE, INTERFACES, NODE_NAMES
from cpg_walker.nodes.params import ParamSpec, render_reference, spec_of_descriptor
from cpg_walker.nodes.specs import SPECS

#: Parameters rclpy declares on every node (not ours to describe).
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
#: The source line of a page whose parameters were read from the running node.
FROM_NODE = ("Read from the node's declared parameter descriptors (this node does not declare from "
             "`cpg_walker/nodes/specs.py` yet).")


def declared_specs(node) -> tuple[ParamSpec, ...]:
    """The parameters ``node`` has declared (not rclpy's own), in declaration order, as ParamSpecs."""
    names = [n for n in node._parameters if n not in RCLPY_PARAMETERS]
    described = node.describe_parameters(names)
    return tuple(spec_of_descriptor(n, d) for n, d in zip(names, described, strict=True))


def build_cpg_specs() -> tuple[ParamSpec, ...]:
    """cpg_node's parameters: the node built in a context of its own, from its packaged file."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from cpg_walker.nodes.cpg_node import CPGNode
    from cpg_walker.nodes.graph import random_domain_id
    from cpg_walker.nodes.runtime import params_file

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=random_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = CPGNode(context=ctx, cli_args=["--ros-args", "--params-file",
                                              str(params_file(NODE_NAMES[CPG_NODE]))])
        try:
            return declared_specs(node)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def pages(cpg_specs: tuple[ParamSpec, ...] | None = None) -> dict[str, str]:
    """File name -> Markdown of every node's page (``cpg_specs``: cpg_node's, else built)."""
    out = {}
    for exe, iface in INTERFACES.items():
        if exe in SPECS:
            out[f"{exe}.md"] = render_reference(iface, SPECS[exe])
        else:
            specs = cpg_specs if cpg_specs is not None else build_cpg_specs()
            out[f"{exe}.md"] = render_reference(iface, specs, source=FROM_NODE)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cpg_walker.nodes.reference",
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
