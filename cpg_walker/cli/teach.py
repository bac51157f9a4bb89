"""`cpg-walker teach --gait walk|slow | --csv FILE | --bag DIR [--rate R] [--take-over] [--save FILE]
--out DIR`: teach the running graph's cpg_node a gait live (experiments/teach.py; docs/teaching.md)."""

from __future__ import annotations

import argparse
import sys

from cpg_walker.cli.checks import domain_id, in_file, in_path, out_dir, out_file, positive, within
from cpg_walker.cli.outcome import BAD_INPUT, OK, fall_line, report_fall


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("teach", help="teach the graph's cpg_node a gait live from a stream (/cpg/teach), "
                                     "then optionally take over and walk it")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--gait", choices=("walk", "slow"), help="a packaged recording (its steady stride "
                                                             "repeated after its opening)")
    src.add_argument("--csv", type=in_file, metavar="FILE", help="a recording in the walk data format")
    src.add_argument("--bag", type=in_path, metavar="DIR", help="a rosbag2 recording's JointState topic "
                                                                "(--bag-topic), as a recording")
    p.add_argument("--bag-topic", default="/joint_states", metavar="TOPIC",
                   help="with --bag: the sensor_msgs/JointState topic (default /joint_states)")
    p.add_argument("--speed", type=positive, default=1.0, metavar="S",
                   help="the gait at S times its frequency (default 1)")
    p.add_argument("--rate", type=positive, default=10.0, metavar="R",
                   help="teacher s streamed per wall s (default 10; the stamps stay in the teacher's time, "
                        "so the learned frequency does not depend on it)")
    p.add_argument("--take-over", action="store_true",
                   help="once converged, the taught network walks (~/take_over: through standing, then "
                        "--alpha) for --duration")
    p.add_argument("--duration", type=positive, default=60.0, metavar="S",
                   help="sim s walked after --take-over (default 60)")
    p.add_argument("--alpha", type=within(0.0, 1.0), default=None, metavar="A",
                   help="the taught gait's step length after --take-over (default 0.8: the slow walk taught "
                        "live fell in 2 of 8 in-process take-overs at 1, in 0 of 8 at 0.8)")
    p.add_argument("--save", type=out_file, default=None, metavar="FILE",
                   help="once converged, write the taught network here (a CPG YAML cpg_file loads)")
    p.add_argument("--out", required=True, type=out_dir, help="output directory (teach.json, logs)")
    p.add_argument("--pacing", choices=("lockstep", "realtime"), default="lockstep",
                   help="the started graph's pacing (default lockstep)")
    p.add_argument("--attach", action="store_true",
                   help="teach the graph already running on --domain-id (or ROS_DOMAIN_ID)")
    p.add_argument("--domain-id", type=domain_id, default=None, metavar="N", help="the DDS domain")
    p.add_argument("-p", dest="params", action="append", default=[], metavar="NODE:NAME=VALUE",
                   help="a start-up parameter of the started graph, as `cpg-walker graph -p`; repeatable "
                        "(default: cpg:feedback=false, the walk's feedback gains fall the slow gait; "
                        "cpg:alpha=0.0 stands while learning)")
    p.set_defaults(func=_teach)


#: The started graph's parameters unless -p says otherwise: the walk's feedback gains were searched for the
#: walk; the slow walk learned offline or live falls with them (in-process, 9 s) and walks without.
DEFAULT_PARAMS = ("cpg:feedback=false",)


def _teach(args: argparse.Namespace) -> int:
    from cpg_walker.cli.graph import parse_param
    from cpg_walker.experiments.teach import StreamTeacher, bag_gait, teach_graph

    given = {parse_param(text)[:2] for text in args.params}  # InputError naming a bad one, first
    params = [p for p in DEFAULT_PARAMS if parse_param(p)[:2] not in given] + list(args.params)
    source = bag_gait(args.bag, args.bag_topic) if args.bag is not None else args.gait or args.csv
    teacher = StreamTeacher(source, args.speed)
    from cpg_walker.experiments.teach import TAUGHT_ALPHA

    res = teach_graph(args.out, teacher, rate=args.rate, take_over=args.take_over, save=args.save,
                      alpha=TAUGHT_ALPHA if args.alpha is None else args.alpha,
                      duration=args.duration, domain_id=args.domain_id, attach=args.attach,
                      pacing=args.pacing, params=params,
                      progress=lambda s: print(s, file=sys.stderr, flush=True))
    if res["fell"] and not res["took_over"]:
        return report_fall("teach", [fall_line("teach", res["fell_at_s"], what="while being taught")])
    if not res["converged"]:
        if "after" in res:
            a = res["after"]
            print(f"the walk went on untouched: {a['distance_m']:.2f} m in {a['walked_s']:.1f} sim s after "
                  "the refusal")
        if res["fell"]:
            return report_fall("teach", [fall_line("teach", res.get("fell_at_s"), what="after the refusal")])
        print(f"cpg-walker teach: error: not taught: {res.get('reason')}", file=sys.stderr)
        return BAD_INPUT
    line = (f"taught: {res['learned_frequency_hz']:.4f} Hz learned after {res['converged_after_s']:.1f} "
            f"teacher s")
    if res["teacher_frequency_hz"]:
        line += f" (the teacher's {res['teacher_frequency_hz']:.4f} Hz)"
    print(line)
    if res["saved"]:
        print(f"saved {res['saved']}")
    if res["took_over"]:
        print(f"took over and walked {res['walked_s']:.1f} sim s at alpha {res['alpha']:g}, "
              f"{res['distance_m']:.2f} m")
        if res["fell"]:
            return report_fall("teach", [fall_line("teach", res["fell_at_s"], what="the taught gait")])
    return OK
