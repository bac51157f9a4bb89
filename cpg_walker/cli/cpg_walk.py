"""`cpg-walker cpg-walk --out DIR [--duration S] [--zeta Z] [--alpha A] [--oscillators N] [--cpg FILE]`:
the learned humanoid CPG walks the simulated HOAP-2 in-process (no ROS); DIR/walk.json.
`--feedback on [--pathways P,P] [--set FIELD=VALUE]` closes feedback pathways (walker/feedback.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import config_or_file, count, non_negative, number, out_dir, positive, within
from cpg_walker.cli.outcome import walk_status
from cpg_walker.errors import InputError
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE
from cpg_walker.walker.governor import GovernorConfig


def _schedule(text: str) -> list[tuple[float, float, float]]:
    """``--schedule``: "T,Z,A;..." with T >= 0 sim s and zeta, alpha finite (a value outside the ranges is
    refused when its time comes, recorded in walk.json's ``refused``, and the walk goes on)."""
    out = []
    for item in text.split(";"):
        if not item.strip():
            continue
        parts = item.split(",")
        if len(parts) != 3:
            raise argparse.ArgumentTypeError(f"item {item!r}: expected 'time,zeta,alpha'")
        try:
            t, z, a = (check(x) for check, x in zip(
                (non_negative, number, number), parts, strict=True))
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"item {item!r}: {exc}") from None
        out.append((t, z, a))
    return out


def governed(governor: str | None, feedback: str | None) -> bool:
    """``--governor`` as given, else on unless ``--feedback off`` (the paper's open-loop controller is
    compared as published: commands straight to the oscillators)."""
    return governor == "on" if governor is not None else feedback != "off"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cpg-walk", help="in-process walk driven by the learned humanoid CPG; walk.json")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--duration", type=positive, default=60.0, metavar="S", help="sim seconds (default 60)")
    p.add_argument("--zeta", type=within(*ZETA_RANGE), default=None,
                   help="frequency ratio (negative = backwards; default: cpg_node's, config/cpg.yaml)")
    p.add_argument("--alpha", type=within(*ALPHA_RANGE), default=None,
                   help=f"amplitude (step length) scale, in [0, {GovernorConfig.load().alpha_limit:g}] "
                        f"with the governor, [{ALPHA_RANGE[0]:g}, {ALPHA_RANGE[1]:g}] without (default: "
                        "cpg_node's, config/cpg.yaml)")
    p.add_argument("--oscillators", type=count, default=None, metavar="N",
                   help="oscillators per DOF (learns now unless config/cpg_humanoid.yaml has this N)")
    p.add_argument("--cpg", default=None, type=config_or_file, metavar="FILE",
                   help="learned CPG YAML (default: cpg_node's cpg_file, config/cpg.yaml)")
    p.add_argument("--transition", choices=("recording", "standing"), default="recording",
                   help="start-up: recorded opening steps then hand-over (default), or fade in from standing")
    p.add_argument("--blend", type=non_negative, default=1.0, metavar="S", help="hand-over cross-fade (s)")
    p.add_argument("--schedule", type=_schedule, default=None, metavar="T,Z,A;...",
                   help="commands (time, zeta, alpha) applied during the walk")
    p.add_argument("--feedback", choices=("on", "off"), default="on",
                   help="sensory feedback pathways (paper Sec. III-B; config/feedback.yaml): on (default, as "
                        "cpg_node) | off (the paper's open-loop controller: no pathways and, unless "
                        "--governor on, no governor)")
    p.add_argument("--pathways", default=None, metavar="P,P,...",
                   help="with --feedback on: any of lateral, pendulum, reset (the paper's), amplitude, "
                        "reset_both, heading, ankle (ours); default: config/feedback.yaml's pathways")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a config/feedback.yaml value for this walk (repeatable)")
    p.add_argument("--governor", choices=("on", "off"), default=None,
                   help="the governor (walker/governor.py) between the commands and the CPG: on (default "
                        "with feedback, as cpg_node) | off (default with --feedback off; the raw controller: "
                        "values the robot cannot walk are commanded as they are)")
    p.add_argument("--no-render", action="store_true", help="skip the filmstrip")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json
    import os

    if not args.no_render:
        os.environ.setdefault("MUJOCO_GL", "egl")
    from cpg_walker.experiments.cpg_walk import run_cpg_walk

    if args.pathways is not None:
        from cpg_walker.walker.feedback import check_pathways

        check_pathways(tuple(p.strip() for p in args.pathways.split(",") if p.strip()))
    pathways = None
    if args.feedback == "on":
        from cpg_walker.walker.feedback import default_pathways

        pathways = (default_pathways() if args.pathways is None
                    else tuple(p.strip() for p in args.pathways.split(",") if p.strip()))
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--set {item!r}: expected FIELD=VALUE")
        try:
            overrides[key.strip()] = float(value)
        except ValueError:  # the string fields (lateral_mode, heading_reference)
            overrides[key.strip()] = value.strip()
    if overrides:
        from cpg_walker.walker.feedback import FeedbackConfig

        try:
            FeedbackConfig.load(**overrides)  # a bad field or value, before the walk
        except InputError as exc:
            raise InputError(f"--set: {exc}") from None
    m = run_cpg_walk(args.out, args.duration, args.zeta, args.alpha, args.oscillators, args.cpg,
                     args.transition, args.blend, args.schedule, render=not args.no_render, pathways=pathways,
                     feedback_overrides=overrides, governed=governed(args.governor, args.feedback))
    keys = ("fell", "fall_time_s", "duration_s", "distance_m", "mean_speed_mps", "steps", "lateral_drift_m",
            "heading_change_deg", "n_oscillators")
    print(json.dumps({k: m[k] for k in keys}))
    return walk_status("cpg-walk", m)
