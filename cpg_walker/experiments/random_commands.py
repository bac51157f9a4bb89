"""Random command sequences, as a user turning the knobs would: a new (ζ, α) drawn uniformly from
cpg_node's declared ranges every ``min_gap_s`` to ``max_gap_s`` sim s (seeded: the same seed, the same
sequence), walked in-process through the governor (walker/governor.py). `cpg-walker random-walks --seeds
A-B --out DIR` walks one per seed and writes DIR/random_walks.json (each sequence, fell, fall time,
distance); it exits 1 when any fell (its job is to walk)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cpg_walker.experiments.study import Engine, study_options, task
from cpg_walker.experiments.walk_runs import WalkSpec, run_walk
from cpg_walker.walker.governor import GovernorConfig, command_range

#: Sim s between commands, and the first command's time (the CPG drives alone from ≈ 6.6 s).
MIN_GAP_S, MAX_GAP_S, FIRST_S = 8.0, 16.0, 8.0


def sequence(seed: int, duration_s: float = 120.0, min_gap_s: float = MIN_GAP_S, max_gap_s: float = MAX_GAP_S,
             zeta_range: tuple[float, float] | None = None,
             alpha_range: tuple[float, float] | None = None) -> tuple[tuple[float, float, float], ...]:
    """(t, ζ, α) commands from FIRST_S to ``duration_s``, rounded to 0.01; the ranges default to cpg_node's
    declared ones (with its governor: governor.command_range)."""
    gcfg = GovernorConfig.load()
    zeta_range = zeta_range or command_range("zeta", gcfg)
    alpha_range = alpha_range or command_range("alpha", gcfg)
    rng = np.random.default_rng(seed)
    out, t = [], FIRST_S
    while t < duration_s:
        z = round(float(rng.uniform(*zeta_range)), 2)
        a = round(float(rng.uniform(*alpha_range)), 2)
        out.append((round(t, 2), z, a))
        t += float(rng.uniform(min_gap_s, max_gap_s))
    return tuple(out)


def spec(seed: int, duration_s: float = 120.0, feedback: str = "ours",
         pathways: tuple[str, ...] | None = None) -> WalkSpec:
    """The walk of one seed: from standing at ζ = α = 1, then the seed's sequence (``pathways``: these
    feedback pathways instead of the ``feedback`` variant's)."""
    return WalkSpec(duration_after_s=duration_s, schedule=sequence(seed, duration_s), variant=feedback,
                    pathways=pathways, label=f"seed {seed}", governed=True)


@task(value=lambda r: float(r["distance_m"] or 0.0),
      attrs=lambda s, r: {"label": s.label, "fell": r["fell"], "fall_time_s": r["fall_time_s"]})
def random_walk(s: WalkSpec) -> dict:
    """One seed's sequence (a study task; value: the distance walked, m)."""
    r = run_walk(s)
    return {"label": s.label, "feedback": s.variant, "schedule": [list(x) for x in s.schedule],
            "fell": r["fell"], "fall_time_s": r["fall_time_s"], "distance_m": r.get("distance_m")}


def run_random_walks(seeds: list[int], out_dir: str | Path, duration_s: float = 120.0, feedback: str = "ours",
                     jobs: int | None = None, command: str = "cpg-walker random-walks",
                     pathways: tuple[str, ...] | None = None, storage: str | None = None,
                     study: str | None = None, resume: bool = False) -> dict:
    """Walk every seed's sequence as the study ``study`` (default "random-walks") in ``storage`` (default
    DIR/study.db); DIR/random_walks.json. ``falls``: how many fell."""
    from cpg_walker.experiments.provenance import provenance

    url, name = study_options(storage, study, out_dir, "random-walks")
    with Engine(url, name, "random-walks", jobs, resume=resume,
                replace=storage is None and not resume) as eng:
        runs = eng.map(random_walk, [spec(s, duration_s, feedback, pathways) for s in seeds], "random-walks")
    report = {"seeds": list(seeds), "duration_s": duration_s, "feedback": feedback,
              "pathways": None if pathways is None else list(pathways),
              "falls": sum(1 for r in runs if r["fell"]), "runs": runs, **provenance(command)}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "random_walks.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    return report
