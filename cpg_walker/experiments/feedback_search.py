"""`cpg-walker feedback-search`: CMA-ES (the ``cma`` library) over the feedback gains, robustness in the
objective, then a held-out judgement.

Search space: the FeedbackConfig fields named in config/feedback_search.yaml (field -> [low, high]); CMA-ES
works in [0, 1] per field (x = low + u·(high − low)), starting from config/feedback.yaml's values; every
candidate is ``FeedbackConfig.load(**values)`` and walks with the configured pathways, so new fields and
pathways need only a line in the YAML.

Objective (minimised; summed over the scenarios, each one in-process walk, experiments/walk_runs.py):

* survive first: a fall costs ``fall_penalty`` − (s survived after the command);
* otherwise ``speed_weight``·|v − ζα·v₁| / max(|ζα|·v₁, min_speed) (v: speed over the second half of the
  window; v₁: the open-loop ζ = 1 speed of the ``reference`` walk, measured once per search),
  + ``heading_weight``·|Δheading| / (``heading_deg_per_min``·window min)
  + ``drift_weight``·|lateral drift| / (``drift_m_per_min``·window min)
  + ``torque_weight``·mean|τ| / ``torque_Nm``.

The scenarios (several ζ, change times, from standing) make robustness part of it. Each generation's
candidates × scenarios run in parallel; after each generation the CMA state (and numpy's global random
state, which ``cma`` samples from) is pickled to DIR/state.pkl, so ``resume`` continues exactly where it
stopped (same seed -> same candidates). DIR/trials.jsonl gets one line per candidate (parameters,
per-scenario metrics, objective), DIR/best.yaml the best gains as a config/feedback.yaml fragment.
``holdout`` then walks the best gains, the defaults and the open loop on the searched and the held-out
scenarios (other ζ, change times, friction ±30 %, a push): DIR/holdout.json and holdout.md.
"""

from __future__ import annotations

import json
import math
import pickle
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.experiments.config_file import Config, deep_merge
from cpg_walker.experiments.study import Engine, EngineSettings, study_options, task
from cpg_walker.experiments.walk_runs import (
    CELL_LEGEND,
    Push,
    WalkSpec,
    result_cell,
    run_walk,
    start_time,
)
from cpg_walker.walker.feedback import PATHWAYS, FeedbackConfig, default_pathways

_SCENARIO_KEYS = {"name", "zeta", "alpha", "start", "duration_after_s", "friction_scale", "push", "schedule"}
_PUSH_KEYS = {"at_s", "impulse_ns", "duration_s", "direction"}


def load_config(path: str | Path | None = None, quick: bool = False) -> dict:
    """config/feedback_search.yaml (or ``path``), validated: each field a numeric FeedbackConfig field with
    low < high, scenarios with known keys; one error naming file, line and key otherwise."""
    from cpg_walker.paths import config_path

    c = Config(path or config_path("feedback_search.yaml"))
    d = c.data
    for key in ("pathways", "fields", "cma", "objective", "reference", "scenarios", "holdout", "transition"):
        if key not in d:
            raise c.error((key,), "missing")
    template = {k: v for k, v in d.items() if k != "quick"}
    c.check_known(d.get("quick") or {}, template, ("quick",))
    defaults = FeedbackConfig.load()
    known = {f.name for f in fields(FeedbackConfig)}
    if not isinstance(d["fields"], dict) or not d["fields"]:
        raise c.error(("fields",), "expected a mapping field: [low, high]")
    for name, rng in d["fields"].items():
        if name not in known:
            raise c.error(("fields", name),
                          f"unknown FeedbackConfig field; known: {', '.join(sorted(known))}")
        val = getattr(defaults, name)
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise c.error(("fields", name), f"not a numeric field (its value is {val!r})")
        if not (isinstance(rng, list) and len(rng) == 2 and all(isinstance(x, (int, float)) for x in rng)):
            raise c.error(("fields", name), f"expected [low, high], got {rng!r}")
        if not rng[0] < rng[1]:
            raise c.error(("fields", name), f"low must be < high, got [{rng[0]}, {rng[1]}]")
    p = d["pathways"]
    if p != "default":
        if not (isinstance(p, list) and all(x in PATHWAYS for x in p)):
            raise c.error(("pathways",), f"'default' or a list of {list(PATHWAYS)}, got {p!r}")
    for sect in ("scenarios", "holdout"):
        for src, lst in ((d, d[sect]), (d.get("quick") or {}, (d.get("quick") or {}).get(sect))):
            pre = (sect,) if src is d else ("quick", sect)
            for i, s in enumerate(lst or []):
                _check_scenario(c, s, (*pre, i))
    cfg = deep_merge(template, d.get("quick") or {}) if quick else template
    cm = cfg["cma"]
    if not (cm["popsize"] >= 2 and cm["generations"] >= 1 and 0 < cm["sigma0"] <= 1):
        raise c.error(("cma",), "need popsize >= 2, generations >= 1, 0 < sigma0 <= 1")
    return cfg


