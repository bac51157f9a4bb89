"""`cpg-walker learn --out DIR [--oscillators N] [--no-config]`: learn the humanoid CPG from the
recorded walk (paper Sec. III-A); write config/cpg_humanoid.yaml, DIR/cpg_humanoid.yaml, DIR/fig6.png
and DIR/learn.json."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("learn", help="learn the 10-DOF humanoid CPG from the recorded walk; Fig 6")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--oscillators", type=int, default=None, metavar="N",
                   help="oscillators per DOF (default: config/cpg_humanoid_learning.yaml)")
    p.add_argument("--no-config", action="store_true",
                   help="do not overwrite config/cpg_humanoid.yaml (the node's default)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.experiments.learn import run_learn

    if args.oscillators is not None and args.oscillators < 1:
        raise ValueError(f"--oscillators must be >= 1, got {args.oscillators}")
    r = run_learn(args.out, args.oscillators, keep_config=not args.no_config)
    keys = ("gait_frequency_hz", "recorded_gait_frequency_hz", "max_rms_error_deg", "n_oscillators",
            "converged", "strides_learned", "learning_wall_time_s")
    print(json.dumps({k: r[k] for k in keys}))
    print(json.dumps(r["rms_error_deg_by_paper_name"]))
    return 0
