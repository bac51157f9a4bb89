"""The README's locomotion results as data: each a named in-process walk (walk_runs.WalkSpec with the
default feedback pathways and cpg_node's start-up: the recorded opening steps, then the CPG), measured by
``cpg-walker results --out docs/results`` into ``headline.json`` / ``headline.md`` (with the command,
commit, date and load), and held by test/test_headline.py to the committed figures within ``MARGINS``.

Every walk is deterministic in-process (same code, same libraries: the same numbers), so the margins do
not absorb noise: they say how far a change of the controller may move a headline figure before it counts
as a regression rather than a new result (then regenerate the artifact and say so).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cpg_walker.experiments.demo import DEMO_SCHEDULE, FIRST_SEGMENT
from cpg_walker.experiments.walk_runs import WalkSpec, run_many, run_walk

#: How far a re-run may sit from the committed figure. Speed: 10 % of it or 0.01 m/s, whichever is larger
#: (the demo's backward speed over ten start phases 0.25 s apart spread 4 %, -0.064 to -0.067 m/s);
#: heading change: 5 degrees (the stride-averaged yaw of these walks ends within -2 and +1 degrees);
#: lateral drift: 0.15 m (measured -0.12 to -0.003 m over 30-60 s walks).
MARGINS = {"speed_rel": 0.10, "speed_abs_mps": 0.01, "heading_deg": 5.0, "drift_m": 0.15}
RESULTS_NAME = "headline"


@dataclass(frozen=True)
class Scenario:
    """One headline walk: its spec and what the README calls it."""

    name: str
    title: str
    spec: WalkSpec
    #: (from, to, label) sim-s windows whose speed is a headline figure (their second half is measured)
    segments: tuple[tuple[float, float, str], ...] = ()


def demo_segments(end_s: float) -> tuple[tuple[float, float, str], ...]:
    """The demo's segments of constant command up to ``end_s``: (from, to, label), the first from the
    hand-over's end (``walk_start``)."""
    from cpg_walker.experiments.demo import walk_start_s

    starts = [(walk_start_s(), FIRST_SEGMENT)] + [(t, label) for t, _, _, label in DEMO_SCHEDULE if t < end_s]
    ends = [t for t, _ in starts[1:]] + [end_s]
    return tuple((round(a, 3), round(b, 3), label) for (a, label), b in zip(starts, ends, strict=True))


DEMO_S = 60.0  # the demo's default duration (cpg-walker demo, make demo)

#: The walks as a user gets them: through the governor (cpg_node's default).
SCENARIOS: tuple[Scenario, ...] = (
    Scenario("zeta1_60s", "zeta 1, 60 s (the learned walk)",
             WalkSpec(1.0, 1.0, "standing", 60.0, governed=True)),
    Scenario("zeta1.5_from_standing", "zeta 1.5 from standing",
             WalkSpec(1.5, 1.0, "standing", 40.0, governed=True)),
    Scenario("zeta1.5_at_10s", "zeta 1 -> 1.5 at 10 s", WalkSpec(1.5, 1.0, "at_10s", 40.0, governed=True)),
    Scenario("zeta-1.2_from_standing", "zeta -1.2 (backwards) from standing",
             WalkSpec(-1.2, 1.0, "standing", 40.0, governed=True)),
    Scenario("zeta-1.2_at_10s", "zeta 1 -> -1.2 at 10 s", WalkSpec(-1.2, 1.0, "at_10s", 40.0, governed=True)),
    Scenario("reversal_at_15s", "reversal zeta 1 -> -1 at 15 s",
             WalkSpec(-1.0, 1.0, "at_15s", 40.0, governed=True)),
    Scenario("alpha_0_then_1", "alpha 1 -> 0 at 10 s (stands), -> 1 at 25 s (walks again)",
             WalkSpec(1.0, 0.0, "at_10s", 40.0, schedule=((25.0, 1.0, 1.0),), governed=True),
             segments=((10.0, 25.0, "alpha 0"), (25.0, 50.0, "alpha 1 again"))),
    Scenario("demo_schedule", f"the demo's schedule, {DEMO_S:g} s",
             WalkSpec(1.0, 1.0, "standing", DEMO_S, governed=True,
                      schedule=tuple((t, z, a) for t, z, a, _ in DEMO_SCHEDULE if t < DEMO_S)),
             segments=demo_segments(DEMO_S)),
)


def scenario(name: str) -> Scenario:
    found = [s for s in SCENARIOS if s.name == name]
    if not found:
        raise KeyError(f"no headline scenario {name!r}; there are {[s.name for s in SCENARIOS]}")
    return found[0]


