"""Does a benchmark run count? One check for every section's runs (experiments/bench*.py).

Every run a section records (a walk, a graph run, a measurement entry) carries ``valid`` and, when
false, ``invalid_reason``. An invalid run stays in bench.json with its reason but feeds no figure, table
or plot (bench_report.py); an invalid run behind a HEADLINE figure fails ``cpg-walker bench`` (exit 1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

#: The commanded gait (ζ = α = 1) walks ≈ 0.08 m/s (results.md: 0.083 m/s over 60 s through the graph, the
#: in-process loop 1.58 m in 20 s). A walk must cover at least 0.05 m, ≈ 0.6 s of that gait: the
#: benchmark walks that are checked for movement last 3 s or more and cover ≥ 0.17 m even from standing
#: (run_walk: 0.005 m in 1 s, 0.17 m in 3 s, 0.24 m in 4 s), while a robot that only stood (no targets, no
#: controller) drifts < 1 mm (0.0003 m in the 2026-12-02 run's stalled real-time walk). The robots
#: section's 1 s graph runs move only millimetres by design: fall and ticks are checked there, not distance.
MIN_WALK_DISTANCE_M = 0.05

#: The runs behind the figures benchmarks.md quotes (dotted paths into bench.json; a list is checked run by
#: run): an invalid one among them makes `cpg-walker bench` (and --from-json) exit 1.
HEADLINE: tuple[str, ...] = (
    "robot.replay_runs",  # "the in-process replay 19× real time"
    "loop.cpg_walk_20s.runs",  # "loop wall / time inside mj_step 1.7–1.9"
    "graph.realtime", "graph.fast", "graph.lockstep",  # sim + PID × real time, latency p50/p99
    "graph.lockstep_cpg_walk",  # "the three-node CPG walk 2.1× in lockstep", cpg_node CPU
    "graph.realtime_cpg_walk",  # "cpg_node in real time ticks every 2.000 ms with |jitter| ..."
)


def check_run(*, fell: bool | None = None, fall_time_s: float | None = None,
              ticks: Mapping[str, int | None] | None = None, distance_m: float | None = None,
              walking: bool = False, error: str | None = None,
              figures: Mapping[str, float | None] | None = None) -> dict:
    """``{"valid": True}`` or ``{"valid": False, "invalid_reason": "..."}`` (reasons joined by "; ").

    Invalid: an ``error``; the robot ``fell``; a controller in ``ticks`` (node -> ticks it handled, None:
    it reported none at exit) with no ticks; a ``walking`` run whose ``distance_m`` (forward, base) is
    missing or below MIN_WALK_DISTANCE_M; a measured figure in ``figures`` missing, not finite or negative."""
    reasons: list[str] = []
    if error:
        reasons.append(f"error: {error}")
    if fell:
        reasons.append("fell" + (f" at {fall_time_s:.1f} s" if fall_time_s is not None else ""))
    for node, n in (ticks or {}).items():
        if n is None:
            reasons.append(f"no controller ticks ({node} reported no stats at exit)")
        elif n <= 0:
            reasons.append(f"no controller ticks ({node})")
    if walking:
        if distance_m is None:
            reasons.append("distance not recorded")
        elif not distance_m >= MIN_WALK_DISTANCE_M:
            reasons.append(f"moved {distance_m:.4g} m (< {MIN_WALK_DISTANCE_M} m)")
    for name, value in (figures or {}).items():
        if value is None or not math.isfinite(value) or value < 0:
            reasons.append(f"{name} is {value}")
    return {"valid": True} if not reasons else {"valid": False, "invalid_reason": "; ".join(reasons)}


def _get(results: Mapping, path: str):
    node = results
    for key in path.split("."):
        if not isinstance(node, Mapping) or key not in node:
            return None
        node = node[key]
    return node


def runs_in(node, path: str = "") -> list[tuple[str, dict]]:
    """(path, run) of every run (a dict carrying ``valid``) at or below ``node``, depth first."""
    if isinstance(node, Mapping):
        if "valid" in node:
            return [(path, node)]
        return [r for k, v in node.items() for r in runs_in(v, f"{path}.{k}" if path else str(k))]
    if isinstance(node, list):
        return [r for i, v in enumerate(node) for r in runs_in(v, f"{path}[{i}]")]
    return []


def invalid_runs(results: Mapping) -> list[tuple[str, str]]:
    """(path, reason) of every invalid run in ``results`` (bench.json)."""
    return [(p, r.get("invalid_reason", "invalid")) for p, r in runs_in(results) if r["valid"] is not True]


def headline_problems(results: Mapping) -> list[str]:
    """Why the HEADLINE figures of the sections that ran do not stand: "path: reason" of each invalid run
    behind one, or of a headline run that is missing or carries no validity (a bench.json from before
    runs were checked). Empty: every headline figure stands."""
    problems = []
    for path in HEADLINE:
        if not isinstance(results.get(path.split(".")[0]), Mapping):
            continue  # the section did not run
        node = _get(results, path)
        runs = runs_in(node, path)
        if node is None or not runs:
            problems.append(f"{path}: no run with a validity check recorded")
        problems += [f"{p}: {r.get('invalid_reason', 'invalid')}" for p, r in runs if r["valid"] is not True]
    return problems


def is_valid(run) -> bool:
    """A run (or an entry) counts: it carries ``valid: true``."""
    return isinstance(run, Mapping) and run.get("valid") is True


def combine(runs: list[dict]) -> dict:
    """The validity of a figure measured over ``runs`` (each with its check_run keys): valid when every
    run is; else "k of n runs invalid: reason; ..." (each distinct reason once)."""
    bad = [r.get("invalid_reason", "invalid") for r in runs if r.get("valid") is not True]
    if not runs:
        return {"valid": False, "invalid_reason": "no runs"}
    if not bad:
        return {"valid": True}
    return {"valid": False,
            "invalid_reason": f"{len(bad)} of {len(runs)} runs invalid: " + "; ".join(dict.fromkeys(bad))}


def numbers(entry: Mapping, prefix: str = "") -> dict[str, float]:
    """Every number in a measurement entry (nested keys joined by "."), for check_run's ``figures``."""
    out: dict[str, float] = {}
    for k, v in entry.items():
        if isinstance(v, Mapping):
            out.update(numbers(v, f"{prefix}{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[f"{prefix}{k}"] = v
    return out
