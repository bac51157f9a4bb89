"""`cpg-walker demo --out DIR`: the project's main job, end to end (what `make demo` runs).

1. The paper's Section II experiment with the generic CPG (figures + section2.json) in DIR/section2.
2. The simulated HOAP-2 walking Fujitsu's recorded gait for 30 s under PID control, rendered offscreen
   to a side-view filmstrip and GIF, in DIR/replay.
Later issues add the robot walking from the learned CPG.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job end to end (what `make demo` runs)")
    p.add_argument("--out", default="results", help="output directory (default: results)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    import os
    import sys
    from pathlib import Path

    os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

    from cpg_walker.cli.section2 import run_section2
    from cpg_walker.experiments.replay import replay_recording

    out = Path(args.out)
    print("== 1/2  Section II: the generic CPG learns and replays a periodic signal", file=sys.stderr)
    status = run_section2(out / "section2")
    if status:
        return status
    print("== 2/2  the simulated HOAP-2 walks Fujitsu's recorded gait (30 s, PID, in-process)",
          file=sys.stderr)
    report = replay_recording(str(out / "replay"), gait="walk")
    keys = ("fell", "duration_s", "distance_m", "mean_speed_mps", "steps", "lateral_drift_m",
            "heading_change_deg")
    print(json.dumps({"replay": {k: report[k] for k in keys}}))
    print(f"demo: figures and JSON under {out}/ (section2/*.png, replay/filmstrip.png, replay/replay.gif)",
          file=sys.stderr)
    return 0
