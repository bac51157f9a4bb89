"""`cpg-walker sweep --out DIR [--quick] [--jobs N] [--duration S] [--config FILE] [--calibrate]
[--storage URL] [--study NAME] [--resume]`: issue 11's experiment — ζ forward/backward × feedback
off/paper/ours × start standing/at 10 s, α sweep, largest push recovered, the paper's Fig. 8 (grid:
config/sweep.yaml); DIR/sweep.json, sweep.md, PNGs. Every walk is a trial of an Optuna study (default
DIR/study.db, made afresh unless --resume); `cpg-walker worker` on other hosts joins a --storage one."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import in_text_file, out_dir, positive
from cpg_walker.cli.study_args import add_study_args, check_study_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="zeta x feedback x start sweep, alpha, pushes, Fig. 8; JSON + MD + PNG")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--quick", action="store_true", help="the small subset (config/sweep.yaml's quick:)")
    p.add_argument("--duration", type=positive, default=None, metavar="S",
                   help="sim s walked after each command (default: config/sweep.yaml's duration_after_s)")
    p.add_argument("--config", default=None, type=in_text_file, metavar="FILE",
                   help="a sweep YAML (default config/sweep.yaml)")
    p.add_argument("--calibrate", action="store_true",
                   help="only measure the zeta = 1 calibration of config/feedback.yaml (pitch reference, "
                        "touchdown phase) and write DIR/calibration.json")
    add_study_args(p, "sweep")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from cpg_walker.experiments.sweep import calibrate, fall_thresholds, run_sweep

    check_study_args(args)
    if args.calibrate:
        cal = calibrate()
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "calibration.json").write_text(json.dumps(cal, indent=2) + "\n")
        print(json.dumps(cal))
        return 0
    r = run_sweep(args.out, args.quick, args.jobs, args.config, args.duration, storage=args.storage,
                  study=args.study, resume=args.resume)
    print(json.dumps(fall_thresholds(r["runs"])))
    return 0
