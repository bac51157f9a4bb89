"""`cpg-walker faults --out DIR`: kill (SIGKILL) and restart each node of the walking ROS graph in turn
(sim_node in realtime pacing, pid_node, cpg_node at zeta 1); per fault: fell or not, time until walking
again; DIR/faults.json and DIR/faults.md (experiments/faults.py)."""

from __future__ import annotations

import argparse

from cpg_walker.cli.checks import non_negative, out_dir, positive, within
from cpg_walker.cli.outcome import fall_line, report_fall
from cpg_walker.walker.controller import ZETA_RANGE


def _nodes(text: str) -> str:
    """``--nodes``: one or more of FAULT_ORDER, comma-separated."""
    from cpg_walker.experiments.faults import FAULT_ORDER

    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in FAULT_ORDER]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected nodes among {','.join(FAULT_ORDER)}, got {text!r}")
    return text


def register(sub: argparse._SubParsersAction) -> None:
    from cpg_walker.experiments.faults import FAULT_ORDER

    p = sub.add_parser("faults", help="kill and restart each graph node while walking; faults.json + table")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.add_argument("--zeta", type=within(*ZETA_RANGE), default=1.0,
                   help="frequency ratio to walk at (default 1)")
    p.add_argument("--warm", type=non_negative, default=14.0, metavar="S",
                   help="sim s of walking before the first fault (default 14)")
    p.add_argument("--away", type=positive, default=None, metavar="S",
                   help="wall s between killing a node and starting it again (default 2; with --in-process: "
                        "sim s the PID is lost, default 3)")
    p.add_argument("--nodes", default=",".join(FAULT_ORDER), type=_nodes, metavar="A,B",
                   help=f"nodes to kill, in order (default {','.join(FAULT_ORDER)})")
    p.add_argument("--in-process", action="store_true",
                   help="instead: the PID lost for --away sim s at 52 phases over two strides, "
                        "in-process; back by tracking the live gait vs re-entering it (fault_phases.json)")
    p.add_argument("--cpg-loss", action="store_true",
                   help="instead: cpg_node lost for good at 80 times over 6.4 strides, in-process: pid_node "
                        "on its last horizon, with and without the horizon's foreseen stop (cpg_loss.json)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import json

    from cpg_walker.experiments.faults import markdown_table, run_faults

    if args.cpg_loss:
        from pathlib import Path

        from cpg_walker.experiments.fault_phases import run_cpg_loss

        report = run_cpg_loss()
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "cpg_loss.json").write_text(json.dumps(report, indent=1) + "\n")
        print(json.dumps(report["summary"]))
        # the loss without the foreseen stop (0 s) is the baseline, its falls are data; the configured stop's
        # falls are failures of what cpg_node/pid_node do
        return report_fall("faults", [
            fall_line("faults", r["fall_time_s"], what=f"cpg_node lost at {r['t_kill']:g} s, horizon stop "
                                                       f"{r['horizon_stop_s']:g} s")
            for r in report["runs"] if r["fell"] and r["horizon_stop_s"] > 0])
    if args.in_process:
        from pathlib import Path

        from cpg_walker.experiments.fault_phases import run_phases

        report = run_phases(away=3.0 if args.away is None else args.away)
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "fault_phases.json").write_text(json.dumps(report, indent=1) + "\n")
        print(json.dumps(report["summary"]))
        # 'live' is the compared alternative (its falls are data); 'reenter' is what the graph does
        return report_fall("faults", [
            fall_line("faults", r["fall_time_s"], what=f"PID lost at {r['t_kill']:g} s, re-entered")
            for r in report["runs"] if r["fell"] and r["mode"] == "reenter"])
    nodes = tuple(n.strip() for n in args.nodes.split(",") if n.strip())
    away = 2.0 if args.away is None else args.away
    report = run_faults(args.out, zeta=args.zeta, warm_s=args.warm, away_wall_s=away, faults=nodes)
    print(json.dumps(report["faults"]))
    print(markdown_table(report), end="")
    return report_fall("faults", [
        fall_line("faults", r["fall_time_s"], what=f"after {r['node']} was killed at {r['killed_at_s']:g} s")
        for r in report["faults"] if r["fell"]])
