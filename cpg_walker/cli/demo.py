"""`cpg-walker demo --out DIR`: the project's main job, end to end (what `make demo` runs).

1. The paper's Section II experiment with the generic CPG (figures + section2.json) in DIR/section2.
2. The simulated HOAP-2 walking Fujitsu's recorded gait for 30 s under PID control, rendered offscreen
   to a side-view filmstrip and GIF, in DIR/replay.
3. The humanoid CPG (paper Sec. III-A) learned from that walk: Fig. 6 and the learned YAML, in DIR/learn.
4. The robot walking 60 s from the learned CPG (in-process; zeta = alpha = 1), filmstrip in DIR/cpg_walk.
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
    from cpg_walker.experiments.cpg_walk import run_cpg_walk
    from cpg_walker.experiments.learn import run_learn
    from cpg_walker.experiments.replay import replay_recording

    out = Path(args.out)
    print("== 1/4  Section II: the generic CPG learns and replays a periodic signal", file=sys.stderr)
    status = run_section2(out / "section2")
    if status:
        return status
    print("== 2/4  the simulated HOAP-2 walks Fujitsu's recorded gait (30 s, PID, in-process)",
          file=sys.stderr)
    report = replay_recording(str(out / "replay"), gait="walk")
    keys = ("fell", "duration_s", "distance_m", "mean_speed_mps", "steps", "lateral_drift_m",
            "heading_change_deg")
    print(json.dumps({"replay": {k: report[k] for k in keys}}))
    print("== 3/4  learning the 10-DOF humanoid CPG from the recorded walk (Fig. 6)", file=sys.stderr)
    learned = run_learn(str(out / "learn"))
    print(json.dumps({"learn": {k: learned[k] for k in ("gait_frequency_hz", "recorded_gait_frequency_hz",
                                                         "max_rms_error_deg", "n_oscillators")}}))
    print("== 4/4  the simulated HOAP-2 walks 60 s from the learned CPG (zeta = 1, alpha = 1)",
          file=sys.stderr)
    walked = run_cpg_walk(str(out / "cpg_walk"), duration=60.0,
                          cpg_file=str(out / "learn" / "cpg_humanoid.yaml"))
    print(json.dumps({"cpg_walk": {k: walked[k] for k in keys}}))
    print(f"demo: figures and JSON under {out}/ (section2/*.png, replay/filmstrip.png, replay/replay.gif, "
          "learn/fig6.png, cpg_walk/filmstrip.png)",
          file=sys.stderr)
    return 0