def run_scenario(sc: Scenario) -> dict:
    """Walk ``sc`` in-process; its figures: fell, fall time, steady speed (the window's second half),
    heading change, lateral drift, distance, and each headline segment's speed over its second half."""
    halves = tuple((round(0.5 * (a + b), 3), b) for a, b, _ in sc.segments)
    spec = dataclasses.replace(sc.spec, segments=halves) if halves else sc.spec
    m = run_walk(spec)
    if "error" in m:
        return {"name": sc.name, "error": m["error"]}
    out = {"name": sc.name, "title": sc.title, "spec": m["spec"],
           **{k: m[k] for k in ("fell", "fall_time_s", "duration_s", "t_cmd_s", "steady_speed_mps",
                                "mean_speed_mps", "heading_change_deg", "lateral_drift_m", "distance_m",
                                "steps")}}
    if halves:
        out["segments"] = [{"from_s": a, "to_s": b, "label": label, "measured_from_s": seg["from_s"],
                            "speed_mps": seg["mean_speed_mps"]}
                           for (a, b, label), seg in zip(sc.segments, m["segments"], strict=True)]
    return out


def run_all(progress: Callable[[int], None] | None = None, jobs: int | None = None) -> list[dict]:
    """Every scenario (in parallel over ``jobs`` processes, default every core)."""
    class _P:
        def update(self, k: int) -> None:
            if progress is not None:
                progress(k)

    return run_many(run_scenario, SCENARIOS, jobs=jobs, progress=_P())


def speed_bound(value: float) -> float:
    """The allowed |re-run - committed| of a speed (``MARGINS``)."""
    return max(MARGINS["speed_rel"] * abs(value), MARGINS["speed_abs_mps"])


def differences(committed: dict, fresh: dict) -> list[str]:
    """What a re-run of a scenario changed beyond ``MARGINS`` (empty: it holds): a fall is always one."""
    if "error" in fresh:
        return [f"{committed['name']}: {fresh['error']}"]
    name, out = committed["name"], []
    if fresh["fell"]:
        out.append(f"{name}: fell at {fresh['fall_time_s']} s")
    pairs = [("steady_speed_mps", speed_bound(committed["steady_speed_mps"])),
             ("heading_change_deg", MARGINS["heading_deg"]), ("lateral_drift_m", MARGINS["drift_m"])]
    for key, bound in pairs:
        if abs(fresh[key] - committed[key]) > bound:
            out.append(f"{name}: {key} {fresh[key]} vs {committed[key]} committed (bound {bound:g})")
    for seg_c, seg_f in zip(committed.get("segments", []), fresh.get("segments", []), strict=True):
        bound = speed_bound(seg_c["speed_mps"])
        if abs(seg_f["speed_mps"] - seg_c["speed_mps"]) > bound:
            out.append(f"{name} '{seg_c['label']}': speed {seg_f['speed_mps']} vs {seg_c['speed_mps']} "
                       f"committed (bound {bound:g})")
    return out


def markdown(doc: dict) -> str:
    """headline.md: one row per scenario, one per segment below it; the provenance under the table."""
    rows = ["| walk (in-process, feedback on) | fell | speed m/s (second half) | heading change ° | "
            "lateral drift m | distance m |", "|---|---|---|---|---|---|"]
    for r in doc["runs"]:
        if "error" in r:
            rows.append(f"| {r['name']} | error: {r['error']} | | | | |")
            continue
        fell = f"at {r['fall_time_s']} s" if r["fell"] else "no"
        rows.append(f"| {r['title']} | {fell} | {r['steady_speed_mps']:+.3f} | "
                    f"{r['heading_change_deg']:+.1f} | {r['lateral_drift_m']:+.3f} | "
                    f"{r['distance_m']:+.2f} |")
        for s in r.get("segments", []):
            rows.append(f"| &nbsp;&nbsp;from {s['from_s']:g} s: {s['label']} | | {s['speed_mps']:+.3f} "
                        "| | | |")
    p = doc["provenance"]
    rows += ["", f"`{p['command']}` at commit {p['commit']} on {p['date']} ({p['cpus']} CPUs, load average "
                 f"{p['load_average_start'][0]} at the start); {doc['wall_s']:.0f} s wall. Metrics: "
                 "experiments/walk_runs.py (speed along the heading at the command, over the window's "
                 "second half; heading change from stride-averaged yaw)."]
    return "\n".join(rows) + "\n"


def write(out_dir: str | Path, doc: dict) -> tuple[Path, Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js, md = out / f"{RESULTS_NAME}.json", out / f"{RESULTS_NAME}.md"
    js.write_text(json.dumps(doc, indent=1) + "\n")
    md.write_text(markdown(doc))
    return js, md
