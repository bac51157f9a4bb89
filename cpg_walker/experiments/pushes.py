"""The largest lateral pushes recovered standing (α 0) and walking (ζ 1, α 1), both ways, as a user gets
the robot (in-process, the default feedback pathways, through the governor): `cpg-walker pushes --out DIR`
writes DIR/pushes.json and pushes.md. A push is a horizontal force on the torso perpendicular to the
heading, ``DURATION_S`` long, at ``AT_S``; recovered = no fall for ``AFTER_S`` after it (bisection on the
impulse, ``sweep.push_bisection``). Falls are data: exit status 0."""

from __future__ import annotations

import json
from pathlib import Path

from cpg_walker.experiments.sweep import push_bisection
from cpg_walker.experiments.walk_runs import run_many

#: Sim s of the push (the CPG has taken over from ≈ 6.6 s), its length, the recovery window; the bracket
#: [0, MAX_NS] N s halved ITERATIONS times (resolution MAX_NS / 2**ITERATIONS).
AT_S, DURATION_S, AFTER_S, MAX_NS, ITERATIONS = 15.0, 0.1, 10.0, 8.0, 7
#: (what, α): standing in place, and the learned walk.
CASES = (("standing", 0.0), ("walking", 1.0))


def tasks(variant: str = "ours") -> list[dict]:
    return [{"case": case, "zeta": 1.0, "alpha": alpha, "direction": d, "variant": variant, "governed": True,
             "at_s": AT_S, "after_s": AFTER_S, "duration_s": DURATION_S, "max_impulse_Ns": MAX_NS,
             "iterations": ITERATIONS, "transition": "recording"}
            for case, alpha in CASES for d in (1.0, -1.0)]


def _one(task: dict) -> dict:
    return {"case": task["case"], **push_bisection(task)}


def markdown(report: dict) -> str:
    rows = ["| case | push to the | recovered N·s | fell at N·s |", "|---|---|---|---|"]
    for r in report["runs"]:
        side = "left" if r["direction"] > 0 else "right"
        rows.append(f"| {r['case']} (ζ {r['zeta']:g}, α {r['alpha']:g}) | {side} | "
                    f"{r['max_recovered_impulse_Ns']:.2f} | {r['first_fall_impulse_Ns']:.2f} |")
    p = report["provenance"]
    return (f"# Lateral pushes recovered ({report['variant']} feedback, through the governor)\n\n"
            + "\n".join(rows) + f"\n\nA {DURATION_S:g} s push on the torso at {AT_S:g} s; recovered = no "
            f"fall for {AFTER_S:g} s; resolution {MAX_NS / 2 ** ITERATIONS:.3f} N·s. `{p['command']}` at "
            f"commit {p['commit']} on {p['date']}.\n")


def run_pushes(out_dir: str | Path, variant: str = "ours", jobs: int | None = None,
               command: str = "cpg-walker pushes") -> dict:
    from cpg_walker.experiments.provenance import provenance

    report = {"variant": variant, "runs": run_many(_one, tasks(variant), jobs=jobs),
              "provenance": provenance(command)}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "pushes.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    (out / "pushes.md").write_text(markdown(report), encoding="utf-8")
    return report