def _check_scenario(c: Config, s: object, key: tuple) -> None:
    if not isinstance(s, dict) or "name" not in s:
        raise c.error(key, "a scenario is a mapping with a name")
    bad = sorted(set(s) - _SCENARIO_KEYS)
    if bad:
        raise c.error(key, f"unknown scenario key(s) {bad}; known: {sorted(_SCENARIO_KEYS)}")
    if "push" in s and set(s["push"]) - _PUSH_KEYS:
        raise c.error(key, f"push keys: {sorted(_PUSH_KEYS)}")
    try:
        start_time(s.get("start", "standing"))
    except ValueError as exc:
        raise c.error(key, str(exc)) from None


def scenario_spec(s: dict, pathways: tuple[str, ...], overrides: dict | None, transition: str,
                  variant: str = "search") -> WalkSpec:
    """A WalkSpec from a scenario mapping; ``overrides`` None = open loop."""
    kw = {k: v for k, v in s.items() if k not in ("name", "push", "schedule")}
    push = Push(**s["push"]) if "push" in s else None
    sched = tuple(tuple(x) for x in s.get("schedule", ()))
    if overrides is None:
        return WalkSpec(**kw, push=push, schedule=sched, variant="off", transition=transition,
                        label=s["name"])
    return WalkSpec(**kw, push=push, schedule=sched, variant=variant, pathways=tuple(pathways),
                    overrides=dict(overrides), transition=transition, label=s["name"])


def scenario_cost(m: dict, v1: float, obj: dict) -> float:
    """The objective of one walk's metrics (module docstring)."""
    if "error" in m:
        return 2.0 * obj["fall_penalty"]
    if m["fell"]:
        return obj["fall_penalty"] - (m["fall_time_s"] - m["t_cmd_s"])
    minutes = max(m["window_s"], 1e-6) / 60.0
    target = m["zeta"] * m["alpha"] * v1
    return (obj["speed_weight"] * abs(m["steady_speed_mps"] - target) / max(abs(target), obj["min_speed_mps"])
            + obj["heading_weight"] * abs(m["heading_change_deg"]) / (obj["heading_deg_per_min"] * minutes)
            + obj["drift_weight"] * abs(m["lateral_drift_m"]) / (obj["drift_m_per_min"] * minutes)
            + obj["torque_weight"] * (m["mean_abs_torque_Nm"] or 0.0) / obj["torque_Nm"])


def _brief(m: dict) -> dict:
    keys = ("fell", "fall_time_s", "t_cmd_s", "window_s", "distance_m", "steady_speed_mps", "mean_speed_mps",
            "heading_change_deg", "lateral_drift_m", "mean_abs_torque_Nm", "phase_resets", "error")
    return {k: m[k] for k in keys if k in m}


def _eval(spec: WalkSpec) -> dict:
    try:
        return run_walk(spec)
    except ValueError as exc:  # a candidate FeedbackConfig rejected by its own validation
        return {"error": str(exc)}


