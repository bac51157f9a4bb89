"""`cpg-walker feedback-sweep --out DIR`: ζ sweep, open loop vs the feedback pathways (paper Sec. IV)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("feedback-sweep", help="zeta sweep with/without sensory feedback; JSON + PNG")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--duration", type=float, default=40.0, metavar="S", help="sim seconds per walk")
    p.add_argument("--zetas", default=None, metavar="Z,Z,...", help="default 0.8,1.0,1.1,1.2,1.3,1.5")
    p.add_argument("--conditions", default=None, metavar="C,C,...",
                   help="off, paper, signed+pendulum+reset, reset, ours (default: all)")
    p.add_argument("--calibrate", action="store_true", help="first measure the zeta = 1 calibration")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from cpg_walker.cli.main import UserError
    from cpg_walker.experiments.feedback_sweep import CONDITIONS, ZETAS, run_sweep

    zetas = ZETAS if args.zetas is None else tuple(float(z) for z in args.zetas.split(","))
    conds = None if args.conditions is None else args.conditions.split(",")
    if conds and any(c not in CONDITIONS for c in conds):
        raise UserError(f"--conditions: choose from {list(CONDITIONS)}")
    r = run_sweep(args.out, zetas, conds, args.duration, args.calibrate)
    print(r["png"])
    return 0
