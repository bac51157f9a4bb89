"""Every committed result the docs quote, and the command that regenerates it (``cpg-walker results``).

Each ``Artifact`` is one `cpg-walker` command run into ``docs/results/<name>/`` (its ``--out``; the
benchmarks keep ``docs/bench``); the docs quote figures from those files, and their generated tables
(``readme_blocks``) are checked against them by the tests. ``wall_min`` is what the run took on the
project's 2-core machine, for the progress line; the commands record their provenance (command, commit,
date, load) where they can.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Artifact:
    name: str
    what: str
    argv: tuple[str, ...]  # the cpg-walker command line, without --out (empty: `results` runs it itself)
    files: tuple[str, ...]  # what it writes into its directory that is committed
    wall_min: float  # about how long it takes on the 2-core machine (minutes)


ARTIFACTS: tuple[Artifact, ...] = (
    Artifact("headline", "the README's headline walks, in-process", (),
             ("headline.json", "headline.md"), 1.0),
    Artifact("faults", "each graph node killed and restarted while walking", ("faults",),
             ("faults.json", "faults.md"), 1.0),
    Artifact("fault_phases", "the PID lost at 52 phases over two strides, in-process",
             ("faults", "--in-process"), ("fault_phases.json",), 8.0),
    Artifact("cpg_loss", "cpg_node lost at 80 times, with and without the horizon's stop, in-process",
             ("faults", "--cpg-loss"), ("cpg_loss.json",), 8.0),
    Artifact("transport", "the largest loss and delay the realtime walk survives", ("transport",),
             ("transport.json", "transport.md", "transport.png"), 17.0),
    Artifact("soak", "10 sim minutes of walking with a change every 20 s", ("soak", "--pacing", "lockstep"),
             ("soak.json", "soak.md"), 25.0),
    Artifact("two_hosts", "the walk across a veth pair between two network namespaces (root)", ("two-hosts",),
             ("two_hosts.json",), 2.0),
    Artifact("scaleout", "sweep and feedback search as PostgreSQL studies, workers in two network namespaces "
             "(root)", ("scaleout",),
             ("scaleout.json", "scaleout.md", "dashboard.png", "dashboard_trials.png"), 8.0),
    Artifact("envelope", "which (zeta, alpha) walk, from standing and changed at 10 s, in-process",
             ("envelope",), ("envelope.json", "envelope.md", "envelope.png"), 20.0),
    Artifact("pushes", "the largest lateral pushes recovered standing and walking, in-process", ("pushes",),
             ("pushes.json", "pushes.md"), 3.0),
    Artifact("drive_check", "/cmd_vel commanded vs achieved and the steering protocol, in-process",
             ("drive-check",), ("drive_check.json", "drive_check.md", "drive_check.png"), 8.0),
    Artifact("steer_graph", "turn in place, side step, forward through the realtime graph by a Twist client",
             ("drive-check", "--graph", "--plan", "steer", "--pacing", "realtime"),
             ("drive_graph.json", "drive_graph.md"), 2.0),
    Artifact("teach_slow", "the slow walk taught live through the realtime graph, taking over, 60 s walked",
             ("teach", "--gait", "slow", "--take-over", "--pacing", "realtime"), ("teach.json", "teach.md"),
             2.0),
    Artifact("teach_unseen", "the walk at 1.25 x its frequency taught live through the graph",
             ("teach", "--gait", "walk", "--speed", "1.25"), ("teach.json", "teach.md"), 1.0),
    Artifact("random_walks", "100 random command sequences of 120 s through the governor, in-process",
             ("random-walks", "--seeds", "400-499"), ("random_walks.json",), 14.0),
    Artifact("random_walks_default", "50 more random command sequences of 120 s with cpg_node's default "
             "pathways, in-process", ("random-walks", "--seeds", "500-549"), ("random_walks.json",), 7.0),
    Artifact("random_walks_no_ankle", "the same 50 without the ankle strategy (the defaults before it)",
             ("random-walks", "--seeds", "500-549", "--pathways", "amplitude,reset_both,heading"),
             ("random_walks.json",), 7.0),
    Artifact("transitions", "every change between six walking states at 8 stride phases, in-process",
             ("transitions", "--phases", "8"), ("transitions.json", "transitions.png"), 15.0),
    Artifact("envelope_open_loop", "the same without feedback (the governor's open-loop table)",
             ("envelope", "--config", "envelope_open_loop.yaml"),
             ("envelope.json", "envelope.md", "envelope.png"), 3.0),
    Artifact("bench", "the benchmarks (every figure beside its same-run baseline)", ("bench",),
             ("bench.json", "bench.md", "bench_table.md", "bench_oscillators.png", "bench_robots.png"), 52.0),
)


#: Where an artifact lives under the results root, when not in its own <name>/ folder.
PLACES = {"bench": "../bench"}


def artifact(name: str) -> Artifact:
    found = [a for a in ARTIFACTS if a.name == name]
    if not found:
        raise KeyError(name)
    return found[0]