def _scenario(s: dict, overrides: dict | None, item: dict) -> dict:
    m = _eval(scenario_spec(s, tuple(item["pathways"]), overrides, item["transition"]))
    return {**_brief(m), "cost": round(scenario_cost(m, item["v1"], item["objective"]), 4)}


def _candidate_attrs(item: dict, result: dict) -> dict:
    per = result["scenarios"]
    return {"generation": item["generation"], "candidate": item["candidate"],
            "falls": sum(bool(m.get("fell")) for m in per.values()),
            **{f"cost {name}": m["cost"] for name, m in per.items()}}


def _candidate_params(item: dict) -> dict[str, tuple[float, float, float]]:
    return {n: (v, *item["fields"][n]) for n, v in item["params"].items()}


@task(value=lambda r: r["objective"], attrs=_candidate_attrs, params=_candidate_params)
def evaluate_candidate(item: dict) -> dict:
    """One candidate of the search (a study task): its gains ``item["params"]`` walked on every searched
    scenario in turn; {"scenarios": {name: metrics + cost}, "objective": the sum} (the trial's value)."""
    per = {s["name"]: _scenario(s, item["params"], item) for s in item["scenarios"]}
    return {"scenarios": per, "objective": round(sum(p["cost"] for p in per.values()), 4)}


def _holdout_attrs(item: dict, result: dict) -> dict:
    return {"gains": item["gains"], "scenario": item["scenario"]["name"], "fell": result.get("fell")}


@task(value=lambda r: r["cost"], attrs=_holdout_attrs)
def holdout_walk(item: dict) -> dict:
    """One walk of the held-out judgement (a study task): gains ``item["gains"]`` (off: open loop) on one
    scenario; its metrics and cost."""
    return _scenario(item["scenario"], item["overrides"], item)


class Space:
    """The searched fields and their [low, high]: to and from the normalised [0, 1] coordinates."""

    def __init__(self, ranges: dict[str, list[float]]):
        self.names = list(ranges)
        self.low = np.array([float(ranges[n][0]) for n in self.names])
        self.high = np.array([float(ranges[n][1]) for n in self.names])

    def values(self, u: np.ndarray) -> dict[str, float]:
        x = self.low + np.clip(u, 0.0, 1.0) * (self.high - self.low)
        return {n: float(v) for n, v in zip(self.names, x, strict=True)}

    def normalise(self, values: dict[str, float]) -> np.ndarray:
        x = np.array([float(values[n]) for n in self.names])
        return (x - self.low) / (self.high - self.low)


def _pathways(cfg: dict) -> tuple[str, ...]:
    return default_pathways() if cfg["pathways"] == "default" else tuple(cfg["pathways"])


def _reference_speed(out: Path, cfg: dict, engine: Engine | None = None) -> float:
    """v₁ (m/s): the open-loop reference walk's speed, measured once per search and kept in the study
    (``v1_mps``) and DIR/reference.json."""
    f = out / "reference.json"
    known = engine.study.user_attrs.get("v1_mps") if engine is not None else None
    if known is None and f.is_file():
        known = json.loads(f.read_text())["v1_mps"]
    if known is not None:
        v1 = float(known)
    else:
        ref = {"name": "reference", **cfg["reference"]}
        m = run_walk(scenario_spec(ref, (), None, cfg["transition"]))
        if m["fell"] or m["steady_speed_mps"] <= 0:
            raise RuntimeError(f"the reference walk {cfg['reference']} fell or did not move forward: "
                               f"{_brief(m)}")
        v1 = float(m["steady_speed_mps"])
        f.write_text(json.dumps({"v1_mps": v1, "walk": _brief(m)}, indent=1) + "\n")
    if engine is not None:
        engine.study.set_user_attr("v1_mps", v1)
    return v1


def _task_setup(cfg: dict, v1: float) -> dict:
    return {"pathways": list(_pathways(cfg)), "transition": cfg["transition"], "objective": cfg["objective"],
            "v1": v1}


