"""`cpg-walker learn --out DIR [--oscillators N] [--install]`: learn the humanoid CPG from the recorded
walk (paper Sec. III-A); write DIR/cpg_humanoid.yaml, DIR/fig6.png and DIR/learn.json (and, with
--install, the packaged config/cpg_humanoid.yaml that cpg_node loads by default)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import count, out_dir


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("learn", help="learn the 10-DOF humanoid CPG from the recorded walk; Fig 6")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--oscillators", type=count, default=None, metavar="N",
                   help="oscillators per DOF (default: config/cpg_humanoid_learning.yaml)")
    p.add_argument("--install", action="store_true",
                   help="also replace the packaged config/cpg_humanoid.yaml (cpg_node's default file)")
    p.add_argument("--no-config", action="store_true",
                   help="(kept for old scripts; the packaged file is only written with --install)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.experiments.learn import run_learn

    r = run_learn(args.out, args.oscillators, install=args.install)
    keys = ("gait_frequency_hz", "recorded_gait_frequency_hz", "max_rms_error_deg", "n_oscillators",
            "converged", "strides_learned", "learning_wall_time_s")
    print(json.dumps({k: r[k] for k in keys}))
    print(json.dumps(r["rms_error_deg_by_paper_name"]))
    return 0
