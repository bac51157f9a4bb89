"""Benchmark section ``studies``: trials per hour of the experiments' engine (experiments/study.py) with
one and with two workers, each `cpg-walker worker --jobs 1` in its own network namespace reaching a
throwaway PostgreSQL over veth (experiments/scaleout.py), beside the same trials on one machine (the
default SQLite study, two local processes). The trials are random command sequences (the random-walks
experiment: equal lengths, through the governor). Trials per hour = completed trials over the span from
the first trial's start to the last one's end (worker start-up excluded); root and PostgreSQL needed,
else the section says why and measures nothing."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

#: (seeds, sim s per walk): quick, full.
QUICK, FULL = (range(8), 20.0), (range(24), 60.0)


def run(quick: bool = False) -> dict:
    from cpg_walker.experiments import scaleout
    from cpg_walker.experiments.random_commands import run_random_walks
    from cpg_walker.experiments.study import storage_url

    seeds, duration = QUICK if quick else FULL
    seeds = list(seeds)
    why = scaleout.unavailable()
    if why:
        return {"skipped": why}
    work = Path(tempfile.mkdtemp(prefix="bench_studies_"))
    out: dict = {"setup": {"trials": len(seeds), "trial": f"random-walks sequence of {duration:g} sim s",
                           "workers": "cpg-walker worker --jobs 1, each in a network namespace, PostgreSQL "
                                      "in the root namespace over veth"}}
    t0 = time.monotonic()
    run_random_walks(seeds, work / "one_machine", duration, jobs=2)
    local = scaleout.study_summary(storage_url(None, work / "one_machine"), "random-walks")
    out["one_machine_2_processes"] = {"trials_per_hour": local["trials_per_hour"], "span_s": local["span_s"],
                                      "wall_s": round(time.monotonic() - t0, 2)}
    with scaleout.cluster(2) as (server, spokes):
        for key, names in (("1_worker", ["A"]), ("2_workers", ["A", "B"])):
            study = f"walks-{key}"

            def coordinate(url: str, study: str = study) -> None:
                run_random_walks(seeds, work / study, duration, jobs=0, storage=url, study=study)

            r = scaleout.run_with_workers(spokes, server, study, names, work / "logs" / study, coordinate)
            out[key] = {k: r[k] for k in ("trials_per_hour", "span_s", "wall_s", "by_worker", "completed")}
    one, two = out["1_worker"]["trials_per_hour"], out["2_workers"]["trials_per_hour"]
    out["ratio_2_to_1_workers"] = round(two / one, 3) if one and two else None
    return out
