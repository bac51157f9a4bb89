"""`cpg-walker record --out DIR [--duration S]`: record a running graph (the environment's ROS_DOMAIN_ID) to
DIR/recording.mcap, a rosbag2 MCAP with every topic, /tf and /tf_static (nodes/recorder_node.py, run in
this process). Ctrl-C, SIGTERM or the end of ``--duration`` finish the file; it is complete only then."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import non_negative, out_dir
from cpg_walker.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a running graph to DIR/recording.mcap (rosbag2 MCAP)")
    p.add_argument("--out", required=True, type=out_dir, metavar="DIR", help="directory of the bag")
    p.add_argument("--duration", type=non_negative, default=None, metavar="S",
                   help="seconds of sim time to record, from the first /clock received (default: the "
                        "recorder's, config/recorder.yaml: until Ctrl-C)")
    p.add_argument("--wall-time", action="store_true",
                   help="the graph has no /clock: bag times are the wall-clock receive times")
    p.set_defaults(func=_run)


def recorder_argv(out: str, duration: float | None, wall_time: bool) -> list[str]:
    """recorder_node's command line: its parameters file, then the overrides (as Graph passes them)."""
    import math

    from cpg_walker.graph.processes import param_arg
    from cpg_walker.nodes.params import params_file

    if duration is not None and not (duration >= 0 and math.isfinite(duration)):
        raise InputError(f"--duration must be >= 0 seconds (0: until Ctrl-C), got {duration}")
    params = {"use_sim_time": not wall_time, "out_dir": out}
    if duration is not None:
        params["duration"] = float(duration)
    argv = ["recorder_node", "--ros-args", "--params-file", str(params_file("recorder"))]
    for name, value in params.items():
        argv += ["-p", param_arg(name, value)]
    return argv


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from cpg_walker.graph.processes import env_domain_id
    from cpg_walker.nodes.recorder_node import main

    env_domain_id()  # InputError when ROS_DOMAIN_ID is not a domain

    return main(recorder_argv(str(Path(args.out).resolve()), args.duration, args.wall_time))
