"""``cpg-walker walk``: the CPG walk through the ROS graph, three processes.

cpg_node streams the learned CPG as /joint_targets on every /clock tick (the recording's opening steps,
then the CPG), pid_node closes the loop over /joint_states -> /joint_torques, sim_node steps the HOAP-2
and records the run. Run and summarised by the graph replay's code (experiments/replay_graph.py), so
walk.json has replay.json's keys plus ``zeta``, ``alpha``, ``feedback``, ``real_time_factor`` and the CPG
facts. Every node gets its parameters file (config/<node>.yaml); ``zeta``/``alpha``/``cpg_file`` None
leave cpg_node's values from config/cpg.yaml.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cpg_walker.walker.learning import cpg_defaults

#: Wall s to allow cpg_node for learning at start-up (cpg_file ''): pid_node's startup_wait then.
LEARN_WAIT_S = 600.0


def check_modulation(zeta: float, alpha: float) -> None:
    """The cpg_node's ranges, checked before any process starts."""
    from cpg_walker.walker.controller import modulation_error

    for name, value in (("zeta", zeta), ("alpha", alpha)):
        reason = modulation_error(name, value)
        if reason:
            raise ValueError(reason)


def run_graph_walk(
    out_dir: str | Path,
    duration: float = 60.0,
    zeta: float | None = None,
    alpha: float | None = None,
    cpg_file: str | None = None,
    pacing: str = "lockstep",
    control_period: float | None = None,
    stop_on_fall: bool = True,
    timeout: float | None = None,
) -> dict:
    """Walk through sim_node + pid_node + cpg_node; write ``walk.json``; return its content. ``zeta``,
    ``alpha``, ``cpg_file`` None: cpg_node's own (config/cpg.yaml), not passed on."""
    from cpg_walker.experiments.replay_graph import run_graph
    from cpg_walker.nodes.runtime import PACINGS
    from cpg_walker.walker.learning import load_controller

    if pacing not in PACINGS:
        raise ValueError(f"pacing must be realtime, fast or lockstep, got {pacing!r}")
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"--duration must be a positive number of seconds, got {duration}")
    defaults = cpg_defaults()
    overrides = {name: float(value) for name, value in (("zeta", zeta), ("alpha", alpha))
                 if value is not None}
    zeta, alpha = (float(defaults[name]) if value is None else value
                   for name, value in (("zeta", zeta), ("alpha", alpha)))
    check_modulation(zeta, alpha)
    cpg_file = defaults["cpg_file"] if cpg_file is None else cpg_file
    learn_now = not cpg_file
    ctrl = None
    if not learn_now:  # fail early, in this process, on a missing or corrupt file
        ctrl, origin, _ = load_controller(cpg_file)
        cpg_file = str(Path(origin).resolve())
    out = Path(out_dir)
    limit = timeout if timeout is not None else 60.0 + duration * 5.0 + (LEARN_WAIT_S if learn_now else 0.0)
    run = run_graph(out, "cpg_node", {"cpg_file": cpg_file, **overrides},
                    duration=duration, pacing=pacing, control_period=control_period,
                    stop_on_fall=stop_on_fall, timeout=limit,
                    pid_params={"startup_wait": LEARN_WAIT_S} if learn_now else None)
    period = ctrl.period / abs(zeta) if ctrl is not None and zeta else None
    metrics, _ = run.report(period_s=period)
    report = {
        **metrics,
        "zeta": zeta, "alpha": alpha, "feedback": False,
        "n_oscillators": int(ctrl.net.N) if ctrl is not None else None,
        "cpg_file": cpg_file or "learned at start-up",
    }
    (out / "walk.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
