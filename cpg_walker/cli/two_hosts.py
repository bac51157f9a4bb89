"""`cpg-walker two-hosts --out DIR [--duration S] [--no-local]`: the lockstep CPG walk with sim_node in
one network namespace and pid_node + cpg_node in another, joined by a veth pair it creates and removes
(root needed), next to the same walk on one host; writes DIR/two_hosts.json with the state->torque round
trip (p50/p99) of both (experiments/two_hosts.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import out_dir, positive
from cpg_walker.cli.outcome import fall_line, report_fall


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("two-hosts", help="the walk across a veth pair between two network namespaces "
                                         "(root), next to the local walk; write two_hosts.json")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--duration", type=positive, default=30.0, metavar="S", help="sim seconds (default 30)")
    p.add_argument("--no-local", dest="local", action="store_false",
                   help="skip the walk on one host (only the two-host walk)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.errors import InputError
    from cpg_walker.experiments.two_hosts import compare
    from cpg_walker.graph.netns import unavailable

    why = unavailable()
    if why:
        raise InputError(f"cannot create the two hosts: {why}")
    result = compare(args.out, duration=args.duration, local=args.local)
    print(json.dumps(result["state_to_torque_ms"]))
    for name, run in result["runs"].items():
        fall = f"fell at {run['fall_time_s']} s" if run["fell"] else "no fall"
        print(f"{name}: {run['distance_m']:.3f} m in {run['duration_s']:.1f} s, {fall}, real-time factor "
              f"{run['real_time_factor']:.2f}")
    print(f"two_hosts.json in {args.out}")
    return report_fall("two-hosts", [fall_line("two-hosts", run["fall_time_s"], what=f"{name} walk")
                                     for name, run in result["runs"].items() if run["fell"]])