def search(out_dir: str | Path, generations: int | None = None, popsize: int | None = None, seed: int = 1,
           jobs: int | None = None, resume: bool = False, quick: bool = False, config: str | None = None,
           log=print, storage: str | None = None, study: str | None = None,
           settings: EngineSettings | None = None) -> dict:
    """Run (or continue, ``resume``) the CMA-ES search up to ``generations`` as the study ``study`` (default
    "feedback-search") in ``storage`` (default DIR/study.db); returns the best so far.

    This call coordinates: it asks ``cma`` for each generation and enqueues the candidates; workers run
    them (``evaluate_candidate``). A resumed search asks again from the same seed and reads the
    generations already in the study back instead of walking them, so it continues exactly where it
    stopped, whichever workers ran what."""
    import cma

    from cpg_walker.progress import Progress

    cfg = load_config(config, quick)
    gens = int(cfg["cma"]["generations"] if generations is None else generations)
    pop = int(cfg["cma"]["popsize"] if popsize is None else popsize)
    if gens < 1 or pop < 2:
        raise InputError(f"--generations must be >= 1 and --popsize >= 2, got {gens}, {pop}")
    out = Path(out_dir)
    space = Space(cfg["fields"])
    setup = {"fields": cfg["fields"], "pathways": list(_pathways(cfg)), "popsize": pop, "seed": seed,
             "scenarios": cfg["scenarios"], "objective": cfg["objective"]}
    url, name = study_options(storage, study, out, "feedback-search")
    with Engine(url, name, "feedback-search", jobs, settings, attrs={"setup": setup},
                resume=resume) as engine:
        v1 = _reference_speed(out, cfg, engine)
        (out / "setup.json").write_text(json.dumps(setup, indent=1) + "\n")
        x0 = np.clip(space.normalise(asdict(FeedbackConfig.load())), 0.05, 0.95)
        es = cma.CMAEvolutionStrategy(x0.tolist(), float(cfg["cma"]["sigma0"]),
                                      {"seed": seed, "popsize": pop, "bounds": [0.0, 1.0], "verbose": -9})
        best: dict = {"objective": math.inf}
        lines = []
        base = {**_task_setup(cfg, v1), "fields": cfg["fields"], "scenarios": cfg["scenarios"]}
        for gen in range(gens):
            us = es.ask()
            cands = [space.values(np.asarray(u)) for u in us]
            items = [{**base, "params": c, "generation": gen, "candidate": k} for k, c in enumerate(cands)]
            progress = Progress(len(items), f"generation {gen + 1}/{gens}", unit="candidates")
            res = engine.map(evaluate_candidate, items, f"generation {gen}", progress)
            progress.close()
            bad = [r["error"] for r in res if "error" in r and "objective" not in r]
            if bad:
                raise RuntimeError(f"generation {gen}: a candidate could not be evaluated: {bad[0]}")
            es.tell(us, [r["objective"] for r in res])
            for k, (c, r) in enumerate(zip(cands, res, strict=True)):
                lines.append(json.dumps({"generation": gen, "candidate": k, "params": c, **r}))
                if r["objective"] < best["objective"]:
                    best = {"objective": r["objective"], "generation": gen, "candidate": k, "params": c,
                            "scenarios": r["scenarios"]}
            (out / "trials.jsonl").write_text("".join(x + "\n" for x in lines))
            (out / "state.pkl").write_bytes(pickle.dumps({"setup": setup, "es": es, "generation": gen + 1,
                                                          "best": best, "np_random": np.random.get_state()}))
            write_best(out / "best.yaml", best, setup)
            objs = sorted(r["objective"] for r in res)
            log(f"generation {gen + 1}/{gens}: objective best {objs[0]:.2f}, median "
                f"{objs[len(objs) // 2]:.2f}; best so far {best['objective']:.2f} (v1 = {v1:.4f} m/s)")
    return best


