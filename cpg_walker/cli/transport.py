"""`cpg-walker transport --out DIR`: the largest loss and delay of the controllers' topics at which the CPG
walk still walks (realtime walks through relay_node; experiments/transport.py). Writes DIR/transport.json,
DIR/transport.md and DIR/transport.png."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import number, out_dir, positive, within
from cpg_walker.errors import InputError


def _floats(text: str) -> list[float]:
    try:
        return [number(x) for x in text.split(",") if x.strip()]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected comma-separated finite numbers, got {text!r}") from None


def _zetas(text: str) -> list[float]:
    """``--zetas``: numbers in ZETA_RANGE, at least one."""
    from cpg_walker.walker.controller import ZETA_RANGE

    values = _floats(text)
    if not values or any(not ZETA_RANGE[0] <= z <= ZETA_RANGE[1] for z in values):
        raise argparse.ArgumentTypeError(f"expected zeta values in [{ZETA_RANGE[0]:g}, {ZETA_RANGE[1]:g}], "
                                         f"got {text!r}")
    return values


def register(sub: argparse._SubParsersAction) -> None:
    from cpg_walker.experiments import transport as t

    p = sub.add_parser("transport", help="largest loss / delay of the controllers' topics the walk survives "
                                         "(realtime, relay_node); write transport.json/.md/.png")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--duration", type=positive, default=30.0, metavar="S",
                   help="sim s of each walk (default 30)")
    p.add_argument("--zetas", type=_zetas, default=list(t.ZETAS), metavar="Z,Z",
                   help=f"zeta values (default {','.join(map(str, t.ZETAS))}); each with feedback on and off")
    p.add_argument("--losses", type=_floats, default=list(t.LOSSES), metavar="L,L",
                   help=f"loss fractions tried in order (default {','.join(map(str, t.LOSSES))})")
    p.add_argument("--delays-ms", type=_floats, default=[d * 1e3 for d in t.DELAYS_S], metavar="D,D",
                   help="delays (ms) tried in order, jitter half of each (default "
                        f"{','.join(f'{d * 1e3:g}' for d in t.DELAYS_S)})")
    p.add_argument("--seed", type=within(0, 2**32 - 1, int), default=1, help="relay_node's seed (default 1)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import shlex
    import sys

    from cpg_walker.experiments.transport import run_transport

    for name, values, hi in (("--losses", args.losses, 1.0), ("--delays-ms", args.delays_ms, 10_000.0)):
        if not values or any(not 0 < v <= hi for v in values):
            raise InputError(f"{name} must be numbers in (0, {hi:g}], got {values}")
    command = "cpg-walker " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    report = run_transport(args.out, zetas=args.zetas, losses=args.losses,
                           delays_s=[d / 1e3 for d in args.delays_ms], duration=args.duration, seed=args.seed,
                           command=command)
    from cpg_walker.experiments.transport import markdown_table

    print(markdown_table(report), end="")
    return 0
