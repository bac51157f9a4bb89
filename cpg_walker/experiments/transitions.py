"""The transition map: which changes (ζ₁, α₁) → (ζ₂, α₂) survive at every stride phase, through the governor
(walker/governor.py) as cpg_node applies them. Each walk starts at ζ = α = 1, is commanded (ζ₁, α₁) at
FROM_S and, once settled, (ζ₂, α₂) at TO_S plus a fraction k/phases of the stride at ζ₁ (k = 0 ..
phases - 1), and walks on AFTER_S. `cpg-walker sweep --out DIR` writes DIR/transitions.json (every run and
the matrix of the fraction of phases survived) and DIR/transitions.png."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cpg_walker.experiments.study import Engine, study_options, task
from cpg_walker.experiments.walk_runs import WalkSpec, run_walk

#: The states of the map: slow, the learned walk, fast, backward, fast backward, standing.
STATES: tuple[tuple[float, float], ...] = ((0.4, 0.5), (1.0, 1.0), (1.5, 1.0), (-1.0, 1.0), (-1.5, 1.0),
                                           (1.0, 0.0))
#: Sim s: the first state is commanded at FROM_S, the second at TO_S (+ the phase), then AFTER_S walked.
FROM_S, TO_S, AFTER_S = 8.0, 28.0, 20.0


def specs(states=STATES, phases: int = 4, period_s: float = 1.0,
          times: tuple[float, float, float] = (FROM_S, TO_S, AFTER_S)) -> list[tuple[dict, WalkSpec]]:
    """(the run's key, its WalkSpec) for every ordered pair of distinct states and every phase; ``times``:
    (from, to, after) sim s."""
    from_s, to_s, after_s = times
    out = []
    for z1, a1 in states:
        stride = period_s / abs(z1) if z1 else period_s
        for z2, a2 in states:
            if (z1, a1) == (z2, a2):
                continue
            for k in range(phases):
                t2 = round(to_s + stride * k / phases, 4)
                key = {"from": [z1, a1], "to": [z2, a2], "phase": k, "at_s": t2}
                out.append((key, WalkSpec(zeta=z1, alpha=a1, start=f"at_{from_s:g}s",
                                          duration_after_s=t2 + after_s - from_s, schedule=((t2, z2, a2),),
                                          governed=True, label=f"{z1:g},{a1:g} -> {z2:g},{a2:g} #{k}")))
    return out


def _attrs(item: tuple[dict, WalkSpec], result: dict) -> dict:
    key, _ = item
    return {"from": key["from"], "to": key["to"], "phase": key["phase"], "fell": result["fell"]}


@task(value=lambda r: 0.0 if r["fell"] else 1.0, attrs=_attrs)
def transition_walk(item: tuple[dict, WalkSpec]) -> dict:
    """One change of the map (a study task; value 1 when it walked on, 0 when it fell)."""
    key, spec = item
    r = run_walk(spec)
    return {**key, "fell": bool(r.get("fell", True)), "fall_time_s": r.get("fall_time_s"),
            "error": r.get("error")}


def from_config(t: dict) -> tuple[tuple[tuple[float, float], ...], int, tuple[float, float, float]]:
    """(states, phases, (from, to, after) sim s) of config/sweep.yaml's ``transitions:`` section."""
    states = tuple((float(z), float(a)) for z, a in t["states"])
    return states, int(t["phases"]), (float(t["from_s"]), float(t["to_s"]), float(t["after_s"]))


def run_transitions(out_dir: str | Path, states=STATES, phases: int = 4, jobs: int | None = None,
                    times: tuple[float, float, float] = (FROM_S, TO_S, AFTER_S), command: str = "",
                    engine: Engine | None = None, storage: str | None = None, study: str | None = None,
                    resume: bool = False) -> dict:
    """Walk the map, as the batch "transitions" of ``engine``'s study (or of the study ``study``, default
    "transitions", in ``storage``, default DIR/study.db); write DIR/transitions.json and transitions.png;
    return the report (``command``: the command line, recorded with the provenance)."""
    from cpg_walker.experiments.provenance import provenance
    from cpg_walker.experiments.walk_runs import _controller

    prov = provenance(command) if command else None
    period = _controller().period
    items = specs(states, phases, period, times)
    if engine is None:
        url, name = study_options(storage, study, out_dir, "transitions")
        attrs = {"states": [list(s) for s in states], "phases": phases, "times": list(times)}
        with Engine(url, name, "transitions", jobs, resume=resume, replace=storage is None and not resume,
                    attrs=attrs) as eng:
            runs = eng.map(transition_walk, items, "transitions")
    else:
        runs = engine.map(transition_walk, items, "transitions")
    n = len(states)
    matrix = np.full((n, n), np.nan)
    for i, s1 in enumerate(states):
        for j, s2 in enumerate(states):
            cell = [r for r in runs if tuple(r["from"]) == s1 and tuple(r["to"]) == s2]
            if cell:
                matrix[i, j] = sum(not r["fell"] for r in cell) / len(cell)
    report = {"states": [list(s) for s in states], "phases": phases, "gait_period_s": period,
              "from_s": times[0], "to_s": times[1], "after_s": times[2], "runs": runs,
              "survived_fraction": [[None if np.isnan(x) else round(float(x), 3) for x in row]
                                    for row in matrix],
              "falls": sum(r["fell"] for r in runs)}
    if prov:
        report["provenance"] = prov
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "transitions.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    plot(report, out / "transitions.png")
    return report


def plot(report: dict, path: Path) -> Path:
    """The matrix: rows the state walked, columns the state commanded, the fraction of phases survived."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [f"ζ {z:g}, α {a:g}" for z, a in report["states"]]
    m = np.array([[np.nan if x is None else x for x in row] for row in report["survived_fraction"]])
    fig, ax = plt.subplots(figsize=(7.5, 6))
    im = ax.imshow(m, cmap="RdYlGn", vmin=0, vmax=1)
    for i in range(len(names)):
        for j in range(len(names)):
            if not np.isnan(m[i, j]):
                ax.text(j, i, f"{m[i, j]:.0%}", ha="center", va="center", fontsize=10)
    ax.set_xticks(range(len(names)), names, rotation=35, ha="right")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel("commanded (ζ₂, α₂)")
    ax.set_ylabel("walking at (ζ₁, α₁)")
    ax.set_title(f"Transitions survived, over {report['phases']} stride phases (through the governor)")
    fig.colorbar(im, ax=ax, label="fraction of phases without a fall")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