def write_best(path: Path, best: dict, setup: dict) -> None:
    import yaml

    head = (f"# best gains of cpg-walker feedback-search (objective {best['objective']}, generation "
            f"{best['generation']}, candidate {best['candidate']}, seed {setup['seed']}, pathways "
            f"{','.join(setup['pathways'])}); a config/feedback.yaml fragment\n")
    body = yaml.safe_dump({k: round(v, 6) for k, v in best["params"].items()}, sort_keys=False)
    path.write_text(head + body)


def read_best(path: Path) -> dict:
    import yaml

    d = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not isinstance(d, dict):
        raise InputError(f"{path}: expected a mapping of FeedbackConfig fields")
    FeedbackConfig.load(**d)  # validates names and values
    return d


def holdout(out_dir: str | Path, jobs: int | None = None, quick: bool = False, config: str | None = None,
            best_file: str | None = None, storage: str | None = None, study: str | None = None) -> dict:
    """Walk the best gains (DIR/best.yaml), config/feedback.yaml's defaults and the open loop on the
    searched and the held-out scenarios, as a batch of the search's study; DIR/holdout.json and
    holdout.md, side by side."""
    import hashlib

    from cpg_walker.progress import Progress

    cfg = load_config(config, quick)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    best = read_best(Path(best_file) if best_file else out / "best.yaml")
    scen = [*cfg["scenarios"], *cfg["holdout"]]
    cands = {"off": None, "default": {}, "best": best}
    url, name = study_options(storage, study, out, "feedback-search")
    with Engine(url, name, "feedback-search", jobs, resume=True) as engine:
        v1 = _reference_speed(out, cfg, engine)
        base = _task_setup(cfg, v1)
        items = [{**base, "gains": g, "overrides": c, "scenario": s} for g, c in cands.items() for s in scen]
        tag = hashlib.blake2b(json.dumps(items, sort_keys=True).encode(), digest_size=4).hexdigest()
        progress = Progress(len(items), "holdout", unit="walks")
        flat = engine.map(holdout_walk, items, f"holdout {tag}", progress)
        progress.close()
    bad = [r["error"] for r in flat if "error" in r and "cost" not in r]
    if bad:
        raise RuntimeError(f"holdout: a walk could not be evaluated: {bad[0]}")
    res = [{"scenarios": {s["name"]: flat[i * len(scen) + j] for j, s in enumerate(scen)}}
           for i in range(len(cands))]
    searched = {s["name"] for s in cfg["scenarios"]}
    report = {"v1_mps": v1, "best": best, "pathways": list(_pathways(cfg)), "rows": []}
    for s in scen:
        row = {"scenario": s["name"], "set": "searched" if s["name"] in searched else "held-out", "spec": s}
        for cname, r in zip(cands, res, strict=True):
            row[cname] = r["scenarios"][s["name"]]
        report["rows"].append(row)
    for cname, r in zip(cands, res, strict=True):
        costs = {s["name"]: r["scenarios"][s["name"]]["cost"] for s in scen}
        report[f"objective_{cname}"] = {
            "searched": round(sum(v for k, v in costs.items() if k in searched), 3),
            "held-out": round(sum(v for k, v in costs.items() if k not in searched), 3)}
    (out / "holdout.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "holdout.md").write_text(holdout_markdown(report, list(cands)))
    return report


def holdout_markdown(report: dict, names: list[str]) -> str:
    lines = ["# feedback-search: searched vs held-out", "",
             f"v1 (open-loop ζ = 1 speed) = {report['v1_mps']} m/s; pathways "
             f"{', '.join(report['pathways'])}; cell: {CELL_LEGEND}; (cost).", "",
             "| scenario | set | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for row in report["rows"]:
        lines.append(f"| {row['scenario']} | {row['set']} | "
                     + " | ".join(f"{result_cell(row[n])} ({row[n]['cost']:.1f})" for n in names) + " |")
    lines += ["", "| objective (sum) | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for st in ("searched", "held-out"):
        lines.append(f"| {st} | " + " | ".join(str(report[f"objective_{n}"][st]) for n in names) + " |")
    lines += ["", "best gains: " + json.dumps(report["best"]), ""]
    return "\n".join(lines)
